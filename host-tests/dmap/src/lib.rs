//! Library side of the `dmap` host toolkit: every subcommand's logic lives in
//! a module here so that tests can call it without spawning the binary.
//!
//! Without the default feature `tools`, the library is its readers and
//! the fixed-point scorer only: the line decoder ([`listen`]), the `.npy`
//! reader and writer ([`npy`]), [`fixed`] and the output rules ([`out`]).
//! That is what the fuzz targets exercise, and they build it without the
//! command line, the console's web server or the serial port.

pub mod fixed;
pub mod fmt;
pub mod listen;
pub mod npy;
pub mod out;

/// The modules of the command line and what it drives (feature `tools`).
macro_rules! tools {
    ($($module:ident),* $(,)?) => {
        $(
            #[cfg(feature = "tools")]
            pub mod $module;
        )*
    };
}

tools!(
    bench,
    calibrate,
    calibration_file,
    child,
    cli,
    cli_values,
    console,
    elf,
    emulate,
    eval,
    font,
    halos,
    objects,
    options,
    render,
    render_marks,
    repo,
    score,
    sensor,
    settings,
    simulate,
    stream,
    twin,
    vectors,
);
