//! The checks a scan's lines must pass beyond their CRC: an object that
//! fits its box and the scan, and a finished scan whose lines agree with
//! one another and with its end line.

use super::crosscheck::cross_check;
use super::scan::{Kind, LineError, ScanResult, q8};
use cvm_core::objects::Object;
use cvm_core::protocol::{self, EndInfo, HeaderInfo};
use cvm_core::{Fault, Verdict};

/// Cross-checks a finished scan: every row has its row line, every
/// listed defect arrived, every position has a score when scores are on.
pub(super) fn check_complete(s: &mut ScanResult, line_no: usize) {
    let rows = s.n_rows() as u32;
    // Gaps between the rows received, not every missing row: an end line
    // may claim billions of rows.
    let missing = gaps(s.rows.keys().copied(), rows);
    let count: u64 = missing.iter().map(|&(a, b)| u64::from(b - a) + 1).sum();
    if count > 0 {
        s.add_problem(LineError {
            line: line_no,
            kind: Kind::Missing,
            what: format!("no row line for {count} row(s): {}", ranges(&missing)),
        });
    }
    let listed: u64 = s.rows.values().map(|r| r.defects as u64).sum::<u64>() - s.unlisted_defects;
    if listed != s.defects.len() as u64 {
        s.add_problem(LineError {
            line: line_no,
            kind: Kind::Missing,
            what: format!(
                "row lines list {listed} defect line(s), {} arrived",
                s.defects.len()
            ),
        });
    }
    if let Some(e) = s.end
        && let Some(what) = verdict_fault(&e)
    {
        s.add_problem(LineError {
            line: line_no,
            kind: Kind::Verdict,
            what,
        });
    }
    if let Some(e) = s.end {
        let (claimed, arrived) = (u64::from(e.totals.objects), s.objects_arrived);
        if claimed != arrived {
            s.add_problem(LineError {
                line: line_no,
                kind: Kind::Missing,
                what: format!(
                    "end line counts {claimed} object(s), {arrived} object line(s) arrived"
                ),
            });
        } else if s.objects.len() as u64 == arrived {
            // Every defective position is in one object or counted in `unobj`.
            let covered: u64 = s.objects.iter().map(|o| u64::from(o.area)).sum();
            let left_out = u64::from(e.totals.unobjected);
            if covered + left_out != u64::from(e.totals.defects) {
                s.add_problem(LineError {
                    line: line_no,
                    kind: Kind::CrossCheck,
                    what: format!(
                        "objects cover {covered} position(s) and {left_out} were left out of every object, but the end line counts {} defect(s)",
                        e.totals.defects
                    ),
                });
            }
        }
    }
    let misplaced = s.end.map_or(0, |e| e.totals.misplaced);
    if misplaced > 0 {
        s.add_problem(LineError {
            line: line_no,
            kind: Kind::Misplaced,
            what: format!(
                "end line: misplaced {misplaced}: map(s) scored at a wrong position (a short row: beams without DRDY); \
                 scores next to the short row are unreliable"
            ),
        });
    }
    if s.scores_enabled {
        // A score line the firmware dropped and counted is allowed; one
        // lost otherwise (or one too many counted) is damage.
        let dropped = s.end.map_or(0, |e| u64::from(e.dropped));
        let expected = u64::from(rows) * s.cols.div_ceil(protocol::SCORES_PER_LINE) as u64;
        let missing = expected.saturating_sub(s.score_lines);
        if missing != dropped {
            s.add_problem(LineError {
                line: line_no,
                kind: Kind::Missing,
                what: format!(
                    "{missing} of {expected} score line(s) missing, but the end line counts {dropped} dropped"
                ),
            });
        }
    }
    if let Some(e) = s.end {
        for p in cross_check(s, &e, line_no) {
            s.add_problem(p);
        }
    }
}

/// What is impossible about an object of a scan of `cols` columns, if
/// anything: a box past the last column, an area beyond its box, a peak
/// or a centroid outside its box. (Each field's own range, an area of 0,
/// a peak below the threshold, no channel, is the parser's.)
pub(super) fn object_fault(o: &Object, cols: usize) -> Option<String> {
    let (h, w) = (
        u64::from(o.row1 - o.row0) + 1,
        u64::from(o.col1 - o.col0) + 1,
    );
    let inside = |r: u32, c: u32| (o.row0..=o.row1).contains(&r) && (o.col0..=o.col1).contains(&c);
    let box_q8 = |v: u64, a: u32, b: u32| (u64::from(a) << 8..=u64::from(b) << 8).contains(&v);
    if o.col1 as usize >= cols {
        Some(format!(
            "columns {}-{} run past the scan's {cols} columns",
            o.col0, o.col1
        ))
    } else if u64::from(o.area) > h * w {
        Some(format!("area {} does not fit its {h}x{w} box", o.area))
    } else if !inside(o.peak_row, o.peak_col) {
        Some(format!(
            "peak_row {} peak_col {} outside its box (rows {}-{}, columns {}-{})",
            o.peak_row, o.peak_col, o.row0, o.row1, o.col0, o.col1
        ))
    } else if !box_q8(o.centroid_row_q8, o.row0, o.row1)
        || !box_q8(o.centroid_col_q8, o.col0, o.col1)
    {
        Some(format!(
            "centroid_row_q8 {} centroid_col_q8 {} ({:.2}, {:.2}) outside its box",
            o.centroid_row_q8,
            o.centroid_col_q8,
            q8(o.centroid_row_q8),
            q8(o.centroid_col_q8)
        ))
    } else {
        None
    }
}

/// What the header's fields contradict among themselves, if anything:
/// with uniform or unit weights the header names the whole scoring
/// configuration, so `q` is the one a scorer of it has (separable weights
/// travel without their values: only `q`'s range is known).
pub(super) fn header_fault(h: &HeaderInfo<'_>) -> Option<String> {
    use cvm_core::{Config, Geometry, Kernels, Scorer, Weights};
    let weights = match h.weights {
        "uniform" => Weights::Uniform,
        "unit" => Weights::Unit,
        _ => return None,
    };
    let kernels = match h.kernels {
        b'S' => Kernels::Square {
            kmax: h.kernel_size,
        },
        _ => Kernels::Paper {
            bmax: h.kernel_size,
        },
    };
    let what = format!(
        "j={}x{}, k={}, b={}, w={}, norm={}",
        h.j1,
        h.j2,
        h.kernels as char,
        h.kernel_size,
        h.weights,
        u8::from(h.normalise)
    );
    let cfg = Config {
        geometry: Geometry::new(h.j1, h.j2).ok()?,
        kernels,
        weights,
        normalise: h.normalise,
        full_scale: h.full_scale,
    };
    match Scorer::new(&cfg) {
        Ok(s) if s.score_frac_bits() == h.q => None,
        Ok(s) => Some(format!(
            "header: q={}, but a scorer of {what} has q={}",
            h.q,
            s.score_frac_bits()
        )),
        Err(e) => Some(format!("header: no scorer has {what} ({e})")),
    }
}

/// The ranges of `0..end` not in `present` (ascending).
fn gaps(present: impl Iterator<Item = u32>, end: u32) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    let mut next = 0;
    for k in present.take_while(|&k| k < end) {
        if k > next {
            out.push((next, k - 1));
        }
        next = k + 1;
    }
    if next < end {
        out.push((next, end - 1));
    }
    out
}

/// `1-3, 7` style list, at most a dozen ranges.
fn ranges(v: &[(u32, u32)]) -> String {
    let mut out: Vec<String> = v
        .iter()
        .take(12)
        .map(|&(a, b)| {
            if a == b {
                a.to_string()
            } else {
                format!("{a}-{b}")
            }
        })
        .collect();
    if v.len() > 12 {
        out.push(format!("and {} more ranges", v.len() - 12));
    }
    out.join(", ")
}

/// What is wrong with the end line's verdict given its own totals, as far
/// as the totals decide it without the board's limits (how many missing
/// or misplaced positions a scan may have, which objects count).
pub(super) fn verdict_fault(e: &EndInfo) -> Option<String> {
    let t = &e.totals;
    let frames = t.bad > 0 || t.rejected > 0 || t.extra > 0;
    let v = e.verdict;
    let why = match v {
        _ if frames != (v == Verdict::Fault(Fault::Frames)) => {
            "bad, rejected and extra frames make the verdict fault-frames, and only they do"
        }
        Verdict::Good if t.unobjected > 0 => {
            "defects left out of every object, yet the part is good"
        }
        Verdict::Objects if t.objects == 0 && t.unobjected == 0 => {
            "no object, yet the verdict is obj"
        }
        Verdict::Fault(Fault::Missing) if t.missing == 0 => {
            "no position without data, yet the verdict is fault-missing"
        }
        Verdict::Fault(Fault::Misplaced) if t.misplaced == 0 => {
            "no misplaced frame, yet the verdict is fault-misplaced"
        }
        _ => return None,
    };
    Some(format!("end line: verdict {}: {why}", v.as_str()))
}
