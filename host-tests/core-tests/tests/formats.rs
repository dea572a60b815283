//! The fixed-point input format `f` (docs/performance.md, fixed-point
//! arithmetic) is chosen per configuration by `Scorer::new`, never below
//! 0, so that raw counts convert exactly, by a left shift. Every
//! configuration must find one: a geometry, kernel set or weighting that
//! no longer does would make the scorer refuse it (`ConfigError::Range`).

use cvm_core::{Config, Geometry, Kernels, MAX_J, Scorer, Weights};
use cvm_core_tests::rng;
use rand::RngExt;

/// Every geometry, kernel size and built-in weighting, normalised and raw.
fn all_configs() -> Vec<Config> {
    let mut v = Vec::new();
    for normalise in [false, true] {
        for j1 in 1..=16u8 {
            for j2 in 1..=16u8 {
                let kernels = (0..=8u8)
                    .map(|bmax| Kernels::Paper { bmax })
                    .chain((0..16u8).map(|kmax| Kernels::Square { kmax }));
                for kernels in kernels {
                    for weights in [Weights::Uniform, Weights::Unit] {
                        v.push(Config {
                            geometry: Geometry::new(j1, j2).unwrap(),
                            kernels,
                            weights,
                            normalise,
                            full_scale: u16::MAX,
                        });
                    }
                }
            }
        }
    }
    v
}

/// The input format of a raw scorer, read off its conversion of a flat map
/// (`y = v 2^f`), checked to be exactly that for every cell.
fn raw_format(scorer: &Scorer, v: u16) -> i32 {
    let n = scorer.cells();
    let mut x = vec![0i32; n];
    scorer.normalise(&vec![v; n], &mut x).unwrap();
    let f = (f64::from(x[0]) / f64::from(v)).log2().round() as i32;
    assert!(f >= 0, "raw format {f} below 0");
    assert!(
        x.iter().all(|&y| i64::from(y) == i64::from(v) << f),
        "not v 2^f: {x:?}"
    );
    f
}

/// The input format of a normalising scorer, read off its conversion of a
/// flat map (`y ≈ 2^f / N` per cell).
fn normalised_format(scorer: &Scorer) -> i32 {
    let n = scorer.cells();
    let mut x = vec![0i32; n];
    scorer.normalise(&vec![500; n], &mut x).unwrap();
    (f64::from(x[0]) * n as f64).log2().round() as i32
}

#[test]
fn every_configuration_has_formats() {
    let configs = all_configs();
    assert_eq!(configs.len(), 2 * 256 * 25 * 2);
    let mut min_raw = i32::MAX;
    for cfg in &configs {
        let scorer = Scorer::new(cfg).unwrap_or_else(|e| panic!("{cfg:?}: {e:?}"));
        if !cfg.normalise {
            let f = raw_format(&scorer, 1024);
            min_raw = min_raw.min(f);
            if let Kernels::Square { .. } = cfg.kernels {
                // The finest `f` with `Σ|x| <= N 65535 2^f < 2^31` and a
                // folded count `|v| < 2^18` shifted by `f + 2` inside
                // `i32`: the bound on the embedding never binds first.
                let n = scorer.cells() as f64 * 65535.0;
                let expected = (2147483647.0 / n).log2().floor() as i32;
                assert_eq!(f, expected.min(11), "{cfg:?}");
            }
        } else if let Kernels::Square { .. } = cfg.kernels {
            // Normalised square maps: the paper kernels' format and exact
            // reciprocal, f = 28.
            assert_eq!(normalised_format(&scorer), 28, "{cfg:?}");
        } else if let Kernels::Paper { .. } = cfg.kernels {
            // The finest format, 28, always fits normalised maps (the
            // reciprocal of the sum is exact for it; the scorer's
            // `reciprocal` is only ever called with it).
            assert_eq!(normalised_format(&scorer), 28, "{cfg:?}");
        }
    }
    // The paper kernels' raw formats are 8 to 11; the square kernels'
    // `Σ|x| = N 65535 2^f < 2^31` is tightest at 16x16: f = 7.
    assert_eq!(min_raw, 7);
}

/// Separable weights of widely different magnitudes (1e-8 to 1e8, some
/// zero) still give formats (normalised and raw), and do not push the paper
/// kernels' raw format down: the factors are quantised relative to their
/// largest entry.
#[test]
fn separable_weights_keep_raw_formats() {
    let mut r = rng(1);
    let mut built = 0;
    for j1 in 1..=16u8 {
        for j2 in 1..=16u8 {
            for trial in 0..6 {
                let mut w1 = [0f64; MAX_J];
                let mut w2 = [1f64; MAX_J];
                for (a, b) in w1.iter_mut().zip(w2.iter_mut()) {
                    *a = 10f64.powf(r.random_range(-8.0..8.0));
                    if trial % 2 == 0 {
                        *b = 10f64.powf(r.random_range(-8.0..8.0));
                    }
                }
                if trial == 3 {
                    w1[1..].fill(0.0);
                }
                for normalise in [false, true] {
                    let cfg = Config {
                        geometry: Geometry::new(j1, j2).unwrap(),
                        kernels: Kernels::Paper { bmax: trial as u8 },
                        weights: Weights::Separable { w1, w2 },
                        normalise,
                        full_scale: u16::MAX,
                    };
                    let scorer = Scorer::new(&cfg).unwrap_or_else(|e| panic!("{cfg:?}: {e:?}"));
                    if normalise {
                        assert_eq!(normalised_format(&scorer), 28, "{cfg:?}");
                    } else {
                        assert!(raw_format(&scorer, 777) >= 8, "{cfg:?}");
                    }
                    built += 1;
                }
            }
        }
    }
    assert_eq!(built, 256 * 6 * 2);
}

/// The reciprocal of a normalised map's (shifted) sum, `floor(2^60 / s)`,
/// is exact: 100 000 sums at each end of its range (2^30, the only power
/// of two in it and the only exact quotient, included) and a million
/// random ones. The exhaustive check over all
/// 2^30 sums is `reciprocal_is_exact_for_every_sum` (ignored by default:
/// about 15 s with `--release`, minutes without).
#[test]
fn reciprocal_is_exact() {
    let check = |s: u32| {
        let want = (1u64 << 60) / u64::from(s);
        assert_eq!(cvm_core::scorer::reciprocal_q60(s) as u64, want, "s = {s}");
    };
    let (lo, hi) = (1u32 << 30, (1u32 << 31) - 1);
    for s in (lo..lo + 100_000).chain(hi - 100_000..=hi) {
        check(s);
    }
    let mut r = rng(60);
    for _ in 0..1_000_000 {
        check(r.random_range(lo..=hi));
    }
}

#[test]
#[ignore = "2^30 cases: run with --release --ignored"]
fn reciprocal_is_exact_for_every_sum() {
    for s in (1u32 << 30)..(1u32 << 31) {
        let want = (1u64 << 60) / u64::from(s);
        assert_eq!(cvm_core::scorer::reciprocal_q60(s) as u64, want, "s = {s}");
    }
}

/// Every refusal says why, in words of its own (the firmware and the tools
/// print them).
#[test]
fn configuration_and_frame_errors_say_why() {
    use cvm_core::{ConfigError, FrameError};
    let messages = [
        (
            ConfigError::Geometry.to_string(),
            "detector axis outside 1..=16",
        ),
        (
            ConfigError::KernelSize.to_string(),
            "square kernel size K above 15",
        ),
        (
            ConfigError::Weights.to_string(),
            "a weight is negative or not finite, or all weights are zero",
        ),
        (
            ConfigError::Range.to_string(),
            "no fixed-point scaling keeps every accumulator in range",
        ),
        (
            ConfigError::FullScale.to_string(),
            "a full scale of 0 flags every map saturated",
        ),
        (
            FrameError::Length.to_string(),
            "frame or state buffer of the wrong length",
        ),
    ];
    for (got, want) in messages {
        assert_eq!(got, want);
    }
}

/// A full scale of 0 is refused (the header's `fs` starts at 1, and every
/// sample would flag its map saturated); 1 is the smallest accepted.
#[test]
fn a_full_scale_of_zero_is_refused() {
    use cvm_core::{Config, ConfigError, Geometry, Scorer};
    let mut cfg = Config::paper(Geometry::new(3, 3).unwrap());
    cfg.full_scale = 0;
    assert_eq!(Scorer::new(&cfg).err(), Some(ConfigError::FullScale));
    cfg.full_scale = 1;
    assert!(Scorer::new(&cfg).is_ok());
}

/// `threshold_from_units` is the smallest integer score whose real value
/// reaches the threshold: checked against `score_to_units` on both sides,
/// at exact multiples of a score unit, between them, and at the ends.
#[test]
fn threshold_from_units_is_the_smallest_score_reaching_it() {
    for cfg in [
        Config::paper(Geometry::new(9, 9).unwrap()),
        Config {
            normalise: false,
            ..Config::paper(Geometry::new(15, 15).unwrap())
        },
    ] {
        let scorer = Scorer::new(&cfg).unwrap();
        let unit = scorer.score_to_units(1);
        assert_eq!(unit, 2f64.powi(-scorer.score_frac_bits()));
        let mut r = rng(7);
        let mut cases: Vec<f64> = vec![unit, 2.0 * unit, 1000.0 * unit, 0.5 * unit, 1e-300];
        cases.extend((0..2000).map(|_| r.random_range(0.0..1.0) * 1e4 * unit));
        cases.extend((0..200).map(|_| r.random_range(1u32..1 << 30) as f64 * unit));
        for t in cases {
            let s = scorer.threshold_from_units(t);
            assert!(s >= 1, "{t}");
            assert!(scorer.score_to_units(s) >= t, "{t}: {s}");
            assert!(scorer.score_to_units(s - 1) < t, "{t}: {s}");
        }
        assert_eq!(scorer.threshold_from_units(0.0), 0);
        assert_eq!(scorer.threshold_from_units(-1.0), 0);
        assert_eq!(scorer.threshold_from_units(f64::NAN), u32::MAX);
        assert_eq!(scorer.threshold_from_units(f64::INFINITY), u32::MAX);
        assert_eq!(
            scorer.threshold_from_units(u32::MAX as f64 * unit),
            u32::MAX
        );
        assert_eq!(
            scorer.threshold_from_units((u32::MAX - 1) as f64 * unit),
            u32::MAX - 1
        );
    }
}

/// Separable weights must be finite and non-negative: one bad entry among
/// good ones, on either axis, refuses the configuration, whatever the sum
/// of the weights would be.
#[test]
fn a_negative_or_infinite_weight_is_refused() {
    for bad in [-0.25, -1e-300, f64::INFINITY, f64::NEG_INFINITY, f64::NAN] {
        for axis in 0..2 {
            for at in [0, 3] {
                let mut w = [[1.0; MAX_J]; 2];
                w[axis][at] = bad;
                let cfg = Config {
                    geometry: Geometry::new(5, 6).unwrap(),
                    kernels: Kernels::Paper { bmax: 0 },
                    weights: Weights::Separable { w1: w[0], w2: w[1] },
                    normalise: true,
                    full_scale: u16::MAX,
                };
                assert_eq!(
                    Scorer::new(&cfg).err(),
                    Some(cvm_core::ConfigError::Weights),
                    "weight {bad} at {at} of axis {axis}"
                );
            }
        }
    }
}

/// Scorers built from the same configuration are equal (their unrolled
/// passes too), scorers of two geometries are not, and a scorer's debug
/// form names its passes.
#[test]
fn scorers_compare_by_configuration_and_passes() {
    let cfg = |j1, j2| Config {
        geometry: Geometry::new(j1, j2).unwrap(),
        kernels: Kernels::Paper { bmax: 0 },
        weights: Weights::Uniform,
        normalise: true,
        full_scale: u16::MAX,
    };
    let a = Scorer::new(&cfg(9, 9)).unwrap();
    assert!(a == Scorer::new(&cfg(9, 9)).unwrap());
    assert!(a != Scorer::new(&cfg(9, 8)).unwrap());
    assert!(a != Scorer::new(&cfg(8, 9)).unwrap());
    assert!(format!("{a:?}").contains("passes: Passes"), "{a:?}");
}

/// The configuration-time square root: 0 for what has none (zero,
/// negative, NaN), and within one rounding of the correctly rounded root
/// elsewhere, from below 1 to far above.
#[test]
fn table_square_root() {
    use cvm_core::tables::sqrt;
    for x in [0.0, -0.0, -1.0, -1e-300, f64::NAN, f64::NEG_INFINITY] {
        assert_eq!(sqrt(x), 0.0, "sqrt({x})");
    }
    let mut r = rng(0x7371_7274);
    for _ in 0..2000 {
        let x = 10f64.powf(r.random_range(-12.0..12.0));
        let (got, want) = (sqrt(x), x.sqrt());
        assert!(
            (got - want).abs() <= 2.0 * f64::EPSILON * want,
            "sqrt({x}) = {got}, not {want}"
        );
    }
    for x in [1.0, 4.0, 2.0, 0.25, 1e10] {
        assert!(
            (sqrt(x) - x.sqrt()).abs() <= f64::EPSILON * x.sqrt(),
            "sqrt({x})"
        );
    }
}

/// docs/protocol.md states `q`'s formula for a decoder that has no
/// scorer: the largest `q` in -120..=62 with `D 2^q <= 2^31 - 1`, `D =
/// J1 J2 W` for normalised maps and `J1 J2 W (J1 J2 65535)^2` for raw
/// ones, `W` 1 with uniform weights, `n1 n2` with unit weights (`n` an
/// axis's kernel sizes: `J`, or `b` when `0 < b <= J`) and `b + 1` with
/// square kernels. Every configuration a scorer accepts has that `q`.
#[test]
fn the_score_format_is_the_documented_formula() {
    let mut checked = 0;
    for (j1, j2) in [
        (1u8, 1u8),
        (3, 3),
        (5, 7),
        (9, 9),
        (15, 15),
        (16, 16),
        (16, 3),
    ] {
        let g = Geometry::new(j1, j2).unwrap();
        let mut kernels: Vec<Kernels> = (0..=17).map(|bmax| Kernels::Paper { bmax }).collect();
        kernels.extend((0..=15).map(|kmax| Kernels::Square { kmax }));
        for k in kernels {
            for w in [Weights::Uniform, Weights::Unit] {
                for normalise in [true, false] {
                    let cfg = Config {
                        geometry: g,
                        kernels: k,
                        weights: w,
                        normalise,
                        full_scale: u16::MAX,
                    };
                    let Ok(s) = Scorer::new(&cfg) else { continue };
                    let n = |j: u8, b: u8| if b == 0 || b > j { j } else { b } as f64;
                    let weight = match (k, w) {
                        (Kernels::Square { kmax }, _) => kmax as f64 + 1.0,
                        (_, Weights::Uniform) => 1.0,
                        (Kernels::Paper { bmax }, _) => n(j1, bmax) * n(j2, bmax),
                    };
                    let cells = j1 as f64 * j2 as f64;
                    let d = if normalise {
                        cells * weight
                    } else {
                        cells * weight * (cells * 65535.0).powi(2)
                    };
                    let q = (-120..=62)
                        .rev()
                        .find(|&q| d * 2f64.powi(q) <= (2f64.powi(31) - 1.0))
                        .unwrap_or(-120);
                    assert_eq!(s.formats().score, q, "{cfg:?}");
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 300, "{checked}");
}
