//! Batch fixed-point scoring of a whole scan with the core's scorer: the
//! same per-map preparation, distances and magnitudes as the streaming
//! engine, applied to a scan held in memory (`dmap score --distance
//! cvm-fixed`). The streaming engine must reproduce it bit for bit.

use std::collections::HashMap;
use std::sync::Mutex;

use cvm_core::{Config, Kernels, PositionScore, Scorer, flags, magnitude, power, spread};

/// The fixed-point scorer of `cfg`, ready to prepare maps: with square
/// kernels, their factor table built and attached ([`Scorer::with_factors`]).
/// A table depends on the geometry, `kmax` and the normalisation only, and
/// lives as long as the process, as a firmware's does: each is built once
/// and shared by every scorer of its configuration.
pub fn scorer(cfg: &Config) -> Result<Scorer, cvm_core::ConfigError> {
    type Key = (u8, u8, u8, bool);
    static BUILT: Mutex<Option<HashMap<Key, Scorer>>> = Mutex::new(None);
    let scorer = Scorer::new(cfg)?;
    let Kernels::Square { kmax } = cfg.kernels else {
        return Ok(scorer);
    };
    let key = (cfg.geometry.j1, cfg.geometry.j2, kmax, cfg.normalise);
    let mut built = BUILT.lock().unwrap_or_else(|e| e.into_inner());
    let built = built.get_or_insert_with(HashMap::new);
    if let Some(other) = built.get(&key) {
        return scorer.with_factors_of(other);
    }
    let table: &'static mut [i32] = vec![0; scorer.factor_words()].leak();
    let scorer = scorer.with_factors(table)?;
    built.insert(key, scorer.clone());
    Ok(scorer)
}

/// Scores every position of a `rows x cols` scan of `u16` maps (raster
/// order, `cells` samples per map), with the border rule of docs/method.md §3.
/// The CVM and power channels' values are filled in (the spread
/// channel's, off by default, by [`add_spread`]); the decisions (defect flags and
/// strength) are left to the caller, which knows the thresholds.
///
/// # Panics
/// If `data` does not hold `rows * cols` maps: callers pass a scan that
/// [`crate::npy`] has read and checked.
pub fn score_scan(scorer: &Scorer, rows: usize, cols: usize, data: &[u16]) -> Vec<PositionScore> {
    let n = scorer.cells();
    assert_eq!(
        data.len(),
        rows * cols * n,
        "scan length does not match its shape"
    );
    let w = scorer.state_words();
    let mut states = vec![0i32; rows * cols * w];
    let mut fl = vec![0u8; rows * cols];
    let mut scratch = cvm_core::scorer::Scratch::new();
    for (i, (frame, state)) in data
        .chunks_exact(n)
        .zip(states.chunks_exact_mut(w))
        .enumerate()
    {
        fl[i] = scorer
            .prepare_with(frame, state, &mut scratch)
            .expect("frame length checked above");
    }
    let state = |r: usize, c: usize| &states[(r * cols + c) * w..(r * cols + c + 1) * w];
    let powers: Vec<u32> = data
        .chunks_exact(n)
        .map(|f| f.iter().map(|&a| u32::from(a)).sum())
        .collect();
    let pw = |r: usize, c: usize| powers[r * cols + c];
    let mut out = Vec::with_capacity(rows * cols);
    for r in 0..rows {
        for c in 0..cols {
            let (l, rr) = (c.saturating_sub(1), (c + 1).min(cols - 1));
            let (u, d) = (r.saturating_sub(1), (r + 1).min(rows - 1));
            // A missing neighbour at the border is the map itself; d(a, a) = 0.
            let g0 = if l == rr {
                0
            } else {
                scorer.distance(state(r, l), state(r, rr))
            };
            let g1 = if u == d {
                0
            } else {
                scorer.distance(state(u, c), state(d, c))
            };
            let mag = magnitude(g0, g1);
            let mut f = fl[r * cols + c];
            if g0 == u32::MAX || g1 == u32::MAX || mag == u32::MAX {
                f |= flags::CLIPPED;
            }
            let p0 = power::contrast(pw(r, l), pw(r, rr));
            let p1 = power::contrast(pw(u, c), pw(d, c));
            out.push(PositionScore {
                g0,
                g1,
                mag,
                strength: 0,
                p0,
                p1,
                pmag: power::magnitude(p0, p1),
                flags: f,
                ..PositionScore::default()
            });
        }
    }
    out
}

/// The spread channel's values (`s0`, `s1`, `smag`) of the scores
/// [`score_scan`] gave for the same scan, with the same border rule: what
/// the streaming engine reports with its spread channel on.
///
/// # Panics
/// If `data` or `scores` do not match `rows x cols`.
pub fn add_spread(
    scorer: &Scorer,
    rows: usize,
    cols: usize,
    data: &[u16],
    scores: &mut [PositionScore],
) {
    let n = scorer.cells();
    assert_eq!(
        data.len(),
        rows * cols * n,
        "scan length does not match its shape"
    );
    assert_eq!(scores.len(), rows * cols, "one score per position");
    let g = scorer.geometry();
    let (j1, j2, h) = (g.j1 as usize, g.j2 as usize, scorer.spread_half() as usize);
    let q: Vec<u16> = data
        .chunks_exact(n)
        .map(|f| {
            let p = f.iter().map(|&a| u32::from(a)).sum();
            spread::outside_core(f, j1, j2, h, p)
        })
        .collect();
    let at = |r: usize, c: usize| q[r * cols + c];
    for (i, s) in scores.iter_mut().enumerate() {
        let (r, c) = (i / cols, i % cols);
        let (l, rr) = (c.saturating_sub(1), (c + 1).min(cols - 1));
        let (u, d) = (r.saturating_sub(1), (r + 1).min(rows - 1));
        s.s0 = at(r, l).abs_diff(at(r, rr));
        s.s1 = at(u, c).abs_diff(at(d, c));
        s.smag = spread::magnitude(s.s0, s.s1);
    }
}

/// The gradient image of docs/method.md §2 (`rows x cols x 3`, distance units).
pub fn to_image(scorer: &Scorer, scores: &[PositionScore]) -> Vec<f64> {
    scores
        .iter()
        .flat_map(|s| {
            if s.flags & flags::NO_DATA != 0 {
                [f64::NAN; 3]
            } else {
                [
                    scorer.score_to_units(s.g0),
                    scorer.score_to_units(s.g1),
                    scorer.score_to_units(s.mag),
                ]
            }
        })
        .collect()
}
