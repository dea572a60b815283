//! Library side of the `dmap` host toolkit: every subcommand's logic lives in
//! a module here so that tests can call it without spawning the binary.

pub mod npy;
pub mod score;

pub mod fixed;
pub mod options;
pub mod eval;
pub mod font;
pub mod render;
pub mod simulate;
