//! `dmap twin`: the H743 release firmware, unmodified, run on the chip
//! model in `host-tests/twin` (an STM32H743 on Unicorn, with a detector
//! model wired to its pins). One file per part:
//!
//! * `runner.rs`: the command itself: its options, the firmware's build
//!   per compile-time configuration (cached in `target/twin/elf`), the
//!   model's run under supervision, its output and its verdict.
//! * `record.rs`: the settings record in bank 2 that hands the firmware a
//!   run's settings, written with the product's own store code.
//! * `requests.rs`: what the model gets besides the scan: the host's bytes
//!   on the serial link (`--requests`, `--command`, a live host), bank 2
//!   kept between runs (`--flash`) and a power cut (`--power-cut`).
//! * `pins.rs`: the READY and REJECT outputs' timeline (`--pins`) and the
//!   verdicts beside their edges.
//! * `checks.rs`: what is checked before the model starts: the faults,
//!   the run's model time, and that an `--elf` fits the run.
//!
//! The `--command` requests in `dmap sensor`'s words are
//! [`crate::sensor::twin`], which `dmap console` shares.

pub mod checks;
pub mod pins;
pub mod record;
pub mod requests;
mod runner;

pub use runner::*;
