//! dmap's integration tests, one binary: each file of this folder is a
//! module, so the suite links once and its tests share the cores (one
//! binary per file linked dmap and its dependencies 38 times, and ran the
//! files one after another). `score_memory.rs` is a binary of its own:
//! it measures the peak memory of every child the process waited for.

mod common;

mod bad_input_round3;
mod bench_cli;
mod calibrate_cli;
mod calibrate_device;
mod calibrate_refs;
mod calibrate_tail;
mod calibration_input;
mod cli_flags;
mod cli_usage;
mod conformance;
mod console_bad_input;
mod console_browser;
mod console_emulate;
mod console_port;
mod console_replay;
mod edges_cli;
mod emulate;
mod fixed_cli;
mod halos_found;
mod halos_parts;
mod halos_pooled;
mod listen_crosscheck;
mod listen_input;
mod listen_interrupt;
mod listen_objects;
mod listen_vectors;
mod listen_verdict;
mod npy_io;
mod objects_cli;
mod outputs_cli;
mod readme;
mod render_objects;
mod score_cli;
mod sensor_cli;
mod sensor_twin;
mod settings_set;
mod sim_render_eval_cli;
mod stream_listen;
mod threshold_zero;
mod twin;
mod twin_commands;
mod twin_contract;
mod twin_failsafe;
mod twin_field;
mod twin_input;
mod twin_link;
mod twin_outputs;
mod twin_reset;
mod twin_store;
