//! `dmap eval`: the paper's detection metrics (docs/method.md §3) and per-defect
//! size estimates of a gradient image against a ground-truth mask.

use std::path::{Path, PathBuf};

use crate::cli_values::Component;
use crate::fmt::fmt_num;
use crate::objects::components;
use anyhow::{Result, bail};
use clap::Args;
use std::fmt::Write;

#[derive(Args, Clone, Debug)]
pub struct EvalArgs {
    /// Gradient image (.npy, rows x cols x 3)
    #[arg(value_name = "GRAD.npy")]
    pub input: PathBuf,
    /// Ground-truth mask (.npy, bool, rows x cols)
    #[arg(long, value_name = "MASK.npy")]
    pub truth: PathBuf,
    /// Component of a rows x cols x 3 gradient image (or its index 0, 1, 2)
    #[arg(long, alias = "channel", value_enum, default_value = "magnitude")]
    pub component: Component,
    /// Score above which a position counts as defective (default: defect-free mean + K std)
    #[arg(long, allow_hyphen_values = true)]
    pub threshold: Option<f64>,
    /// Threshold from a calibration file (`dmap calibrate`, with or without --from-scores), in distance units
    #[arg(long, value_name = "CAL.json", conflicts_with = "threshold")]
    pub calibration: Option<PathBuf>,
    /// K of the automatic threshold: the defect-free mean plus K standard deviations
    #[arg(long = "k-std", alias = "k", value_name = "K", default_value_t = 5.0)]
    pub k: f64,
    /// Positions around each truth component searched for above-threshold scores
    #[arg(long, default_value_t = 2)]
    pub dilate: usize,
    /// Distance between scan positions (µm)
    #[arg(long, default_value_t = 334.0)]
    pub pitch_um: f64,
    /// Print one JSON object instead of the table
    #[arg(long)]
    pub json: bool,
}

/// Statistics of the paper's Eqs. 11-12 and the CNR. NaN pixels are left
/// out of every statistic and counted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metrics {
    pub snr: f64,
    pub psnr: f64,
    pub cnr: f64,
    pub mean_defect: f64,
    pub max_defect: f64,
    pub mean_free: f64,
    /// Population standard deviation (ddof = 0) over defect-free pixels.
    pub std_free: f64,
    pub n_defect: usize,
    pub n_free: usize,
    pub nan_defect: usize,
    pub nan_free: usize,
}

/// SNR, PSNR and CNR of `values` with defect pixels where `truth` is set.
/// Statistics over an empty set are NaN.
pub fn metrics(values: &[f64], truth: &[bool]) -> Metrics {
    let (mut sd, mut maxd, mut nd, mut nand) = (0.0, f64::NEG_INFINITY, 0usize, 0usize);
    let (mut sf, mut nf, mut nanf) = (0.0, 0usize, 0usize);
    for (&v, &t) in values.iter().zip(truth) {
        match (v.is_nan(), t) {
            (true, true) => nand += 1,
            (true, false) => nanf += 1,
            (false, true) => {
                sd += v;
                maxd = maxd.max(v);
                nd += 1;
            }
            (false, false) => {
                sf += v;
                nf += 1;
            }
        }
    }
    let nan = f64::NAN;
    let mean_defect = if nd > 0 { sd / nd as f64 } else { nan };
    let max_defect = if nd > 0 { maxd } else { nan };
    let mean_free = if nf > 0 { sf / nf as f64 } else { nan };
    // Two-pass variance: the scores span many decades.
    let std_free = if nf > 0 {
        let ss: f64 = values
            .iter()
            .zip(truth)
            .filter(|(v, t)| !**t && !v.is_nan())
            .map(|(v, _)| (v - mean_free).powi(2))
            .sum();
        (ss / nf as f64).sqrt()
    } else {
        nan
    };
    Metrics {
        snr: mean_defect / std_free,
        psnr: max_defect / std_free,
        cnr: (max_defect - mean_free).abs() / std_free,
        mean_defect,
        max_defect,
        mean_free,
        std_free,
        n_defect: nd,
        n_free: nf,
        nan_defect: nand,
        nan_free: nanf,
    }
}

/// Bounding box (rows, cols) in positions of a set of pixels.
fn extent(px: &[(usize, usize)]) -> (usize, usize) {
    if px.is_empty() {
        return (0, 0);
    }
    let (r0, r1) = px
        .iter()
        .fold((usize::MAX, 0), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let (c0, c1) = px
        .iter()
        .fold((usize::MAX, 0), |(a, b), p| (a.min(p.1), b.max(p.1)));
    (r1 - r0 + 1, c1 - c0 + 1)
}

/// Size of one defect: the truth component's bounding box and that of the
/// above-threshold positions within `dilate` positions (Chebyshev) of it,
/// both as (width = columns, height = rows) in positions.
#[derive(Clone, Debug, PartialEq)]
pub struct DefectSize {
    pub first: (usize, usize),
    pub truth: (usize, usize),
    pub estimated: (usize, usize),
    pub above: usize,
    /// Largest finite score within the searched neighbourhood (NaN if none).
    pub peak: f64,
}

pub fn defect_sizes(
    values: &[f64],
    truth: &[bool],
    rows: usize,
    cols: usize,
    threshold: f64,
    dilate: usize,
) -> Vec<DefectSize> {
    components(truth, rows, cols)
        .into_iter()
        .map(|comp| {
            let near = neighbourhood(&comp, rows, cols, dilate);
            let hits: Vec<(usize, usize)> = (0..values.len())
                .filter(|&i| near[i] && values[i] > threshold)
                .map(|i| (i / cols, i % cols))
                .collect();
            let peak = (0..values.len())
                .filter(|&i| near[i] && !values[i].is_nan())
                .map(|i| values[i])
                .fold(f64::NAN, f64::max);
            let (th, tw) = extent(&comp);
            let (eh, ew) = extent(&hits);
            DefectSize {
                first: comp[0],
                truth: (tw, th),
                estimated: (ew, eh),
                above: hits.len(),
                peak,
            }
        })
        .collect()
}

/// The positions within `dilate` (Chebyshev distance) of any pixel of
/// `comp`, as a `rows x cols` mask. Per pixel when that is cheap, else by a
/// summed-area table of the component (linear in the image, whatever
/// `dilate`); the window is clipped to the image, never wrapped.
fn neighbourhood(comp: &[(usize, usize)], rows: usize, cols: usize, dilate: usize) -> Vec<bool> {
    let side = dilate.saturating_mul(2).saturating_add(1);
    let mut near = vec![false; rows * cols];
    if comp.len().saturating_mul(side.saturating_mul(side)) <= rows * cols {
        for &(r, c) in comp {
            for nr in r.saturating_sub(dilate)..=r.saturating_add(dilate).min(rows - 1) {
                for nc in c.saturating_sub(dilate)..=c.saturating_add(dilate).min(cols - 1) {
                    near[nr * cols + nc] = true;
                }
            }
        }
        return near;
    }
    // sat[(r + 1) * (cols + 1) + c + 1]: component pixels in rows 0..=r, cols 0..=c.
    let w = cols + 1;
    let mut sat = vec![0u32; (rows + 1) * w];
    for &(r, c) in comp {
        sat[(r + 1) * w + c + 1] = 1;
    }
    for r in 1..=rows {
        for c in 1..=cols {
            sat[r * w + c] += sat[(r - 1) * w + c] + sat[r * w + c - 1] - sat[(r - 1) * w + c - 1];
        }
    }
    for r in 0..rows {
        let (r0, r1) = (
            r.saturating_sub(dilate),
            r.saturating_add(dilate).min(rows - 1) + 1,
        );
        for c in 0..cols {
            let (c0, c1) = (
                c.saturating_sub(dilate),
                c.saturating_add(dilate).min(cols - 1) + 1,
            );
            let n = sat[r1 * w + c1] + sat[r0 * w + c0] - sat[r0 * w + c1] - sat[r1 * w + c0];
            near[r * cols + c] = n > 0;
        }
    }
    near
}

/// Load one channel of a gradient file as (rows, cols, values).
fn load_scores(path: &Path, channel: usize) -> Result<(usize, usize, Vec<f64>)> {
    let p = crate::render::load_panel(path, channel, String::new())?;
    Ok((p.rows, p.cols, p.values))
}

fn json_num(v: f64) -> serde_json::Value {
    // JSON has no NaN or infinity: undefined statistics become null.
    serde_json::Number::from_f64(v).map_or(serde_json::Value::Null, serde_json::Value::Number)
}

fn fmt(v: f64) -> String {
    if v.is_finite() && (v == 0.0 || (1e-4..1e9).contains(&v.abs())) {
        format!("{v:.4}")
    } else if v.is_finite() {
        format!("{v:.4e}")
    } else {
        "n/a".into()
    }
}

/// Checks the options that need no file.
pub fn check_args(a: &EvalArgs) -> Result<()> {
    if !(a.pitch_um.is_finite() && a.pitch_um > 0.0) {
        bail!("--pitch-um must be positive, got {}", fmt_num(a.pitch_um));
    }
    if !a.k.is_finite() {
        bail!("--k-std must be finite");
    }
    if a.threshold.is_some_and(|t| !t.is_finite()) {
        bail!("--threshold must be finite");
    }
    Ok(())
}

/// What `dmap eval` finds: the metrics, the threshold and how it was
/// chosen, the defects' sizes and the objects.
pub struct Evaluation {
    pub metrics: Metrics,
    pub threshold: f64,
    pub rule: String,
    pub sizes: Vec<DefectSize>,
    pub objects: crate::objects::ObjectReport,
}

/// `dmap eval` on scores already loaded (`values`, one channel, and the
/// mask `truth`, both `rows x cols`), the threshold from `a` (a
/// calibration file named there is read).
pub fn evaluate(
    a: &EvalArgs,
    (rows, cols): (usize, usize),
    values: &[f64],
    truth: &[bool],
) -> Result<Evaluation> {
    let m = metrics(values, truth);
    let calibrated = match &a.calibration {
        Some(p) => Some(crate::calibrate::eval_threshold(p)?),
        None => None,
    };
    let (threshold, rule) = match (a.threshold, calibrated) {
        (Some(t), _) => (t, "given".to_string()),
        (None, Some(t)) => (t, "calibrated".to_string()),
        (None, None) => {
            if m.n_free == 0 {
                bail!("no defect-free positions with a score: give --threshold");
            }
            (
                m.mean_free + a.k * m.std_free,
                format!("defect-free mean + {} x std", a.k),
            )
        }
    };
    Ok(Evaluation {
        metrics: m,
        threshold,
        rule,
        sizes: defect_sizes(values, truth, rows, cols, threshold, a.dilate),
        objects: crate::objects::evaluate(values, truth, rows, cols, threshold),
    })
}

impl Evaluation {
    /// `dmap eval --json`'s document, sizes in mm at `pitch_um`.
    pub fn json(&self, pitch_um: f64) -> serde_json::Value {
        let mm = |n: usize| n as f64 * pitch_um / 1000.0;
        let defects: Vec<serde_json::Value> = self
            .sizes
            .iter()
            .map(|d| {
                serde_json::json!({
                    "truth_mm": [mm(d.truth.0), mm(d.truth.1)],
                    "estimated_mm": [mm(d.estimated.0), mm(d.estimated.1)],
                })
            })
            .collect();
        let m = &self.metrics;
        serde_json::json!({
            "snr": json_num(m.snr),
            "psnr": json_num(m.psnr),
            "cnr": json_num(m.cnr),
            "threshold": json_num(self.threshold),
            "defects": defects,
            "objects": crate::objects::to_json(&self.objects, pitch_um / 1000.0),
        })
    }
}

pub fn run(a: &EvalArgs) -> Result<()> {
    check_args(a)?;
    let (rows, cols, values) = load_scores(&a.input, a.component.index())?;
    let mask = crate::npy::read_mask(&a.truth)?;
    if (mask.rows, mask.cols) != (rows, cols) {
        bail!(
            "truth mask {} is {}x{} but the scores are {rows}x{cols}",
            a.truth.display(),
            mask.rows,
            mask.cols
        );
    }
    let truth = mask.data;
    let e = evaluate(a, (rows, cols), &values, &truth)?;
    if a.json {
        return crate::out::stdout(format!("{}\n", e.json(a.pitch_um)).as_bytes());
    }
    let (m, threshold, rule, sizes, objects) =
        (&e.metrics, e.threshold, &e.rule, &e.sizes, &e.objects);
    let mm = |n: usize| n as f64 * a.pitch_um / 1000.0;
    let mut o = String::new();
    // Writing to a String cannot fail.
    macro_rules! println {
        ($($t:tt)*) => {{
            let _ = writeln!(o, $($t)*);
        }};
    }
    println!("SNR   {}", fmt(m.snr));
    println!("PSNR  {}", fmt(m.psnr));
    println!("CNR   {}", fmt(m.cnr));
    println!(
        "defect-free: {} positions, mean {}, std {} (population); defect: {} positions, mean {}, max {}",
        m.n_free,
        fmt(m.mean_free),
        fmt(m.std_free),
        m.n_defect,
        fmt(m.mean_defect),
        fmt(m.max_defect)
    );
    if m.nan_free + m.nan_defect > 0 {
        println!(
            "NaN scores left out: {} defect-free, {} defect positions",
            m.nan_free, m.nan_defect
        );
    }
    println!(
        "threshold {} ({rule}); sizes from positions above it within {} of each defect, pitch {} um",
        if threshold.abs() < 1e9 {
            format!("{threshold:.6}")
        } else {
            fmt_num(threshold)
        },
        a.dilate,
        fmt_num(a.pitch_um)
    );
    println!(
        "{:<7}{:<14}{:<18}{:<18}{:<7}{:<12}(peak-mean)/std",
        "defect", "first (r,c)", "truth w x h mm", "estimated mm", "above", "peak"
    );
    for (i, d) in sizes.iter().enumerate() {
        println!(
            "{:<7}{:<14}{:<18}{:<18}{:<7}{:<12}{}",
            i + 1,
            format!("({},{})", d.first.0, d.first.1),
            format!("{:.2} x {:.2}", mm(d.truth.0), mm(d.truth.1)),
            format!("{:.2} x {:.2}", mm(d.estimated.0), mm(d.estimated.1)),
            d.above,
            fmt(d.peak),
            fmt((d.peak - m.mean_free) / m.std_free)
        );
    }
    println!(
        "objects (8-connected, score >= threshold): {} defects, {} found, {} missed; {} detected objects, {} false",
        objects.truth.len(),
        objects.found(),
        objects.truth.len() - objects.found(),
        objects.detected,
        objects.false_objects.len()
    );
    println!(
        "{:<7}{:<24}{:<24}{:<8}{:<36}{:<12}",
        "defect",
        "truth rows x cols, area",
        "found rows x cols, area",
        "objects",
        "error rows/cols/area (corrected rows/cols)",
        "peak"
    );
    let span = |e: &crate::objects::Extent| {
        format!(
            "{}-{} x {}-{}, {}",
            e.rows.0, e.rows.1, e.cols.0, e.cols.1, e.area
        )
    };
    for (i, t) in objects.truth.iter().enumerate() {
        println!(
            "{:<7}{:<24}{:<24}{:<8}{:<36}{:<12}",
            i + 1,
            span(&t.truth),
            t.detected.as_ref().map_or("missed".into(), span),
            t.objects,
            match (t.size_error(), t.corrected_error()) {
                (Some((h, w, ar)), Some((ch, cw))) => format!(
                    "{:+.0}%/{:+.0}%/{:+.0}% ({:+.0}%/{:+.0}%)",
                    100.0 * h,
                    100.0 * w,
                    100.0 * ar,
                    100.0 * ch,
                    100.0 * cw
                ),
                _ => "-".into(),
            },
            fmt(t.peak)
        );
    }
    for e in objects.false_objects.iter().take(20) {
        println!("false  {}", span(e));
    }
    if objects.false_objects.len() > 20 {
        println!("false  ... {} more", objects.false_objects.len() - 20);
    }
    crate::out::stdout(o.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metrics_match_hand_computation() {
        // Defect-free values 1, 2, 3, 4: mean 2.5, population variance 1.25.
        // Defect values 10, 20: mean 15, max 20. NaNs excluded and counted.
        let values = [1.0, 2.0, 3.0, 4.0, 10.0, 20.0, f64::NAN, f64::NAN];
        let truth = [false, false, false, false, true, true, true, false];
        let m = metrics(&values, &truth);
        let s = 1.25f64.sqrt();
        assert!((m.std_free - s).abs() < 1e-15);
        assert!((m.snr - 15.0 / s).abs() < 1e-12);
        assert!((m.psnr - 20.0 / s).abs() < 1e-12);
        assert!((m.cnr - 17.5 / s).abs() < 1e-12);
        assert_eq!(
            (m.n_defect, m.n_free, m.nan_defect, m.nan_free),
            (2, 4, 1, 1)
        );
    }

    #[test]
    fn metrics_without_defects_are_nan() {
        let m = metrics(&[1.0, 2.0], &[false, false]);
        assert!(m.snr.is_nan() && m.psnr.is_nan() && m.cnr.is_nan());
        assert_eq!(m.std_free, 0.5);
    }

    #[test]
    fn both_ways_of_dilating_agree() {
        // A component of three pixels on a 9x11 image; every dilation from
        // 0 to beyond the image, per pixel and by the summed-area table.
        let comp = [(2, 3), (3, 3), (6, 9)];
        let (rows, cols) = (9, 11);
        for dilate in [0, 1, 2, 4, 12, usize::MAX] {
            let got = neighbourhood(&comp, rows, cols, dilate);
            for r in 0..rows {
                for c in 0..cols {
                    let want = comp
                        .iter()
                        .any(|&(pr, pc)| r.abs_diff(pr) <= dilate && c.abs_diff(pc) <= dilate);
                    assert_eq!(got[r * cols + c], want, "dilate {dilate} at ({r}, {c})");
                }
            }
        }
    }

    #[test]
    fn sizes_count_above_threshold_positions_near_each_defect() {
        // 6x8 image; truth: 2x2 block at rows 1-2, cols 1-2 and one pixel at (4, 6).
        // Scores above 5 at rows 0-2, cols 1-3 (3 wide, 3 high) near the first
        // defect, and a lone high score at (5, 0) too far from both (dilate 1).
        let (rows, cols) = (6, 8);
        let mut truth = vec![false; rows * cols];
        for (r, c) in [(1, 1), (1, 2), (2, 1), (2, 2), (4, 6)] {
            truth[r * cols + c] = true;
        }
        let mut v = vec![1.0; rows * cols];
        for r in 0..3 {
            for c in 1..4 {
                v[r * cols + c] = 9.0;
            }
        }
        v[5 * cols] = 9.0;
        let s = defect_sizes(&v, &truth, rows, cols, 5.0, 1);
        assert_eq!(s.len(), 2);
        assert_eq!(
            (s[0].truth, s[0].estimated, s[0].above),
            ((2, 2), (3, 3), 9)
        );
        assert_eq!(
            (s[1].truth, s[1].estimated, s[1].above),
            ((1, 1), (0, 0), 0)
        );
    }
}
