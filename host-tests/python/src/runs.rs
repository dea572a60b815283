//! `score`, `score_many`, `stream` and `calibrate`: `dmap score`, `dmap
//! stream` and `dmap calibrate` on arrays (or, for `calibrate`, files).

use crate::arrays::{ScanArray, View};
use crate::{parse, value_error};
use dmap::calibrate::{CalibrateArgs, Calibration};
use dmap::npy::ScanFile;
use dmap::score::ScoreArgs;
use dmap::stream::StreamArgs;
use numpy::{PyArray3, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// `dmap score`'s options, words after `SCAN -o OUT`.
fn score_args(argv: &[String]) -> PyResult<ScoreArgs> {
    let mut all: Vec<String> = vec!["scan".into(), "-o".into(), "-".into()];
    all.extend_from_slice(argv);
    parse::<ScoreArgs>("score", &all)
}

/// Scores `view` as `dmap score` with `args`, into `out` (`rows * cols *
/// 3` values); returns the warnings.
fn score_into(view: View<'_>, args: &ScoreArgs, out: &mut [f64]) -> anyhow::Result<Vec<String>> {
    let scan = view.open()?;
    let mut at = 0;
    dmap::score::score_scan(
        &scan,
        args.distance,
        &args.scoring,
        args.ground,
        &mut |band| {
            out[at..at + band.len()].copy_from_slice(band);
            at += band.len();
            Ok(())
        },
    )
}

/// Output arrays `(rows, cols, 3)` for scans of these positions (1 x 1
/// for a shape `open` will refuse, never used).
fn outputs<'py>(py: Python<'py>, views: &[View<'_>]) -> Vec<Bound<'py, PyArray3<f64>>> {
    views
        .iter()
        .map(|v| {
            let (r, c) = v.positions();
            let n = r.checked_mul(c).and_then(|n| n.checked_mul(3));
            let (r, c) = if n.is_some_and(|n| n <= isize::MAX as usize / 8) {
                (r, c)
            } else {
                (1, 1)
            };
            PyArray3::<f64>::zeros(py, [r, c, 3], false)
        })
        .collect()
}

/// The gradient image of one scan and the warnings (`dmap score`).
#[pyfunction]
pub fn score<'py>(
    py: Python<'py>,
    scan: &Bound<'py, PyAny>,
    argv: Vec<String>,
) -> PyResult<(Bound<'py, PyArray3<f64>>, Vec<String>)> {
    let args = score_args(&argv)?;
    let held = ScanArray::new(scan, "scan")?;
    let view = held.view();
    let out = outputs(py, &[view]).remove(0);
    let mut rw = out.readwrite();
    let slice = rw.as_slice_mut().expect("a new array is contiguous");
    let warnings = py
        .detach(|| score_into(view, &args, slice))
        .map_err(value_error)?;
    drop(rw);
    Ok((out, warnings))
}

/// Images and each one's warnings.
type Many<'py> = (Vec<Bound<'py, PyArray3<f64>>>, Vec<Vec<String>>);

/// The gradient images of many scans, scored in parallel (`dmap score`
/// on each); the warnings of each.
#[pyfunction]
pub fn score_many<'py>(
    py: Python<'py>,
    scans: Vec<Bound<'py, PyAny>>,
    argv: Vec<String>,
) -> PyResult<Many<'py>> {
    let args = score_args(&argv)?;
    let held = scans
        .iter()
        .enumerate()
        .map(|(i, s)| ScanArray::new(s, &format!("scans[{i}]")))
        .collect::<PyResult<Vec<_>>>()?;
    let views: Vec<View<'_>> = held.iter().map(ScanArray::view).collect();
    let outs = outputs(py, &views);
    let mut rws: Vec<_> = outs.iter().map(|o| o.readwrite()).collect();
    let slices: Vec<&mut [f64]> = rws
        .iter_mut()
        .map(|rw| rw.as_slice_mut().expect("a new array is contiguous"))
        .collect();
    let results: Vec<anyhow::Result<Vec<String>>> = py.detach(|| {
        views
            .par_iter()
            .zip(slices)
            .map(|(v, out)| score_into(*v, &args, out))
            .collect()
    });
    drop(rws);
    let warnings = results
        .into_iter()
        .collect::<anyhow::Result<Vec<_>>>()
        .map_err(value_error)?;
    Ok((outs, warnings))
}

/// The firmware's result lines for one scan and the warnings (`dmap
/// stream`); `calibration` the text of the calibration that `--calibration
/// NAME` in `argv` names, if it is not to be read from a file.
#[pyfunction]
#[pyo3(signature = (scan, argv, calibration=None))]
pub fn stream<'py>(
    py: Python<'py>,
    scan: &Bound<'py, PyAny>,
    argv: Vec<String>,
    calibration: Option<String>,
) -> PyResult<(Bound<'py, PyBytes>, Vec<String>)> {
    let mut all: Vec<String> = vec!["scan".into()];
    all.extend(argv);
    let args = parse::<StreamArgs>("stream", &all)?;
    let held = ScanArray::new(scan, "scan")?;
    let view = held.view();
    let load = |path: &Path| match &calibration {
        Some(text) => Calibration::from_text(path, text),
        None => Calibration::load(path),
    };
    let (lines, warnings) = py
        .detach(|| {
            let scan = view.open()?;
            let mut lines = Vec::new();
            let w = dmap::stream::stream_with(
                &scan,
                (&args.scoring, &args.output, args.from_flash),
                &load,
                &mut |b| {
                    lines.extend_from_slice(b);
                    Ok(())
                },
            )?;
            anyhow::Ok((lines, w))
        })
        .map_err(value_error)?;
    Ok((PyBytes::new(py, &lines), warnings))
}

/// A reference: an array, or a file `dmap calibrate` would read.
enum Reference<'py> {
    Array(ScanArray<'py>),
    File(PathBuf),
}

/// `dmap calibrate` on references (arrays, or `.npy` paths as `str`),
/// named `names` in the file: the calibration file's text, the summary
/// line and the warnings.
#[pyfunction]
pub fn calibrate<'py>(
    py: Python<'py>,
    refs: Vec<Bound<'py, PyAny>>,
    names: Vec<String>,
    argv: Vec<String>,
) -> PyResult<(String, String, Vec<String>)> {
    if names.len() != refs.len() {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "{} names for {} references",
            names.len(),
            refs.len()
        )));
    }
    let mut all = argv;
    all.extend(["-o".into(), "-".into(), "--".into()]);
    all.extend(names.iter().cloned());
    let args = parse::<CalibrateArgs>("calibrate", &all)?;
    let rule = dmap::calibrate::rule(&args).map_err(value_error)?;
    let held = refs
        .iter()
        .zip(&names)
        .map(|(r, name)| match r.cast::<pyo3::types::PyString>() {
            Ok(path) => Ok(Reference::File(path.extract::<PathBuf>()?)),
            Err(_) => ScanArray::new(r, name).map(Reference::Array),
        })
        .collect::<PyResult<Vec<_>>>()?;
    enum Ref<'a> {
        View(View<'a>),
        File(&'a Path),
    }
    let refs: Vec<Ref<'_>> = held
        .iter()
        .map(|h| match h {
            Reference::Array(a) => Ref::View(a.view()),
            Reference::File(p) => Ref::File(p),
        })
        .collect();
    let out = py
        .detach(|| {
            dmap::calibrate::calibrate_with(&args, &rule, &mut |i| match &refs[i] {
                Ref::View(v) => v.open(),
                Ref::File(p) => {
                    let earlier: Vec<&Path> = refs[..i]
                        .iter()
                        .filter_map(|r| match r {
                            Ref::File(q) => Some(*q),
                            Ref::View(_) => None,
                        })
                        .collect();
                    dmap::calibrate::checks::refuse_duplicate(p, &earlier)?;
                    ScanFile::open(p)
                }
            })
        })
        .map_err(value_error)?;
    Ok((out.text, out.summary, out.warnings))
}
