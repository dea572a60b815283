#![no_std]
//! Board-independent firmware logic, shared by the NUCLEO-H743ZI2 and the
//! emulated (QEMU) boards and tested on the host: decoding SPI frames,
//! numbering beams into scan positions, DRDY overrun accounting, and the
//! prioritised output queue. No HAL, no math (that is `cvm-core`).

pub mod acquire;
pub mod decode;
pub mod driver;
pub mod emufile;
pub mod queue;
pub mod sequence;
