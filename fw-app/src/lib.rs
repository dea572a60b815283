#![no_std]
//! Board-independent firmware logic, shared by the NUCLEO-H743ZI2 and the
//! emulated (QEMU) boards and tested on the host: the scoring side's loop
//! (`runtime`, which drives the board through small traits), numbering beams into
//! scan positions, DRDY overrun accounting, the prioritised output queue,
//! the READY and REJECT outputs' logic, the command channel's logic, the
//! settings kept in flash and the emulated board's scan file. No HAL, no
//! math (that is
//! `cvm-core`). Both boards' frames arrive as native `u16` samples, so
//! there is nothing to decode.

pub mod acquire;
pub mod control;
pub mod driver;
pub mod emufile;
pub mod flash_words;
pub mod frames;
pub mod outputs;
pub mod queue;
pub mod runtime;
pub mod sequence;
pub mod settings_store;
pub mod sizing;
