//! `simulate` and `eval`: `dmap simulate` into arrays, `dmap eval` on
//! arrays.

use crate::{parse, value_error};
use dmap::eval::EvalArgs;
use dmap::simulate::SimulateArgs;
use numpy::{
    PyArray1, PyArray2, PyArray4, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// A scan, its truth mask, and the beam power summary.
type Simulated<'py> = (
    Bound<'py, PyArray4<u16>>,
    Bound<'py, PyArray2<bool>>,
    String,
);

/// `dmap simulate` with its options in its words: the scan (`uint16`,
/// `(rows, cols, J1, J2)`), the truth mask (`bool`, `(rows, cols)`) and
/// the summary lines it prints.
#[pyfunction]
pub fn simulate<'py>(py: Python<'py>, argv: Vec<String>) -> PyResult<Simulated<'py>> {
    let mut all: Vec<String> = vec!["-o".into(), "scan.npy".into()];
    all.extend(argv);
    let a = parse::<SimulateArgs>("simulate", &all)?;
    let cfg = dmap::simulate::config(&a).map_err(value_error)?;
    cvm_reference::Geometry::new(cfg.receiver.j1, cfg.receiver.j2)
        .map_err(|e| PyValueError::new_err(format!("--detector: {e}")))?;
    let scan = py
        .detach(|| dmap::simulate::simulate_with(&cfg, a.threads, &|| {}))
        .map_err(value_error)?;
    let summary = dmap::simulate::budget_summary(&scan, &cfg);
    let (rows, cols, j1, j2) = (scan.rows, scan.cols, scan.j1, scan.j2);
    let data = PyArray1::from_vec(py, scan.data).reshape([rows, cols, j1, j2])?;
    let truth = PyArray1::from_vec(py, scan.truth).reshape([rows, cols])?;
    Ok((data, truth, summary))
}

/// One channel of a gradient image array `(rows, cols, 3)` (float64 or
/// float32), as `dmap eval` reads a file.
fn channel(grad: &Bound<'_, PyAny>, ch: usize) -> PyResult<(usize, usize, Vec<f64>)> {
    let bad = |what: String| PyValueError::new_err(format!("grad: {what}"));
    let shape_of = |a: &[usize]| {
        if a.len() != 3 || a[2] != 3 {
            Err(bad(format!(
                "a gradient image must have shape (rows, cols, 3), got {a:?}"
            )))
        } else {
            Ok((a[0], a[1]))
        }
    };
    let pick = |v: Vec<f64>| -> PyResult<Vec<f64>> {
        if ch >= 3 {
            return Err(PyValueError::new_err(format!(
                "--component {ch} does not exist: 0 horizontal, 1 vertical, 2 magnitude"
            )));
        }
        Ok(v.chunks_exact(3).map(|c| c[ch]).collect())
    };
    let (rows, cols, values) = if let Ok(a) = grad.extract::<PyReadonlyArrayDyn<'_, f64>>() {
        let (r, c) = shape_of(a.shape())?;
        (r, c, pick(a.as_array().iter().copied().collect())?)
    } else if let Ok(a) = grad.extract::<PyReadonlyArrayDyn<'_, f32>>() {
        let (r, c) = shape_of(a.shape())?;
        (
            r,
            c,
            pick(a.as_array().iter().map(|&x| f64::from(x)).collect())?,
        )
    } else {
        return Err(bad(
            "a gradient image must be a float64 (or float32) array (rows, cols, 3)".into(),
        ));
    };
    if rows == 0 || cols == 0 {
        return Err(bad(format!("empty array {rows}x{cols}")));
    }
    Ok((rows, cols, values))
}

/// `dmap eval --json` on a gradient image and a truth mask (options in its
/// words): the JSON document, and the metrics beside it as a JSON object.
#[pyfunction]
pub fn eval(
    grad: &Bound<'_, PyAny>,
    truth: &Bound<'_, PyAny>,
    argv: Vec<String>,
) -> PyResult<(String, String)> {
    let mut all: Vec<String> = vec![
        "grad".into(),
        "--truth".into(),
        "truth".into(),
        "--json".into(),
    ];
    all.extend(argv);
    let a = parse::<EvalArgs>("eval", &all)?;
    dmap::eval::check_args(&a).map_err(value_error)?;
    let (rows, cols, values) = channel(grad, a.component.index())?;
    let mask = truth
        .extract::<PyReadonlyArrayDyn<'_, bool>>()
        .map_err(|_| PyValueError::new_err("truth: a mask must be a bool array (rows, cols)"))?;
    if mask.ndim() != 2 {
        return Err(PyValueError::new_err(format!(
            "truth: a mask must have shape (rows, cols), got {:?}",
            mask.shape()
        )));
    }
    if (mask.shape()[0], mask.shape()[1]) != (rows, cols) {
        return Err(PyValueError::new_err(format!(
            "truth mask truth is {}x{} but the scores are {rows}x{cols}",
            mask.shape()[0],
            mask.shape()[1]
        )));
    }
    let t: Vec<bool> = mask.as_array().iter().copied().collect();
    let e = dmap::eval::evaluate(&a, (rows, cols), &values, &t).map_err(value_error)?;
    let m = &e.metrics;
    let num = |v: f64| serde_json::Number::from_f64(v).map_or(serde_json::Value::Null, Into::into);
    let extra = serde_json::json!({
        "mean_defect": num(m.mean_defect),
        "max_defect": num(m.max_defect),
        "mean_free": num(m.mean_free),
        "std_free": num(m.std_free),
        "n_defect": m.n_defect,
        "n_free": m.n_free,
        "nan_defect": m.nan_defect,
        "nan_free": m.nan_free,
        "rule": e.rule,
    });
    Ok((e.json(a.pitch_um).to_string(), extra.to_string()))
}
