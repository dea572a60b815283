//! Library side of the `dmap` host toolkit: every subcommand's logic lives in
//! a module here so that tests can call it without spawning the binary.

pub mod bench;
pub mod calibrate;
pub mod calibration_file;
pub mod child;
pub mod cli;
pub mod cli_values;
pub mod console;
pub mod elf;
pub mod emulate;
pub mod eval;
pub mod fixed;
pub mod fmt;
pub mod font;
pub mod halos;
pub mod listen;
pub mod npy;
pub mod objects;
pub mod options;
pub mod out;
pub mod render;
pub mod render_marks;
pub mod repo;
pub mod score;
pub mod sensor;
pub mod settings;
pub mod simulate;
pub mod stream;
pub mod twin;
pub mod vectors;
