//! The core's host tests, one binary: each file of this folder is a
//! module, so the suite links once and its tests share the cores.

mod ahead;
mod calibration;
mod command;
mod embedding_exact;
mod engine;
mod fixed_vs_f64;
mod flags_and_summaries;
mod formats;
mod frame_copy;
mod magnitude;
mod objects;
mod overflow_proof;
mod passes_asm;
mod pipeline;
mod pooled;
mod power;
mod protocol;
mod protocol_layout;
mod protocol_ranges;
mod protocol_versions;
mod record;
mod spread;
mod square_factors;
mod tail;
