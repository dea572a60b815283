//! The square kernels' factor table (`Scorer::with_factors`): its size for
//! every geometry, the factorisation of every geometry and kernel size
//! that the tests of the distances do not reach, and the errors of a
//! scorer, an engine or a table that do not fit together. The distances
//! themselves are checked against the f64 brute force in `fixed_vs_f64`.

use cvm_core::scorer::MAX_FACTOR_WORDS;
use cvm_core::stream::{EngineError, row_words};
use cvm_core::{Config, ConfigError, Engine, FrameError, Geometry, Kernels, Scorer, Weights};

fn config(j1: u8, j2: u8, kmax: u8, normalise: bool) -> Config {
    Config {
        geometry: Geometry::new(j1, j2).unwrap(),
        kernels: Kernels::Square { kmax },
        weights: Weights::Unit,
        normalise,
        full_scale: u16::MAX,
    }
}

fn table(words: usize) -> &'static mut [i32] {
    vec![0; words].leak()
}

/// Words of a table counted the way the module docs describe it: four
/// blocks (even or odd along each axis); a block of `s` cells stored as
/// pairs of rows `(i, i+1)`, each a count, a diagonal and both rows'
/// coefficients of the columns `i+1..s` in groups of three, then the last
/// diagonal of an odd block.
fn expected_words(j1: usize, j2: usize) -> usize {
    let halves = |j: usize| [j.div_ceil(2), j / 2];
    let mut words = 0;
    for n1 in halves(j1) {
        for n2 in halves(j2) {
            let s = n1 * n2;
            let pairs: usize = (0..s / 2)
                .map(|p| 2 + 6 * (s - 2 * p - 1).div_ceil(3))
                .sum();
            words += pairs + s % 2;
        }
    }
    words
}

#[test]
fn every_geometry_and_kernel_size_factors() {
    // 16x16: four blocks of 64 cells, 32 pairs of rows each.
    assert_eq!(MAX_FACTOR_WORDS, expected_words(16, 16));
    assert_eq!(MAX_FACTOR_WORDS, 8704);
    let mut built = 0;
    for j1 in 1..=16u8 {
        for j2 in 1..=16u8 {
            let kmaxes = [0, 1, j1.max(j2) - 1, 15];
            for (i, &kmax) in kmaxes.iter().enumerate() {
                // Raw maps change the formats, not the blocks: once per
                // geometry is enough.
                for normalise in [true, false].into_iter().take(if i == 2 { 2 } else { 1 }) {
                    let cfg = config(j1, j2, kmax, normalise);
                    let scorer = Scorer::new(&cfg).unwrap();
                    let words = scorer.factor_words();
                    assert_eq!(words, expected_words(j1 as usize, j2 as usize), "{cfg:?}");
                    assert!(scorer.needs_factors());
                    let scorer = scorer
                        .with_factors(table(words))
                        .unwrap_or_else(|e| panic!("{cfg:?}: {e}"));
                    assert!(!scorer.needs_factors());
                    built += 1;
                }
            }
        }
    }
    assert_eq!(built, 256 * 5);
}

/// A one-cell map has a single block of one cell, `G = Σ_k 1 = K + 1`:
/// its factor is `sqrt(K + 1)` and a distance between two maps of raw
/// counts `a` and `b` is `(K + 1) (a - b)²`, here through the whole
/// fixed-point path.
#[test]
fn one_cell_distance_is_hand_computed() {
    for kmax in [0u8, 3, 15] {
        let scorer = dmap::fixed::scorer(&config(1, 1, kmax, false)).unwrap();
        let (mut a, mut b) = ([0i32; 1], [0i32; 1]);
        scorer.prepare(&[1000], &mut a).unwrap();
        scorer.prepare(&[400], &mut b).unwrap();
        let d = scorer.score_to_units(scorer.distance(&a, &b));
        let exact = (kmax as f64 + 1.0) * 600.0 * 600.0;
        assert!(
            (d - exact).abs() <= 1e-6 * exact,
            "kmax {kmax}: {d} against {exact}"
        );
    }
}

#[test]
fn a_square_scorer_without_its_table_is_refused() {
    let scorer = Scorer::new(&config(5, 7, 4, true)).unwrap();
    // Preparing a map: an error value, not a panic or a silent zero.
    let mut state = vec![0i32; scorer.state_words()];
    assert_eq!(
        scorer.prepare(&[7; 35], &mut state),
        Err(FrameError::Factors)
    );
    // An engine refuses it when it is set up, not beam by beam.
    let words = row_words(4, 5, 7);
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    assert_eq!(
        Engine::<4>::new(&scorer, 4, 1, &mut a, &mut b).err(),
        Some(EngineError::Factors)
    );
    // A table one word short.
    let words = scorer.factor_words();
    assert_eq!(
        scorer.clone().with_factors(table(words - 1)).err(),
        Some(ConfigError::Table)
    );
    // Once attached, the same scorer prepares maps and sets up an engine.
    let scorer = scorer.with_factors(table(words + 3)).unwrap();
    assert!(scorer.prepare(&[7; 35], &mut state).is_ok());
    assert!(Engine::<4>::new(&scorer, 4, 1, &mut a, &mut b).is_ok());
    // What a board prints.
    assert_eq!(
        FrameError::Factors.to_string(),
        "square kernels without their factor table"
    );
    assert_eq!(
        EngineError::Factors.to_string(),
        "square kernels without their factor table"
    );
    assert_eq!(
        ConfigError::Table.to_string(),
        "square kernels' factor table too short or not factorable"
    );
}

#[test]
fn a_table_is_shared_only_between_scorers_it_fits() {
    let built = dmap::fixed::scorer(&config(5, 7, 4, true)).unwrap();
    // Another full scale: the same table.
    let other = Config {
        full_scale: 4095,
        ..config(5, 7, 4, true)
    };
    let shared = Scorer::new(&other)
        .unwrap()
        .with_factors_of(&built)
        .unwrap();
    let mut s1 = vec![0i32; 35];
    let mut s2 = vec![0i32; 35];
    let frame: Vec<u16> = (0..35).map(|i| (i * 37 % 101) as u16).collect();
    built.prepare(&frame, &mut s1).unwrap();
    shared.prepare(&frame, &mut s2).unwrap();
    assert_eq!(s1, s2);
    // Another geometry or kernel size: refused.
    for cfg in [config(7, 5, 4, true), config(5, 7, 3, true)] {
        assert_eq!(
            Scorer::new(&cfg).unwrap().with_factors_of(&built).err(),
            Some(ConfigError::Table),
            "{cfg:?}"
        );
    }
    // A scorer without a table has none to share.
    let bare = Scorer::new(&config(5, 7, 4, true)).unwrap();
    assert_eq!(
        Scorer::new(&config(5, 7, 4, true))
            .unwrap()
            .with_factors_of(&bare)
            .err(),
        Some(ConfigError::Table)
    );
    // The paper kernels need no table: both calls return the scorer.
    let paper = Scorer::new(&Config::paper(Geometry::new(5, 7).unwrap())).unwrap();
    assert_eq!(paper.factor_words(), 0);
    assert!(!paper.needs_factors());
    assert_eq!(paper.clone().with_factors(table(0)).unwrap(), paper);
    assert_eq!(paper.clone().with_factors_of(&built).unwrap(), paper);
}

/// `A_k[r][s]` by enumeration: the boxes of half-width `k` (one centred
/// on every cell, clipped at the border) that hold both cells.
fn boxes_holding(j: usize, k: usize, r: usize, s: usize) -> f64 {
    (0..j)
        .filter(|&t| t.abs_diff(r) <= k && t.abs_diff(s) <= k)
        .count() as f64
}

/// The largest diagonal entry of the folded blocks `G` and of `M` itself,
/// from the definitions: `M = Σ_k A_k ⊗ A'_k`, and a folded cell is the
/// mirrored pair `(e_a ± e_(J-1-a)) / 2` (the middle cell of an odd axis
/// alone), so that its diagonal entry along one axis is
/// `(A[a][a] ± 2 A[a][a'] + A[a'][a']) / 4`, or `A[a][a]`.
fn diagonal_maxima(j1: usize, j2: usize, kmax: usize) -> (f64, f64) {
    let folded = |j: usize, k: usize, a: usize, odd: bool| {
        let m = j - 1 - a;
        if m == a {
            boxes_holding(j, k, a, a)
        } else {
            let sign = if odd { -1.0 } else { 1.0 };
            (boxes_holding(j, k, a, a)
                + sign * 2.0 * boxes_holding(j, k, a, m)
                + boxes_holding(j, k, m, m))
                / 4.0
        }
    };
    let halves = |j: usize| [(j.div_ceil(2), false), (j / 2, true)];
    let mut gmax: f64 = 0.0;
    for (n1, odd1) in halves(j1) {
        for (n2, odd2) in halves(j2) {
            for a in 0..n1 {
                for c in 0..n2 {
                    let g: f64 = (0..=kmax)
                        .map(|k| folded(j1, k, a, odd1) * folded(j2, k, c, odd2))
                        .sum();
                    gmax = gmax.max(g);
                }
            }
        }
    }
    let mut mmax: f64 = 0.0;
    for r in 0..j1 {
        for c in 0..j2 {
            let m: f64 = (0..=kmax)
                .map(|k| boxes_holding(j1, k, r, r) * boxes_holding(j2, k, c, c))
                .sum();
            mmax = mmax.max(m);
        }
    }
    (gmax, mmax)
}

/// The formats of every square configuration meet the overflow proof of
/// the module docs, with `max G_jj` and `max M_ii` computed here from the
/// definitions, and `p` is the finest that does: at `p + 1` a coefficient,
/// a partial sum or the embedding's norm would be too large.
#[test]
fn factor_formats_meet_the_overflow_proof_and_are_the_finest() {
    let i31 = 2f64.powi(31) - 1.0;
    let limit_e = 2f64.powi(30) - 1.0;
    for j1 in 1..=16usize {
        for j2 in 1..=16usize {
            let n = (j1 * j2) as f64;
            let smax = (j1.div_ceil(2) * j2.div_ceil(2)) as f64;
            for kmax in 0..=15usize {
                let (gmax, mmax) = diagonal_maxima(j1, j2, kmax);
                for normalise in [true, false] {
                    let cfg = config(j1 as u8, j2 as u8, kmax as u8, normalise);
                    let formats = Scorer::new(&cfg).unwrap().formats();
                    let (f, p) = (formats.input, formats.factors[0]);
                    let x = if normalise {
                        2f64.powi(f) + n
                    } else {
                        n * 65535.0 * 2f64.powi(f)
                    };
                    let holds = |p: i32| {
                        let coefficient = gmax.sqrt() * 2f64.powi(p) + 0.5;
                        let partial = coefficient * x / 2f64.powi(32) + smax / 2.0;
                        let norm = x * mmax.sqrt() * 2f64.powi(p - 32)
                            + n.sqrt() * (smax / 2.0 + x / 2f64.powi(33));
                        coefficient < i31 && partial < i31 && norm < limit_e
                    };
                    let what = format!("{j1}x{j2} kmax {kmax} normalise {normalise}: f {f} p {p}");
                    assert!(x < i31, "{what}: X = {x}");
                    assert!(holds(p as i32), "{what}: a bound fails");
                    assert!(p == 62 || !holds(p as i32 + 1), "{what}: p + 1 fits too");
                }
            }
        }
    }
}
