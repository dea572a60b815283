//! The three CVM implementations (brute force, summed-area tables,
//! embedding) agree with each other and with hand-computed values, and the
//! distance has the properties docs/method.md §3 asks for.

mod common;

use common::*;
use cvm_reference::*;
use proptest::prelude::*;

fn all_three(c: &CvmConfig, a: &[f64], b: &[f64]) -> [f64; 3] {
    [cvm_brute(c, a, b), cvm_sat(c, a, b), cvm_embedding(c, a, b)]
}

/// Hand computation on a 1x3 detector, a1 = [1, 0, 0], a2 = [0, 0, 1]
/// (already normalised). Axis 1 has one cell, so only the axis-2 boxes
/// matter; boxes [max(1, j-b), min(3, j+b)]:
///   b = 1: centre 1 -> [1,2]: A1 = 1, A2 = 0, diff^2 = 1
///          centre 2 -> [1,3]: 1 vs 1, 0
///          centre 3 -> [2,3]: 0 vs 1, 1          => 2
///   b = 2, 3: every box is [1,3]: 1 vs 1         => 0
/// Unit weights: d = 2. Uniform weights 1/(n1 n2) = 1/3: d = 2/3.
/// Square kernels k = 0..=2: k = 0 single cells give 1 + 0 + 1 = 2, k = 1
/// as b = 1 gives 2, k = 2 gives 0: d = 4.
/// Raw square kernels with a1 = [2, 0, 0], a2 = [0, 0, 1]:
///   k = 0: (2-0)^2 + 0 + (0-1)^2 = 5
///   k = 1: [1,2]: 2 vs 0 -> 4; [1,3]: 2 vs 1 -> 1; [2,3]: 0 vs 1 -> 1 => 6
///   k = 2: three boxes [1,3], 2 vs 1 -> 1 each => 3
///   d = 14.
#[test]
fn hand_computed_1x3() {
    let g = Geometry::new(1, 3).unwrap();
    let (a1, a2) = ([1.0, 0.0, 0.0], [0.0, 0.0, 1.0]);
    let cases = [
        (CvmConfig::paper(g, PaperWeights::Unit, None).unwrap(), 2.0),
        (
            CvmConfig::paper(g, PaperWeights::Uniform, None).unwrap(),
            2.0 / 3.0,
        ),
        (CvmConfig::square(g, None).unwrap(), 4.0),
    ];
    for (c, want) in cases {
        for d in all_three(&c, &a1, &a2) {
            assert!(close(d, want, 1e-14, 0.0), "{c:?}: {d} != {want}");
        }
    }
    let raw = CvmConfig::square(g, None).unwrap().with_normalise(false);
    for d in all_three(&raw, &[2.0, 0.0, 0.0], &a2) {
        assert!(close(d, 14.0, 1e-14, 0.0), "raw square: {d} != 14");
    }
    // Normalised, the factor 2 on a1 changes nothing.
    let norm = CvmConfig::square(g, None).unwrap();
    assert!(close(
        cvm_brute(&norm, &[2.0, 0.0, 0.0], &a2),
        4.0,
        1e-14,
        0.0
    ));
}

/// With paper kernels every box on a 2-cell axis covers the whole axis, so
/// normalised maps that differ only along that axis are at distance 0 (the
/// semi-definite case of docs/method.md §4); the embedding must agree.
#[test]
fn two_cell_axis_is_blind_with_paper_kernels() {
    let g = Geometry::new(2, 3).unwrap();
    let a = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let b = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
    let c = CvmConfig::paper(g, PaperWeights::Unit, None).unwrap();
    for d in all_three(&c, &a, &b) {
        assert!(d.abs() < 1e-15, "{d}");
    }
    // Square kernels (k = 0 is the single cell) do see the move: cells differ
    // at 2 positions (k = 0: 2), k = 1 boxes [1,2]x[max(1,j-1)..]: centre
    // column 1 and 2 include column 1 on both rows -> equal sums; so only
    // k = 0 contributes: d = 2.
    let s = CvmConfig::square(g, None).unwrap();
    for d in all_three(&s, &a, &b) {
        assert!(close(d, 2.0, 1e-14, 0.0), "{d}");
    }
}

#[derive(Clone, Debug)]
enum Kind {
    Unit,
    Uniform,
    Separable(Vec<f64>, Vec<f64>),
    Square,
}

fn config_strategy() -> impl Strategy<Value = CvmConfig> {
    let geo = prop::sample::select(GEOMETRIES);
    (
        geo,
        0usize..4,
        proptest::option::of(1usize..=16),
        any::<bool>(),
        0u64..1000,
    )
        .prop_flat_map(|(j, kind, cap, normalise, _)| {
            let g = geometry(j);
            let n1 = g.j1().min(cap.unwrap_or(99));
            let n2 = g.j2().min(cap.unwrap_or(99));
            let w = (
                prop::collection::vec(0.01f64..10.0, n1),
                prop::collection::vec(0.01f64..10.0, n2),
            );
            (Just((g, kind, cap, normalise)), w)
        })
        .prop_map(|((g, kind, cap, normalise), (w1, w2))| {
            let kind = match kind {
                0 => Kind::Unit,
                1 => Kind::Uniform,
                2 => Kind::Separable(w1, w2),
                _ => Kind::Square,
            };
            let c = match kind {
                Kind::Unit => CvmConfig::paper(g, PaperWeights::Unit, cap),
                Kind::Uniform => CvmConfig::paper(g, PaperWeights::Uniform, cap),
                Kind::Separable(w1, w2) => {
                    CvmConfig::paper(g, PaperWeights::Separable { w1, w2 }, cap)
                }
                Kind::Square => {
                    let limit = g.j1().max(g.j2()) - 1;
                    CvmConfig::square(g, cap.map(|k| k.min(limit)))
                }
            };
            c.unwrap().with_normalise(normalise)
        })
}

/// Absolute floor for comparisons: rounding noise relative to the size of
/// the LCDs (1 when normalised, the raw totals otherwise) summed over all
/// terms.
fn floor(c: &CvmConfig, a: &[f64], b: &[f64]) -> f64 {
    let scale = if c.normalises() {
        1.0
    } else {
        let t: f64 = a.iter().chain(b).sum();
        t * t
    };
    let wsum: f64 = c.kernels().iter().map(|k| k.w).sum();
    1e-14 * scale * wsum * c.geometry().cells() as f64
}

fn config_and_maps() -> impl Strategy<Value = (CvmConfig, Vec<f64>, Vec<f64>)> {
    config_strategy().prop_flat_map(|c| {
        let n = c.geometry().cells();
        (Just(c), map_pair(n)).prop_map(|(c, (a, b))| (c, a, b))
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn brute_sat_embedding_agree((c, a, b) in config_and_maps()) {
        let [brute, sat, emb] = all_three(&c, &a, &b);
        let abs = floor(&c, &a, &b);
        prop_assert!(brute >= 0.0);
        prop_assert!(close(brute, sat, 1e-9, abs), "brute {brute} sat {sat}");
        prop_assert!(close(brute, emb, 1e-9, abs), "brute {brute} embedding {emb}");
    }

    #[test]
    fn zero_on_itself_and_symmetric((c, a, b) in config_and_maps()) {
        let e = CvmEmbedding::new(&c);
        let (ea, eb) = (e.embed(&a), e.embed(&b));
        prop_assert_eq!(e.distance(&ea, &ea), 0.0);
        prop_assert_eq!(cvm_brute(&c, &a, &a), 0.0);
        prop_assert_eq!(cvm_sat(&c, &a, &a), 0.0);
        prop_assert_eq!(cvm_brute(&c, &a, &b), cvm_brute(&c, &b, &a));
        prop_assert_eq!(e.distance(&ea, &eb), e.distance(&eb, &ea));
    }

    #[test]
    fn normalised_distance_ignores_scale((c, a, b) in config_and_maps(), s in 0.001f64..1000.0) {
        let c = c.with_normalise(true);
        let scaled: Vec<f64> = a.iter().map(|x| x * s).collect();
        let d = cvm_brute(&c, &a, &b);
        let ds = cvm_brute(&c, &scaled, &b);
        prop_assert!(close(d, ds, 1e-9, floor(&c, &a, &b)), "{d} vs {ds}");
    }

    #[test]
    fn dark_against_lit_is_positive((c, a, _b) in config_and_maps()) {
        prop_assume!(lit(&a));
        let dark = vec![0.0; a.len()];
        for d in all_three(&c, &dark, &a) {
            prop_assert!(d > 0.0, "d(dark, lit) = {d}");
        }
        for d in all_three(&c, &dark, &dark) {
            prop_assert_eq!(d, 0.0);
        }
    }
}

/// Raw maps: the distance scales with the square of the counts.
#[test]
fn raw_distance_scales_quadratically() {
    let g = Geometry::new(4, 5).unwrap();
    let a: Vec<f64> = (0..20).map(|i| ((i * 7) % 11) as f64).collect();
    let b: Vec<f64> = (0..20).map(|i| ((i * 3) % 5) as f64).collect();
    let c = CvmConfig::square(g, None).unwrap().with_normalise(false);
    let a3: Vec<f64> = a.iter().map(|x| 3.0 * x).collect();
    let b3: Vec<f64> = b.iter().map(|x| 3.0 * x).collect();
    assert!(close(
        cvm_brute(&c, &a3, &b3),
        9.0 * cvm_brute(&c, &a, &b),
        1e-12,
        0.0
    ));
}

#[test]
fn configuration_errors_are_reported() {
    let g = Geometry::new(9, 9).unwrap();
    assert_eq!(
        CvmConfig::paper(g, PaperWeights::Unit, Some(0)),
        Err(ConfigError::ZeroBmax)
    );
    assert!(matches!(
        CvmConfig::paper(
            g,
            PaperWeights::Separable {
                w1: vec![1.0; 9],
                w2: vec![1.0; 3]
            },
            None
        ),
        Err(ConfigError::WeightLength {
            axis: 2,
            expected: 9,
            got: 3
        })
    ));
    assert!(matches!(
        CvmConfig::square(g, Some(9)),
        Err(ConfigError::SquareTooLarge { k_max: 9, limit: 8 })
    ));
    assert!(Geometry::new(17, 3).is_err());
    assert!(Geometry::new(0, 3).is_err());
}

/// Uniform weights sum to 1 (Eq. 10), with and without a cap.
#[test]
fn uniform_weights_sum_to_one() {
    for (j, cap) in [
        ((9, 15), None),
        ((9, 15), Some(4)),
        ((1, 1), None),
        ((16, 2), Some(1)),
    ] {
        let c = CvmConfig::paper(geometry(j), PaperWeights::Uniform, cap).unwrap();
        let s: f64 = c.kernels().iter().map(|k| k.w).sum();
        assert!(close(s, 1.0, 1e-14, 0.0), "{j:?} {cap:?}: {s}");
    }
}
