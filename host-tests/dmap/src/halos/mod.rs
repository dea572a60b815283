//! Scattering halos against the shipped engine: the parts of
//! docs/spread-study.md (both geometries, defect-free or with halos), the
//! three channels calibrated by the tail rule on reference parts, and each
//! scan run through `cvm_core::Engine` and `cvm_core::Objects` exactly as
//! the firmware runs them. The halo test (`tests/halos_found.rs`), the
//! detection-curve experiment (`examples/curves.rs`), the paper-sim
//! bubble runs (`examples/paper_bubbles.rs`) and the pooled decisions for
//! one-position defects (`pooled`, `examples/pooled.rs`) share it.

pub mod calib;
pub mod parts;
pub mod plot;
pub mod pooled;
pub mod run;
pub mod thresholds;

pub use calib::{calibrate, calibrate_scans, scorer_for, simulate};
pub use parts::{Geo, Halo, halo_part, halo_part_of_beam_power, strongest_beam};
pub use run::{Outcome, around, found, near, peak_ratios, run_scan};
pub use thresholds::Thresholds;
