//! Helpers shared by the core's host tests: random maps and scans, and the
//! translation of one scoring configuration into both the fixed-point core
//! and the f64 reference.

use dmap::options::{KernelArg, ScoringArgs, WeightArg};
use rand::rngs::ChaCha8Rng;
use rand::{Rng, RngExt, SeedableRng};

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// The geometries every property is checked on.
pub const GEOMETRIES: &[(usize, usize)] = &[
    (1, 1),
    (1, 5),
    (2, 2),
    (2, 7),
    (7, 2),
    (3, 3),
    (4, 6),
    (9, 9),
    (9, 15),
    (15, 15),
    (16, 16),
];

/// Every scoring variant the CLI offers.
pub fn variants(j1: usize, j2: usize) -> Vec<ScoringArgs> {
    let mut v = Vec::new();
    for raw in [false, true] {
        for w in [WeightArg::Uniform, WeightArg::Unit] {
            v.push(ScoringArgs {
                kernels: KernelArg::Paper,
                weights: Some(w),
                bmax: None,
                raw,
            });
        }
        v.push(ScoringArgs {
            kernels: KernelArg::Paper,
            weights: None,
            bmax: Some(3),
            raw,
        });
        v.push(ScoringArgs {
            kernels: KernelArg::Square,
            weights: None,
            bmax: None,
            raw,
        });
        if j1.max(j2) > 2 {
            v.push(ScoringArgs {
                kernels: KernelArg::Square,
                weights: None,
                bmax: Some(1),
                raw,
            });
        }
    }
    v
}

/// A deflection-map-like random map: a blurred spot at a random place plus
/// background, with a chance of a sparse or a dark map.
pub fn random_map(rng: &mut impl Rng, cells: usize, j2: usize) -> Vec<u16> {
    let j1 = cells / j2;
    match rng.random_range(0..10) {
        0 => vec![0; cells],
        1 => (0..cells)
            .map(|_| {
                if rng.random_bool(0.1) {
                    rng.random()
                } else {
                    0
                }
            })
            .collect(),
        2 => (0..cells).map(|_| rng.random()).collect(),
        _ => {
            let (c1, c2) = (
                rng.random_range(0.0..j1 as f64),
                rng.random_range(0.0..j2 as f64),
            );
            let s = rng.random_range(0.3..3.0);
            let peak = rng.random_range(100.0..60000.0);
            (0..cells)
                .map(|i| {
                    let (a, b) = ((i / j2) as f64 - c1, (i % j2) as f64 - c2);
                    let v = peak * (-(a * a + b * b) / (2.0 * s * s)).exp()
                        + rng.random_range(0.0..20.0);
                    v.min(65535.0) as u16
                })
                .collect()
        }
    }
}

/// A neighbour of `a`: the same map slightly moved and with noise, as
/// neighbouring beams are.
pub fn perturb(rng: &mut impl Rng, a: &[u16]) -> Vec<u16> {
    a.iter()
        .map(|&v| {
            let f = rng.random_range(0.9..1.1);
            ((v as f64) * f + rng.random_range(0.0..5.0)).min(65535.0) as u16
        })
        .collect()
}

pub fn to_f64(a: &[u16]) -> Vec<f64> {
    a.iter().map(|&v| v as f64).collect()
}

use cvm_core::{Engine, PositionScore, RowSummary, Scorer, Totals};

/// Runs the engine over `frames` (position, optional frame; `None` means
/// "mark missing") and returns every emitted row and the totals.
pub fn run_engine(
    scorer: &Scorer,
    cols: usize,
    threshold: u32,
    frames: &[(cvm_core::Position, Option<Vec<u16>>)],
) -> (Vec<(RowSummary, Vec<PositionScore>)>, Totals) {
    run_engine_with(scorer, cols, threshold, cvm_core::power::POWER_OFF, frames)
}

/// [`run_engine`] with the power channel's threshold. Runs the engine
/// twice, without and with the buffer of the current row's last maps
/// ([`Engine::with_near`]), and checks that both give the same rows and
/// totals: every test through here covers both.
pub fn run_engine_with(
    scorer: &Scorer,
    cols: usize,
    threshold: u32,
    power_threshold: u32,
    frames: &[(cvm_core::Position, Option<Vec<u16>>)],
) -> (Vec<(RowSummary, Vec<PositionScore>)>, Totals) {
    let off = cvm_core::spread::SPREAD_OFF;
    run_engine_thresholds(scorer, cols, [threshold, power_threshold, off], frames)
}

/// [`run_engine_with`] with every channel's threshold: CVM, power, spread.
pub fn run_engine_thresholds(
    scorer: &Scorer,
    cols: usize,
    [threshold, power_threshold, spread_threshold]: [u32; 3],
    frames: &[(cvm_core::Position, Option<Vec<u16>>)],
) -> (Vec<(RowSummary, Vec<PositionScore>)>, Totals) {
    let run = |with_near: bool, rows: u32| {
        run_engine_full(
            scorer,
            cols,
            [threshold, power_threshold, spread_threshold],
            frames,
            with_near,
            rows,
        )
    };
    let plain = run(false, 0);
    let near = run(true, 0);
    assert!(
        plain == near,
        "the engine with the near buffer gives other results"
    );
    // With the row count known, the last rows are decided as their beams
    // arrive and held back for the end: the same rows must come out, for
    // the scan's own row count and for a larger one (a scan that ends
    // early). A scan whose last beams are all rejected or beyond the last
    // column gives no row count of its own to test.
    let rows = frames
        .iter()
        .filter(|(p, _)| (p.col as usize) < cols)
        .map(|(p, _)| p.row)
        .max()
        .map_or(0, |r| r.saturating_add(1));
    for known in [rows, rows.saturating_add(2)] {
        for with_near in [false, true] {
            let got = run(with_near, known);
            assert!(
                plain == got,
                "the engine told of {known} rows gives other results"
            );
        }
    }
    plain
}

/// One run of [`run_engine_with`]: with a near buffer (filled with junk
/// first, so that a read of a word it was not given shows) or without.
pub fn run_engine_near(
    scorer: &Scorer,
    cols: usize,
    threshold: u32,
    power_threshold: u32,
    frames: &[(cvm_core::Position, Option<Vec<u16>>)],
    with_near: bool,
    rows: u32,
) -> (Vec<(RowSummary, Vec<PositionScore>)>, Totals) {
    let off = cvm_core::spread::SPREAD_OFF;
    let thresholds = [threshold, power_threshold, off];
    run_engine_full(scorer, cols, thresholds, frames, with_near, rows)
}

/// [`run_engine_near`] with every channel's threshold.
fn run_engine_full(
    scorer: &Scorer,
    cols: usize,
    [threshold, power_threshold, spread_threshold]: [u32; 3],
    frames: &[(cvm_core::Position, Option<Vec<u16>>)],
    with_near: bool,
    rows: u32,
) -> (Vec<(RowSummary, Vec<PositionScore>)>, Totals) {
    let words = cvm_core::stream::row_words_for(cols, scorer.config());
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let mut near = if with_near {
        vec![0x5A5A_5A5Ai32; cvm_core::stream::near_words(scorer.config())]
    } else {
        Vec::new()
    };
    let mut engine = Box::new(
        Engine::<256>::with_near(scorer, cols as u32, threshold, &mut a, &mut b, &mut near)
            .unwrap(),
    );
    engine.set_power_threshold(power_threshold);
    if spread_threshold != cvm_core::spread::SPREAD_OFF {
        engine.set_spread_threshold(spread_threshold);
    }
    engine.set_rows(rows);
    let mut out_rows = Vec::new();
    let mut out = |v: &cvm_core::RowView| out_rows.push((v.summary, v.scores.to_vec()));
    for (pos, f) in frames {
        match f {
            Some(f) => engine.push(*pos, f, &mut out),
            None => engine.mark_missing(*pos, &mut out),
        };
    }
    // What `close` leaves unsent is exactly what `finish` puts out.
    engine.close();
    let mut unsent = Vec::new();
    engine.unsent(&mut |v| unsent.push((v.summary, v.scores.to_vec())));
    let mut last = Vec::new();
    let totals = engine.finish(&mut |v| last.push((v.summary, v.scores.to_vec())));
    let before = out_rows.len();
    out_rows.extend(last);
    assert!(
        out_rows.get(before..) == Some(&unsent[..]),
        "finish put out other rows than close left unsent"
    );
    (out_rows, totals)
}

/// The decisions of docs/method.md §6 applied to scores that have none:
/// a channel fires when its magnitude reaches its threshold; the strength
/// is the larger `floor(65536 score / threshold)` of the channels that
/// fired (a zero threshold counts as 1), saturated to `u32`.
pub fn decide(scores: &mut [PositionScore], threshold: u32, power_threshold: u32) {
    use cvm_core::flags;
    let ratio = |s: u32, t: u32| -> u32 {
        let v = (s as u128 * 65536) / (t.max(1) as u128);
        u32::try_from(v).unwrap_or(u32::MAX)
    };
    for s in scores.iter_mut() {
        s.flags &= !flags::DEFECT;
        s.strength = 0;
        if s.flags & flags::NO_DATA != 0 {
            continue;
        }
        let mut st = Vec::new();
        if s.mag >= threshold {
            s.flags |= flags::CVM_DEFECT;
            st.push(ratio(s.mag, threshold));
        }
        if u32::from(s.pmag) >= power_threshold {
            s.flags |= flags::POWER_DEFECT;
            st.push(ratio(u32::from(s.pmag), power_threshold));
        }
        s.strength = st.into_iter().max().unwrap_or(0);
    }
}

/// The spread decision added to scores [`decide`] has decided: the
/// channel fires when `smag` reaches `spread_threshold`, and the strength
/// becomes the larger of the one there and the spread channel's.
pub fn decide_spread(scores: &mut [PositionScore], spread_threshold: u32) {
    use cvm_core::flags;
    for s in scores.iter_mut() {
        if s.flags & flags::NO_DATA != 0 || s.smag < spread_threshold {
            continue;
        }
        s.flags |= flags::SPREAD_DEFECT;
        let v = (s.smag as u128 * 65536) / (spread_threshold.max(1) as u128);
        s.strength = s.strength.max(u32::try_from(v).unwrap_or(u32::MAX));
    }
}

/// The spread channel's `q` of a map from the f64 reference:
/// `floor(2^16 outside_core)`. Exact: the sums are integers below `2^24`,
/// exact in f64; the quotient's rounding moves it by less than
/// `2^16 2^-53` in units of `q`, while a true value just below an integer
/// `k` is at least `1 / P > 2^-24` away from it.
pub fn spread_q_ref(frame: &[u16], j1: usize, j2: usize, half: usize) -> u16 {
    let g = cvm_reference::Geometry::new(j1, j2).expect("a geometry of the core");
    cvm_reference::outside_core(g, &to_f64(frame), half).map_or(0, |f| (f * 65536.0).floor() as u16)
}

/// `floor(sqrt(s0² + s1²))` by exhaustive search from the f64 root.
pub fn spread_magnitude_ref(s0: u16, s1: u16) -> u32 {
    let s = u64::from(s0).pow(2) + u64::from(s1).pow(2);
    let mut m = (s as f64).sqrt() as u64;
    while m * m > s {
        m -= 1;
    }
    while (m + 1) * (m + 1) <= s {
        m += 1;
    }
    m as u32
}

/// Power contrast of two map sums in `Q15`, from its definition in f64:
/// `floor(2^15 |a - b| / (a + b))` (exact: both below `2^25`, see the test
/// of `cvm_core::power::contrast`).
pub fn contrast_f64(a: u64, b: u64) -> u16 {
    if a + b == 0 {
        return 0;
    }
    ((a.abs_diff(b) as f64 * 32768.0) / (a + b) as f64).floor() as u16
}

/// `floor(sqrt(c0² + c1²))` by exhaustive search from the f64 root.
pub fn power_magnitude_ref(c0: u16, c1: u16) -> u16 {
    let s = u64::from(c0).pow(2) + u64::from(c1).pow(2);
    let mut m = (s as f64).sqrt() as u64;
    while m * m > s {
        m -= 1;
    }
    while (m + 1) * (m + 1) <= s {
        m += 1;
    }
    m as u16
}

/// A random scan: rows x cols maps of `j1 x j2`, neighbours similar, with
/// occasional dark and saturated maps.
pub fn random_scan(rng: &mut impl Rng, rows: usize, cols: usize, j1: usize, j2: usize) -> Vec<u16> {
    let n = j1 * j2;
    let mut data = Vec::with_capacity(rows * cols * n);
    let mut prev = random_map(rng, n, j2);
    for _ in 0..rows * cols {
        let m = match rng.random_range(0..20) {
            0 => vec![0; n],
            1 => {
                let mut m = prev.clone();
                m[rng.random_range(0..n)] = u16::MAX;
                m
            }
            2 | 3 => random_map(rng, n, j2),
            _ => perturb(rng, &prev),
        };
        data.extend_from_slice(&m);
        prev = m;
    }
    data
}

/// The `DARK` and `SATURATED` flags a frame must get, from its samples
/// (docs/method.md §3): dark when every sample is zero, saturated when any
/// sample is at or above `full_scale`.
pub fn frame_flags(frame: &[u16], full_scale: u16) -> u8 {
    let mut f = 0;
    if frame.iter().all(|&a| a == 0) {
        f |= cvm_core::flags::DARK;
    }
    if frame.iter().any(|&a| a >= full_scale) {
        f |= cvm_core::flags::SATURATED;
    }
    f
}

/// The summary of row `row` recomputed from its positions' scores: the
/// largest magnitude among positions with data and the first column
/// reaching it, the positions at or above `threshold`, and the counts of
/// positions without data, dark and saturated.
pub fn row_summary_of(row: u32, scores: &[PositionScore], threshold: u32) -> RowSummary {
    row_summary_with(row, scores, threshold, cvm_core::power::POWER_OFF)
}

/// [`row_summary_of`] with the power channel's threshold: a defect is a
/// position where either magnitude reaches its threshold.
pub fn row_summary_with(
    row: u32,
    scores: &[PositionScore],
    threshold: u32,
    power_threshold: u32,
) -> RowSummary {
    use cvm_core::flags;
    let data: Vec<(usize, &PositionScore)> = scores
        .iter()
        .enumerate()
        .filter(|(_, s)| s.flags & flags::NO_DATA == 0)
        .collect();
    let max = data.iter().map(|(_, s)| s.mag).max().unwrap_or(0);
    let pmax = data
        .iter()
        .map(|(_, s)| u32::from(s.pmag))
        .max()
        .unwrap_or(0);
    let count = |bit: u8| data.iter().filter(|(_, s)| s.flags & bit != 0).count() as u32;
    RowSummary {
        row,
        max,
        argmax: data
            .iter()
            .find(|(_, s)| s.mag == max)
            .map(|(c, _)| *c as u32),
        pmax,
        pargmax: data
            .iter()
            .find(|(_, s)| u32::from(s.pmag) == pmax)
            .map(|(c, _)| *c as u32),
        defects: data
            .iter()
            .filter(|(_, s)| s.mag >= threshold || u32::from(s.pmag) >= power_threshold)
            .count() as u32,
        no_data: (scores.len() - data.len()) as u32,
        dark: count(flags::DARK),
        saturated: count(flags::SATURATED),
    }
}

/// The beams of a `rows` x `cols` scan of `n`-cell maps in raster order,
/// each with its frame where `present` (a position's flag; `None`: all)
/// and marked missing elsewhere.
pub fn scan_frames(
    data: &[u16],
    n: usize,
    rows: usize,
    cols: usize,
    present: Option<&[bool]>,
) -> Vec<(cvm_core::Position, Option<Vec<u16>>)> {
    (0..rows * cols)
        .map(|i| {
            let pos = cvm_core::Position {
                row: (i / cols) as u32,
                col: (i % cols) as u32,
            };
            let here = present.is_none_or(|p| p[i]);
            (pos, here.then(|| data[i * n..(i + 1) * n].to_vec()))
        })
        .collect()
}
