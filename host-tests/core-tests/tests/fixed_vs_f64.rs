//! The fixed-point scorer against the f64 brute force of Eq. 5, 6, 8, 9.
//!
//! Stated bound (README, "Fixed-point accuracy"), with `M` the largest exact
//! distance in a sample (the image maximum) and `step = 2^-q` one score unit:
//!
//! * normalised maps: `|d_fixed - d| <= 1e-5 M + step` for every pair, and
//!   `|d_fixed - d| <= 1e-4 d` wherever `d >= 1e-3 M`;
//! * raw maps: `|d_fixed - d| <= 1e-5 M + step`, and `<= 1e-3 d` wherever
//!   `d >= 1e-3 M` and `d >= 1000 step` (a raw score's step is set by the
//!   largest distance raw counts can reach, so it is coarse for dim maps).
//!
//! Checked here as well, relative to each distance rather than to `M`:
//! `|d_fixed - d| <= 1e-4 d + 2 step` (normalised) and `<= 1e-3 d + 2 step`
//! (raw), so that a score stuck at 0 or cut short fails wherever the exact
//! distance exceeds two steps, dim raw maps included.

use cvm_core::Scorer;
use cvm_core_tests::{GEOMETRIES, perturb, random_map, rng, to_f64, variants};
use cvm_reference::{CvmConfig, cvm_brute};
use dmap::options::{KernelArg, ScoringArgs, WeightArg};

/// Score steps allowed on top of the relative bound of each distance.
const PER_DISTANCE_STEPS: f64 = 2.0;

fn fixed(scorer: &Scorer, a: &[u16], b: &[u16]) -> (f64, u32) {
    let n = scorer.state_words();
    let (mut sa, mut sb) = (vec![0i32; n], vec![0i32; n]);
    scorer.prepare(a, &mut sa).unwrap();
    scorer.prepare(b, &mut sb).unwrap();
    let s = scorer.distance(&sa, &sb);
    // Symmetry and d(a, a) = 0 hold exactly in fixed point.
    assert_eq!(s, scorer.distance(&sb, &sa));
    assert_eq!(scorer.distance(&sa, &sa), 0);
    (scorer.score_to_units(s), s)
}

/// Checks a sample of pairs against the stated bound; returns a description
/// of the first violation.
fn check(
    scorer: &Scorer,
    reference: &CvmConfig,
    raw: bool,
    pairs: &[(Vec<u16>, Vec<u16>)],
) -> Result<f64, String> {
    let samples: Vec<(f64, f64, u32)> = pairs
        .iter()
        .map(|(a, b)| {
            let exact = cvm_brute(reference, &to_f64(a), &to_f64(b));
            let (f, s) = fixed(scorer, a, b);
            (exact, f, s)
        })
        .collect();
    let max = samples.iter().map(|s| s.0).fold(0.0, f64::max);
    let step = scorer.score_to_units(1);
    for &(e, f, s) in &samples {
        let err = (e - f).abs();
        if s == u32::MAX {
            return Err(format!("score clipped: exact {e}"));
        }
        if err > 1e-5 * max + step {
            return Err(format!(
                "exact {e} fixed {f}: error {err:.3e} > 1e-5 * {max:.3e} + {step:.1e}"
            ));
        }
        let rel_ok = if raw {
            e < 1e-3 * max || e < 1000.0 * step || err <= 1e-3 * e
        } else {
            e < 1e-3 * max || err <= 1e-4 * e
        };
        if !rel_ok {
            return Err(format!(
                "exact {e} fixed {f}: relative error {:.3e}",
                err / e
            ));
        }
        // Relative to each distance, whatever the sample's maximum: a
        // score is the distance rounded to the nearest step, so below one
        // step only the step bounds the error, above it the relative
        // bound does. (A score stuck at 0 fails wherever `d > 2 step`.)
        let each = if raw { 1e-3 } else { 1e-4 };
        if err > each * e + PER_DISTANCE_STEPS * step {
            return Err(format!(
                "exact {e} fixed {f}: error {err:.3e} > {each:.0e} * d + {PER_DISTANCE_STEPS} * {step:.1e}"
            ));
        }
    }
    // The share of the sample the per-distance bound constrains tightly.
    let big = samples.iter().filter(|s| s.0 > 10.0 * step).count();
    Ok(big as f64 / samples.len().max(1) as f64)
}

#[test]
fn fixed_point_matches_f64_on_random_maps() {
    let mut failures = Vec::new();
    for (k, &(j1, j2)) in GEOMETRIES.iter().enumerate() {
        let n = j1 * j2;
        let count = if n >= 200 { 60 } else { 200 };
        for args in variants(j1, j2) {
            let scorer = args.scorer(j1, j2).unwrap();
            let reference = args.reference_config(j1, j2).unwrap();
            let mut r = rng(1000 + k as u64);
            let pairs: Vec<_> = (0..count)
                .map(|i| {
                    let a = random_map(&mut r, n, j2);
                    let b = if i % 2 == 0 {
                        perturb(&mut r, &a)
                    } else {
                        random_map(&mut r, n, j2)
                    };
                    (a, b)
                })
                .collect();
            match check(&scorer, &reference, args.raw, &pairs) {
                Err(e) => failures.push(format!("{j1}x{j2} {args:?}: {e}")),
                // Raw maps: most of the sample lies well above one step,
                // where the per-distance bound is tight.
                Ok(share) if args.raw && share < 0.5 => failures.push(format!(
                    "{j1}x{j2} {args:?}: only {share:.2} of the raw distances above 10 steps"
                )),
                Ok(_) => {}
            }
        }
    }
    assert!(
        failures.is_empty(),
        "outside the stated bound:\n{}",
        failures.join("\n")
    );
}

/// The largest inputs at the largest geometry: all full scale, single hot
/// cells, checkerboards and stripes at full scale, against each other. An
/// overflow anywhere would show as a wrong value or a clipped score.
#[test]
fn extreme_inputs_at_16x16_do_not_overflow() {
    let (j1, j2) = (16, 16);
    let n = j1 * j2;
    let full = u16::MAX;
    let mut maps: Vec<Vec<u16>> = vec![vec![full; n], vec![0; n], vec![1; n]];
    for hot in [0, 15, 136, 255] {
        let mut m = vec![0; n];
        m[hot] = full;
        maps.push(m);
    }
    maps.push(
        (0..n)
            .map(|i| if (i / j2 + i % j2) % 2 == 0 { full } else { 0 })
            .collect(),
    );
    maps.push(
        (0..n)
            .map(|i| if (i / j2 + i % j2) % 2 == 1 { full } else { 0 })
            .collect(),
    );
    maps.push(
        (0..n)
            .map(|i| if (i / j2) % 2 == 0 { full } else { 0 })
            .collect(),
    );
    maps.push((0..n).map(|i| if i % 2 == 0 { full } else { 0 }).collect());
    maps.push((0..n).map(|i| if i < n / 2 { full } else { 0 }).collect());
    let mut pairs = Vec::new();
    for a in &maps {
        for b in &maps {
            pairs.push((a.clone(), b.clone()));
        }
    }
    let mut failures = Vec::new();
    for args in variants(j1, j2) {
        let scorer = args.scorer(j1, j2).unwrap();
        let reference = args.reference_config(j1, j2).unwrap();
        if let Err(e) = check(&scorer, &reference, args.raw, &pairs) {
            failures.push(format!("{args:?}: {e}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Hand-computed cases (docs/method.md §3 conventions, 1-based in the comments).
#[test]
fn hand_computed_distances() {
    let uniform = ScoringArgs {
        weights: Some(WeightArg::Uniform),
        ..ScoringArgs::default()
    };
    let unit = ScoringArgs {
        weights: Some(WeightArg::Unit),
        ..ScoringArgs::default()
    };
    let square = ScoringArgs {
        kernels: KernelArg::Square,
        ..ScoringArgs::default()
    };
    let d = |args: &ScoringArgs, j1, j2, a: &[u16], b: &[u16]| {
        fixed(&args.scorer(j1, j2).unwrap(), a, b).0
    };

    // 1x3, ã1 = (1,0,0), ã2 = (0,0,1). Boxes of size b=1 on the 3-cell axis:
    // j=1 -> [1,2], j=2 -> [1,3], j=3 -> [2,3]: A1 = (1,1,0), A2 = (0,1,1),
    // squared differences 1+0+1 = 2. Sizes 2 and 3 cover the whole axis: 0.
    // Uniform weights 1/3: d = 2/3; unit weights: d = 2.
    // Square kernels k = 0, 1, 2: k=0 compares cells (2), k=1 as b=1 (2), k=2 whole axis (0): d = 4.
    let (a, b) = ([7u16, 0, 0], [0u16, 0, 9]);
    assert!((d(&uniform, 1, 3, &a, &b) - 2.0 / 3.0).abs() < 1e-6);
    assert!((d(&unit, 1, 3, &a, &b) - 2.0).abs() < 1e-6);
    assert!((d(&square, 1, 3, &a, &b) - 4.0).abs() < 1e-6);

    // 1x2 with paper kernels: every box covers both cells, so A = Σã = 1 for
    // every lit map (any two lit maps are at distance 0) and A = 0 for a dark
    // one: d(dark, lit) = 2 centres x 2 sizes x w, w = 1/2 uniform -> 2.
    assert_eq!(d(&uniform, 1, 2, &[5, 0], &[0, 3]), 0.0);
    assert!((d(&uniform, 1, 2, &[0, 0], &[0, 3]) - 2.0).abs() < 1e-6);
    assert!((d(&unit, 2, 2, &[1, 2, 3, 4], &[4, 3, 2, 1])).abs() < 1e-6);
}

/// Scaling the raw map does not change a normalised distance (up to the
/// rounding of Eq. 5 in `Q(f)`).
#[test]
fn normalised_distance_is_scale_invariant() {
    let mut r = rng(7);
    for &(j1, j2) in GEOMETRIES {
        let scorer = ScoringArgs::default().scorer(j1, j2).unwrap();
        for _ in 0..20 {
            let a: Vec<u16> = random_map(&mut r, j1 * j2, j2)
                .iter()
                .map(|v| v / 4)
                .collect();
            let b = random_map(&mut r, j1 * j2, j2);
            let a3: Vec<u16> = a.iter().map(|v| v * 3).collect();
            let (d1, _) = fixed(&scorer, &a, &b);
            let (d3, _) = fixed(&scorer, &a3, &b);
            assert!(
                (d1 - d3).abs() <= 1e-6 * d1.max(1e-3),
                "{j1}x{j2}: {d1} vs {d3}"
            );
            let dark = vec![0u16; j1 * j2];
            if a.iter().any(|&v| v > 0) {
                assert!(
                    fixed(&scorer, &dark, &a).1 > 0,
                    "d(dark, lit) must be positive"
                );
            }
            assert_eq!(fixed(&scorer, &dark, &dark).1, 0);
        }
    }
}

/// One scratch space serves every scorer, map after map, in any order: the
/// square kernels keep their summed-area table's zero border in it from
/// one map to the next instead of clearing it, so a map must embed the same
/// whatever the scratch held before, and replacing a map must score the
/// distance between the old and the new one.
#[test]
fn one_scratch_serves_every_scorer_in_any_order() {
    use cvm_core::scorer::Scratch;
    use rand::seq::SliceRandom;
    let mut r = rng(77);
    let mut jobs = Vec::new();
    for &(j1, j2) in GEOMETRIES {
        for args in variants(j1, j2) {
            for _ in 0..3 {
                jobs.push((j1, j2, args.clone()));
            }
        }
    }
    jobs.shuffle(&mut r);
    let mut shared = Scratch::new();
    for (j1, j2, args) in jobs {
        let scorer = args.scorer(j1, j2).unwrap();
        let w = scorer.state_words();
        let (a, b) = (
            random_map(&mut r, j1 * j2, j2),
            random_map(&mut r, j1 * j2, j2),
        );
        let (mut fresh_a, mut fresh_b) = (vec![0i32; w], vec![0i32; w]);
        scorer.prepare(&a, &mut fresh_a).unwrap();
        scorer.prepare(&b, &mut fresh_b).unwrap();
        let mut state = vec![i32::MIN; w];
        scorer.prepare_with(&a, &mut state, &mut shared).unwrap();
        assert_eq!(state, fresh_a, "{j1}x{j2} {args:?}");
        let score = scorer
            .prepare_map(&b, &mut state, &mut [], &mut shared, true)
            .unwrap()
            .score;
        assert_eq!(state, fresh_b, "{j1}x{j2} {args:?}");
        assert_eq!(
            score,
            scorer.distance(&fresh_a, &fresh_b),
            "{j1}x{j2} {args:?}"
        );
    }
}
