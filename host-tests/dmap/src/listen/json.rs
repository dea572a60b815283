//! The JSON report of a decoded stream (`dmap listen --json`, described in
//! docs/dmap.md, "--json").

use super::decoder::Decoder;
use super::scan::{LineError, ObjectSize, ScanResult, channel_names, mm, q8, strength_ratio};
use cvm_core::objects::Object;
use cvm_core::protocol::{self, EndInfo};

/// The end line's totals as a JSON object, keyed as in the line.
pub fn totals_json(e: &EndInfo) -> serde_json::Value {
    let mut t = e.totals;
    let mut m = serde_json::Map::new();
    for (key, field) in protocol::END_FIELDS {
        m.insert(key.into(), (*field(&mut t)).into());
    }
    m.insert(protocol::DROPPED.into(), e.dropped.into());
    m.insert(protocol::VERDICT.into(), e.verdict.as_str().into());
    serde_json::Value::Object(m)
}

/// One object in JSON: `peak` and `centroid` as numbers of positions and
/// threshold ratios, sizes in positions, and in mm with `pitch_um`.
pub fn object_json(o: &Object, s: &ScanResult, pitch_um: Option<f64>) -> serde_json::Value {
    let size = ObjectSize::of(o);
    let mut v = serde_json::json!({
        "id": o.id,
        "rows": [o.row0, o.row1],
        "cols": [o.col0, o.col1],
        "area": o.area,
        "extent": [size.extent.0, size.extent.1],
        "size": [size.size.0, size.size.1],
        "peak": strength_ratio(o.peak),
        "peak_at": [o.peak_row, o.peak_col],
        "peak_magnitude": s.units(o.peak_mag),
        "peak_power": cvm_core::power::to_units(o.peak_power as u32),
        "peak_spread": cvm_core::spread::to_units(o.peak_spread),
        "centroid": [q8(o.centroid_row_q8), q8(o.centroid_col_q8)],
        "channels": channel_names(o.channels),
    });
    if let (Some(p), Some(m)) = (pitch_um, v.as_object_mut()) {
        m.insert(
            "extent_mm".into(),
            serde_json::json!([mm(size.extent.0, p), mm(size.extent.1, p)]),
        );
        m.insert(
            "size_mm".into(),
            serde_json::json!([mm(size.size.0, p), mm(size.size.1, p)]),
        );
    }
    v
}

fn problems_json(v: &[LineError]) -> Vec<serde_json::Value> {
    v.iter()
        .map(|p| serde_json::json!({"line": p.line, "kind": p.kind.name(), "what": p.what}))
        .collect()
}

/// One scan in JSON.
pub fn scan_json(s: &ScanResult, pitch_um: Option<f64>) -> serde_json::Value {
    serde_json::json!({
        "header": {
            "version": s.version,
            "firmware": s.firmware,
            "geometry": [s.geometry.0, s.geometry.1],
            "cols": s.cols,
            "kernels": s.kernels.to_string(),
            "kernel_size": s.kernel_size,
            "weights": s.weights,
            "normalise": s.normalise,
            "full_scale": s.full_scale,
            "threshold": s.threshold,
            "power_threshold": s.power_threshold,
            "spread_threshold": s.spread_threshold,
            "q": s.q,
            "scores": s.scores_enabled,
            "max_defect_lines": s.max_defect_lines,
            "reset_cause": s.reset_cause.map(|c| c.as_str()),
            "boots": s.boots,
            "rows": s.origin.map(|o| o.rows),
            "sources": s.origin.map(|o| o.sources.iter().map(|c| char::from(c.as_char())).collect::<String>()),
            "store": s.origin.map(|o| o.store.word()),
        },
        "rows": s.n_rows(),
        "objects": s.objects.iter().map(|o| object_json(o, s, pitch_um)).collect::<Vec<_>>(),
        "defects": s.defects.iter().map(|d| serde_json::json!({
            "row": d.row,
            "col": d.col,
            "score": d.score,
            "power": d.power,
            "spread": d.spread,
            "strength": strength_ratio(d.strength),
            "channels": channel_names(d.flags),
            "flags": d.flags,
        })).collect::<Vec<_>>(),
        "verdict": s.end.map(|e| e.verdict.as_str()),
        "totals": s.end.as_ref().map(totals_json),
        "problems": problems_json(&s.problems),
        "problem_count": s.problem_count(),
    })
}

/// The whole stream as one JSON document: `objects` and `totals` of the
/// last (or only) scan (`[]` and `null` without one), `problems` of the
/// whole stream (each scan's, with `"scan"` its number from 1, then the
/// line errors, with `"scan": null`), and `scans`, every scan with its
/// header, objects, defect lines, totals and problems.
pub fn summary_json(dec: &Decoder, pitch_um: Option<f64>) -> serde_json::Value {
    let last = dec.scans.last();
    let mut problems = Vec::new();
    for (k, s) in dec.scans.iter().enumerate() {
        for p in &s.problems {
            problems.push(
                serde_json::json!({"scan": k + 1, "line": p.line, "kind": p.kind.name(), "what": p.what}),
            );
        }
    }
    for p in &dec.errors {
        problems.push(
            serde_json::json!({"scan": null, "line": p.line, "kind": p.kind.name(), "what": p.what}),
        );
    }
    let problem_count =
        dec.error_count() + dec.scans.iter().map(|s| s.problem_count()).sum::<usize>();
    serde_json::json!({
        "objects": last.map_or_else(Vec::new, |s| s.objects.iter().map(|o| object_json(o, s, pitch_um)).collect()),
        "verdict": last.and_then(|s| s.end.map(|e| e.verdict.as_str())),
        "totals": last.and_then(|s| s.end.as_ref().map(totals_json)),
        "problems": problems,
        "problem_count": problem_count,
        "damaged": !dec.damage().is_empty(),
        "line_errors": problems_json(&dec.errors),
        "line_error_count": dec.error_count(),
        "scans_skipped": dec.scans_skipped,
        "interrupted": dec.interrupted,
        "replies": dec.replies,
        "pitch_um": pitch_um,
        "scans": dec.scans.iter().map(|s| scan_json(s, pitch_um)).collect::<Vec<_>>(),
    })
}
