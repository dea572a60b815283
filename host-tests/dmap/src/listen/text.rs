//! The human report of a decoded stream.

use super::decoder::Decoder;
use super::scan::{ObjectSize, ScanResult, channel_names, mm, q8, strength_ratio};
use crate::fmt::fmt_num;
use cvm_core::objects::Object;
use cvm_core::protocol::{self, EndInfo};

/// Objects listed per scan in the text summary.
pub const TEXT_OBJECTS: usize = 100;

/// [`summary_text_with`] without a pitch: sizes in positions only.
pub fn summary_text(dec: &Decoder) -> String {
    summary_text_with(dec, None)
}

/// `3x5 positions`, and with a pitch `(1.00 x 1.67 mm)`: height (rows)
/// by width (columns).
fn size_text((h, w): (u64, u64), pitch_um: Option<f64>) -> String {
    match pitch_um {
        Some(p) => format!("{h}x{w} positions ({:.2} x {:.2} mm)", mm(h, p), mm(w, p)),
        None => format!("{h}x{w} positions"),
    }
}

/// A value for the report: four decimals, or four significant digits in
/// exponent form when it is huge or tiny.
fn short(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() || (1e-3..1e6).contains(&a) {
        format!("{v:.4}")
    } else {
        format!("{v:.3e}")
    }
}

/// One object of the text summary.
pub fn object_text(o: &Object, s: &ScanResult, pitch_um: Option<f64>) -> String {
    let size = ObjectSize::of(o);
    format!(
        "object {}: rows {}-{}, cols {}-{}, area {}, extent {}, defect {}; peak {:.2}x threshold at row {} col {} (magnitude {}, power {}, spread {}); centroid row {:.2} col {:.2}; channels {}",
        o.id,
        o.row0,
        o.row1,
        o.col0,
        o.col1,
        o.area,
        size_text(size.extent, pitch_um),
        size_text(size.size, pitch_um),
        strength_ratio(o.peak),
        o.peak_row,
        o.peak_col,
        short(s.units(o.peak_mag)),
        short(cvm_core::power::to_units(o.peak_power as u32)),
        short(cvm_core::spread::to_units(o.peak_spread)),
        q8(o.centroid_row_q8),
        q8(o.centroid_col_q8),
        channel_names(o.channels).join("+")
    )
}

/// The human report: per scan its header, defect lines, objects, totals
/// and problems; then the stream's line errors. With `pitch_um`, object
/// sizes in mm too.
pub fn summary_text_with(dec: &Decoder, pitch_um: Option<f64>) -> String {
    use std::fmt::Write;
    let mut o = String::new();
    for (k, s) in dec.scans.iter().enumerate() {
        let (with, without) = s.coverage();
        let _ = writeln!(
            o,
            "scan {}: firmware {}, {}x{} maps, {} rows x {} cols, threshold {}, {}, {}",
            k + 1,
            s.firmware,
            s.geometry.0,
            s.geometry.1,
            s.n_rows(),
            s.cols,
            fmt_num(s.threshold),
            match s.power_threshold {
                Some(t) => format!("power threshold {} (contrast)", short(t)),
                None => "power channel off".to_string(),
            },
            match s.spread_threshold {
                Some(t) => format!("spread threshold {} (share of the power)", short(t)),
                None => "spread channel off".to_string(),
            }
        );
        let _ = writeln!(
            o,
            "  protocol v{}, full scale {}, at most {} defect line(s) per row, reset cause {}, start {} since power-on",
            s.version,
            s.full_scale,
            s.max_defect_lines,
            s.reset_cause.map_or("-", |c| c.as_str()),
            s.boots
        );
        let total: u64 = s.rows.values().map(|r| r.defects as u64).sum();
        let _ = writeln!(o, "  defects: {total} ({} listed)", s.defects.len());
        for d in s.defects.iter().take(20) {
            let _ = writeln!(
                o,
                "    row {:4} col {:4} score {:.6} power {:.6} spread {:.6} strength {:.2}x threshold, {}",
                d.row,
                d.col,
                d.score,
                d.power,
                d.spread,
                strength_ratio(d.strength),
                channel_names(d.flags).join("+")
            );
        }
        if s.defects.len() > 20 {
            let _ = writeln!(o, "    ... {} more", s.defects.len() - 20);
        }
        let _ = writeln!(o, "  objects: {}", s.objects.len());
        for obj in s.objects.iter().take(TEXT_OBJECTS) {
            let _ = writeln!(o, "    {}", object_text(obj, s, pitch_um));
        }
        if s.objects.len() > TEXT_OBJECTS {
            let _ = writeln!(
                o,
                "    ... {} more (all of them in --json)",
                s.objects.len() - TEXT_OBJECTS
            );
        }
        if let Some(e) = s.end
            && e.totals.unobjected > 0
        {
            let _ = writeln!(
                o,
                "    {} defective position(s) are in no object (more than {} objects or runs open at once): an object may be reported in parts",
                e.totals.unobjected,
                cvm_core::objects::MAX_OBJECTS
            );
        }
        if s.scores_enabled {
            let _ = writeln!(
                o,
                "  scores: {with} positions with data, {without} without data"
            );
        }
        match &s.end {
            Some(e) => {
                let _ = writeln!(o, "  verdict: {}", verdict_text(e.verdict));
                let _ = writeln!(o, "  totals: {}", totals_text(e));
            }
            None => {
                let _ = writeln!(o, "  totals: none (no end line)");
            }
        }
        for p in s.problems.iter().take(50) {
            let _ = writeln!(
                o,
                "  problem at line {}: {} ({})",
                p.line,
                p.what,
                p.kind.name()
            );
        }
        if s.problem_count() > 50 {
            let _ = writeln!(o, "  ... {} more problems", s.problem_count() - 50);
        }
    }
    if let Some(sig) = dec.interrupted {
        let _ = writeln!(o, "interrupted by {sig}: {} scan(s) complete", dec.ended());
    }
    if dec.replies > 0 {
        let _ = writeln!(o, "command replies passed over: {}", dec.replies);
    }
    if dec.scans_skipped > 0 {
        let _ = writeln!(
            o,
            "scans skipped (beyond --max-scans): {}",
            dec.scans_skipped
        );
    }
    let _ = writeln!(o, "line errors: {}", dec.error_count());
    for e in dec.errors.iter().take(50) {
        let _ = writeln!(o, "  line {}: {} ({})", e.line, e.what, e.kind.name());
    }
    if dec.error_count() > 50 {
        let _ = writeln!(o, "  ... {} more", dec.error_count() - 50);
    }
    o
}

/// `rows 300 frames 90000 ... dropped 0`: the end line's totals in its
/// order (`sat` written out).
fn totals_text(e: &EndInfo) -> String {
    let mut t = e.totals;
    let mut parts: Vec<String> = protocol::END_FIELDS
        .iter()
        .map(|(key, field)| {
            let key = if *key == "sat" { "saturated" } else { key };
            format!("{key} {}", field(&mut t))
        })
        .collect();
    parts.push(format!("{} {}", protocol::DROPPED, e.dropped));
    parts.push(format!("{} {}", protocol::VERDICT, e.verdict.as_str()));
    parts.join(" ")
}

/// The part's verdict in words, as a PLC's REJECT pin would act on it.
fn verdict_text(v: cvm_core::Verdict) -> String {
    use cvm_core::{Fault, Verdict};
    let why = match v {
        Verdict::Good => "part good",
        Verdict::Objects => "part rejected: defect objects",
        Verdict::Fault(Fault::Missing) => "part rejected: scan faulty, positions without data",
        Verdict::Fault(Fault::Misplaced) => "part rejected: scan faulty, misplaced frames",
        Verdict::Fault(Fault::Frames) => "part rejected: scan faulty, damaged frames",
    };
    format!("{} ({why})", v.as_str())
}
