//! What one line's fields contradict, among themselves or in the scan's
//! header (docs/protocol.md, "What a decoder checks"): each is a problem
//! of the scan of kind `field`, and the line is kept. The decisions and
//! strengths are computed here from the document's definitions, not with
//! the encoder's code.

use super::scan::{Defect, ScanResult};
use cvm_core::RowSummary;
use cvm_core::flags;
use cvm_core::protocol::{self, EndInfo};

/// `floor(2^16 · v / t)`, saturating; a threshold of 0 gives the largest
/// strength (docs/protocol.md, "Values", Strength).
fn ratio(v: u32, t: u32) -> u32 {
    if t == 0 {
        return u32::MAX;
    }
    ((u64::from(v) << 16) / u64::from(t)).min(u64::from(u32::MAX)) as u32
}

/// The decision bits and the strength of a position with data of
/// magnitudes `mag`, `pmag` and `smag` under the thresholds `thr`, `pthr`
/// and `sthr` (a spread channel that is off has `sthr` 4294967295, above
/// every spread magnitude).
pub(super) fn decide(mag: u32, pmag: u16, smag: u32, [thr, pthr, sthr]: [u32; 3]) -> (u8, u32) {
    let (mut bits, mut strength) = (0, 0);
    if mag >= thr {
        bits |= flags::CVM_DEFECT;
        strength = ratio(mag, thr);
    }
    if u32::from(pmag) >= pthr {
        bits |= flags::POWER_DEFECT;
        strength = strength.max(ratio(u32::from(pmag), pthr));
    }
    if smag >= sthr {
        bits |= flags::SPREAD_DEFECT;
        strength = strength.max(ratio(smag, sthr));
    }
    (bits, strength)
}

/// The channels of `bits` joined by `+` (`cvm+power+spread`, `cvm`, ...), or `none`.
pub(super) fn channels(bits: u8) -> String {
    match super::scan::channel_names(bits).join("+") {
        s if s.is_empty() => "none".to_string(),
        s => s,
    }
}

/// An `R` line against itself and the header.
pub(super) fn row_fault(s: &ScanResult, r: &RowSummary, listed: u32) -> Vec<String> {
    let mut out = Vec::new();
    let at = format!("R line of row {}", r.row);
    let cols = s.cols as u64;
    for (name, c) in [("argmax", r.argmax), ("pargmax", r.pargmax)] {
        if let Some(c) = c
            && u64::from(c) >= cols
        {
            out.push(format!(
                "{at}: {name} {c} is past the scan's {cols} columns"
            ));
        }
    }
    match (r.argmax, r.pargmax) {
        (None, None) => {
            let data = [r.max, r.pmax, r.defects, r.dark, r.saturated];
            if data != [0; 5] || u64::from(r.no_data) != cols {
                out.push(format!(
                    "{at}: argmax and pargmax say no position had data, but max {}, pmax {}, defects {}, dark {}, saturated {} are not all 0 or no_data {} is not the {cols} columns",
                    r.max, r.pmax, r.defects, r.dark, r.saturated, r.no_data
                ));
            }
        }
        (Some(_), Some(_)) => {
            let with_data = cols.saturating_sub(u64::from(r.no_data));
            let marked = u64::from(r.dark) + u64::from(r.saturated);
            if u64::from(r.no_data) >= cols
                || u64::from(r.defects) > with_data
                || marked > with_data
            {
                out.push(format!(
                    "{at}: no_data {}, defects {}, dark {} and saturated {} do not fit {cols} columns with data at argmax",
                    r.no_data, r.defects, r.dark, r.saturated
                ));
            }
        }
        _ => out.push(format!(
            "{at}: one of argmax and pargmax is '-', the other not"
        )),
    }
    let want = r.defects.min(u32::from(s.max_defect_lines));
    if listed != want {
        out.push(format!(
            "{at}: listed {listed}, but {} defect(s) under the header's dcap {} list {want}",
            r.defects, s.max_defect_lines
        ));
    }
    if let Some(n) = s.header_rows
        && r.row >= n
    {
        out.push(format!("{at}: past the header's {n} rows"));
    }
    out
}

/// A `D` line against itself and the header's thresholds.
pub(super) fn defect_fault(s: &ScanResult, d: &Defect) -> Vec<String> {
    let mut out = Vec::new();
    let at = format!("D line of row {} column {}", d.row, d.col);
    if d.col as usize >= s.cols {
        out.push(format!("{at}: past the scan's {} columns", s.cols));
    }
    if (d.flags & flags::CLIPPED != 0) != (d.mag == u32::MAX) {
        out.push(format!(
            "{at}: CLIPPED is set exactly when mag is 4294967295 (flags {}, mag {})",
            d.flags, d.mag
        ));
    }
    let (bits, strength) = decide(d.mag, d.pmag, d.smag, s.thresholds());
    if bits != d.flags & flags::DEFECT {
        out.push(format!(
            "{at}: flags {} say {}, but mag {} against thr {}, pmag {} against pthr {} and smag {} against sthr {} make {}",
            d.flags,
            channels(d.flags),
            d.mag,
            s.thr,
            d.pmag,
            s.pthr,
            d.smag,
            s.sthr,
            channels(bits)
        ));
    } else if strength != d.strength {
        out.push(format!(
            "{at}: strength {}, but its magnitudes and the thresholds make {strength}",
            d.strength
        ));
    }
    out
}

/// An `S` line's positions against the header's thresholds.
pub(super) fn scores_fault(s: &ScanResult, row: u32, col0: u32, chars: &[u8]) -> Vec<String> {
    let at = format!("S line of row {row} from column {col0}");
    let mut out = Vec::new();
    if !s.scores_enabled {
        out.push(format!("{at}: the header says scores=0"));
    }
    if let Some(n) = s.header_rows
        && row >= n
    {
        out.push(format!("{at}: past the header's {n} rows"));
    }
    let mut wrong = (0usize, None);
    for (k, c) in chars.chunks(protocol::SCORE_CHARS).enumerate() {
        let Some(v) = protocol::decode_score(c) else {
            continue;
        };
        if v.flags & flags::NO_DATA != 0 {
            continue;
        }
        let (bits, _) = decide(v.mag, v.pmag, v.smag, s.thresholds());
        if bits != v.flags & flags::DEFECT {
            wrong.0 += 1;
            wrong.1.get_or_insert((col0 as usize + k, v, bits));
        }
    }
    if let (n, Some((col, v, bits))) = wrong {
        out.push(format!(
            "{at}: {n} position(s) whose flags contradict the thresholds, the first column {col}: flags {} say {}, but mag {} against thr {}, pmag {} against pthr {} and smag {} against sthr {} make {}",
            v.flags,
            channels(v.flags),
            v.mag,
            s.thr,
            v.pmag,
            s.pthr,
            v.smag,
            s.sthr,
            channels(bits)
        ));
    }
    out
}

/// The end line's totals against one another and the header: every
/// position has a frame or is missing, marked maps and defects are among
/// the frames, clipped scores among the defects, each object holds at
/// least one defect, a bad frame's position is missing, and the rows are
/// the header's.
pub(super) fn end_fault(s: &ScanResult, e: &EndInfo) -> Vec<String> {
    let t = &e.totals;
    let n = |v: u32| u64::from(v);
    let mut out = Vec::new();
    let positions = n(t.rows) * s.cols as u64;
    if n(t.frames) + n(t.missing) != positions {
        out.push(format!(
            "end line: frames {} and missing {} do not add up to rows {} x {} columns = {positions}",
            t.frames, t.missing, t.rows, s.cols
        ));
    }
    for (what, part, of, whole) in [
        (
            "dark + sat",
            n(t.dark) + n(t.saturated),
            "frames",
            n(t.frames),
        ),
        ("defects", n(t.defects), "frames", n(t.frames)),
        ("misplaced", n(t.misplaced), "frames", n(t.frames)),
        ("bad", n(t.bad), "missing", n(t.missing)),
        ("clipped", n(t.clipped), "defects", n(t.defects)),
        (
            "obj + unobj",
            n(t.objects) + n(t.unobjected),
            "defects",
            n(t.defects),
        ),
    ] {
        if part > whole {
            out.push(format!(
                "end line: {what} ({part}) is more than {of} ({whole})"
            ));
        }
    }
    if !s.scores_enabled && e.dropped > 0 {
        out.push(format!(
            "end line: dropped {}, but the header says scores=0",
            e.dropped
        ));
    }
    if let Some(rows) = s.header_rows
        && rows != t.rows
    {
        out.push(format!(
            "end line: rows {}, but the header says {rows}",
            t.rows
        ));
    }
    out
}
