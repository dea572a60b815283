#![no_std]
#![doc = include_str!("../README.md")]

/// Version of the scoring code, carried in every header line (`fw=`).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

pub mod boot;
pub mod calibration;
pub mod channels;
pub mod command;
pub mod config;
pub mod objects;
pub mod pipeline;
pub mod protocol;
pub mod record;
pub mod scorer;
pub mod settings;
pub mod stream;
pub mod tables;
pub mod verdict;

pub use boot::Boot;
pub use calibration::Calibrator;
pub use channels::{flags, power, spread};
pub use config::{Config, ConfigError, Geometry, Kernels, MAX_CELLS, MAX_J, Weights};
pub use objects::{Object, Objects};
pub use pipeline::Pipeline;
pub use scorer::{Bounds, Formats, FrameError, Scorer, magnitude};
pub use settings::{Outputs, RejectMode, Settings};
pub use stream::{Engine, Position, PositionScore, RowSummary, RowView, Totals};
pub use verdict::{Fault, Verdict};
