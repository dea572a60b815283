//! `decode`: `dmap listen`'s decoder, with all its checks, on bytes.

use crate::parse;
use dmap::listen::{ListenArgs, ScanResult, image_refusal, summary_json};
use numpy::{PyArray1, PyArray3, PyArrayMethods};
use pyo3::prelude::*;

type Image<'py> = Bound<'py, PyArray3<f64>>;

/// One scan's images (score, power, spread), or why `dmap listen -o`
/// would not write them.
type Images<'py> = (Option<(Image<'py>, Image<'py>, Image<'py>)>, Option<String>);

fn image<'py>(
    py: Python<'py>,
    s: &ScanResult,
    data: Vec<f64>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    PyArray1::from_vec(py, data).reshape([s.n_rows(), s.cols, 3])
}

fn images<'py>(py: Python<'py>, s: &ScanResult) -> PyResult<Images<'py>> {
    let refusal = match s.end {
        None => Some("has no end line (cut): its image would be partial".to_string()),
        Some(_) => image_refusal(s),
    };
    if let Some(why) = refusal {
        return Ok((None, Some(why)));
    }
    let imgs = (
        image(py, s, s.image())?,
        image(py, s, s.power_image())?,
        image(py, s, s.spread_image())?,
    );
    Ok((Some(imgs), None))
}

/// Decodes a stream of result lines as `dmap listen --json` (options in
/// its words: `--pitch-um`, `--max-scans`): the JSON document, each scan's
/// images (or why there are none), and the damage `dmap listen` fails on
/// (empty for a whole stream).
#[pyfunction]
pub fn decode<'py>(
    py: Python<'py>,
    data: &[u8],
    argv: Vec<String>,
) -> PyResult<(String, Vec<Images<'py>>, Vec<String>)> {
    let mut all: Vec<String> = vec!["--input".into(), "-".into(), "--json".into()];
    all.extend(argv);
    let args = parse::<ListenArgs>("listen", &all)?;
    let max_scans = args.max_scans as usize;
    let dec = py
        .detach(|| dmap::listen::decode_with(data, 0, max_scans))
        .map_err(crate::value_error)?;
    let doc = summary_json(&dec, args.pitch_um).to_string();
    let imgs = dec
        .scans
        .iter()
        .map(|s| images(py, s))
        .collect::<PyResult<Vec<_>>>()?;
    Ok((doc, imgs, dec.damage()))
}
