//! `cvm_dmap._native`: the Python extension of the `dmap` library. Every
//! function here hands NumPy arrays and the options (as `dmap`'s own
//! command-line words, parsed by `dmap`'s own argument definitions) to the
//! functions the `dmap` subcommands run, with the GIL released while they
//! work; the Python package `cvm_dmap` (python/cvm_dmap/) wraps them with
//! keyword arguments, docstrings and result classes.
//!
//! Errors are `ValueError`s with the one line `dmap` prints after
//! `dmap: error: `.

mod arrays;
mod decode;
mod runs;
mod sim;

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// The one-line message of an error, as `dmap` prints it.
pub(crate) fn value_error(e: anyhow::Error) -> PyErr {
    PyValueError::new_err(format!("{e:#}"))
}

/// Options in `dmap`'s words (`["--kernels", "square", ...]`) parsed by the
/// subcommand's own definitions `T` (defaults, value checks and messages
/// included), as `dmap <command>` parses them; a refusal is clap's message
/// on one line, as `dmap` prints it.
pub(crate) fn parse<T: clap::Args + clap::FromArgMatches>(
    command: &'static str,
    argv: &[String],
) -> PyResult<T> {
    let cmd = T::augment_args(clap::Command::new(command).no_binary_name(true));
    let m = cmd
        .try_get_matches_from(argv)
        .map_err(|e| PyValueError::new_err(one_line(&e.to_string())))?;
    T::from_arg_matches(&m).map_err(|e| PyValueError::new_err(one_line(&e.to_string())))
}

/// clap's message without its usage text and hint, on one line (as
/// `dmap`'s `main` prints it).
fn one_line(text: &str) -> String {
    let what: Vec<&str> = text
        .lines()
        .take_while(|l| !l.starts_with("Usage:"))
        .map(|l| l.trim().trim_start_matches("error: "))
        .filter(|l| !l.is_empty() && !l.starts_with("For more information"))
        .collect();
    what.join(" ")
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(runs::score, m)?)?;
    m.add_function(wrap_pyfunction!(runs::score_many, m)?)?;
    m.add_function(wrap_pyfunction!(runs::stream, m)?)?;
    m.add_function(wrap_pyfunction!(runs::calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(decode::decode, m)?)?;
    m.add_function(wrap_pyfunction!(sim::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(sim::eval, m)?)?;
    m.add("MAX_COLS", dmap::settings::MAX_COLS)?;
    Ok(())
}
