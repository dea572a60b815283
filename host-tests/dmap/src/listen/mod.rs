//! `dmap listen`: decodes the firmware's result lines (from a file, stdin or
//! a serial port), checks every CRC, reports damaged lines by number and
//! keeps going, and rebuilds each scan's score images, defect objects and
//! summary.
//!
//! A line is decoded by `cvm_core::protocol::parse`, beside its encoder;
//! this module holds what a stream of lines needs besides: the stream
//! decoder (`decoder`, its handler of each line type in `handlers`, and
//! `checks`), what it rebuilds of a scan (`scan`), the line reader
//! (`reader`) and what ends it on Ctrl-C (`interrupt`), the two reports
//! (`text`, `json`), and the command (`args`, `run`).

#[cfg(feature = "tools")]
mod args;
mod checks;
mod crosscheck;
mod decoder;
mod handlers;
#[cfg(feature = "tools")]
mod interrupt;
mod json;
mod linechecks;
mod reader;
#[cfg(feature = "tools")]
mod run;
mod scan;
mod text;

#[cfg(feature = "tools")]
pub use args::ListenArgs;
pub use decoder::{DEFAULT_MAX_SCANS, Decoder, MAX_DEFECTS, MAX_ERRORS, MAX_KEPT, MAX_SCANS};
pub use json::{object_json, scan_json, summary_json, totals_json};
pub use reader::{LINE_BUFFER, NextLine, decode, decode_with, next_line};
#[cfg(feature = "tools")]
pub use run::run;
pub use scan::{
    Defect, Kind, LineError, MAX_IMAGE_POSITIONS, MAX_PROBLEMS, ObjectSize, ScanResult,
    channel_names, image_refusal, q8, strength_ratio,
};
pub use text::{TEXT_OBJECTS, object_text, summary_text, summary_text_with};
