//! The firmware logic's host tests, one binary: each file of this folder is a
//! module, so the suite links once and its tests share the cores.

mod control;
mod logic;
mod outputs;
mod queue_model;
mod runtime;
mod sequencer_edges;
mod settings_store;
