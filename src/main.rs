//! Firmware for the NUCLEO-H743ZI2: streaming CVM defect scoring of
//! deflection maps. The board's code (`h743`) feeds the `cvm_fw_app`
//! runtime (sequencing, queueing, the outputs' logic) and the
//! `cvm_core::Pipeline`; only the code that touches hardware is here. The
//! same runtime runs on QEMU's `mps2-an386` in `boards/mps2-an386`, a
//! package of its own beside its memory map.
#![no_std]
#![no_main]

mod config;
mod h743;
