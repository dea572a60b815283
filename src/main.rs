//! Firmware: streaming CVM defect scoring of deflection maps.
//!
//! One application, two boards. The board is a cargo feature: `h743`
//! (NUCLEO-H743ZI2, default) or `emulated` (QEMU `mps2-an386`). Both feed
//! the same `cvm_fw_app` runtime (sequencing, queueing, the outputs'
//! logic) and the same `cvm_core::Pipeline`; only the code that touches
//! hardware differs.
#![no_std]
#![no_main]

#[cfg(all(feature = "h743", feature = "emulated"))]
compile_error!(
    "select one board: `--features h743` (default) or `--no-default-features --features emulated`"
);
#[cfg(not(any(feature = "h743", feature = "emulated")))]
compile_error!(
    "select a board: `--features h743` (default) or `--no-default-features --features emulated`"
);

mod config;

#[cfg(feature = "emulated")]
mod emulated;
#[cfg(feature = "h743")]
mod h743;
