//! Exact EMD: the transportation simplex agrees with the independent
//! successive-shortest-path solver, with the 1-D closed form and with hand
//! values, and behaves as a metric.

mod common;

use common::*;
use cvm_reference::*;
use proptest::prelude::*;

const GROUNDS: [Ground; 2] = [Ground::Euclid, Ground::L1];

/// 2x2 detector, cells (0,0) (0,1) / (1,0) (1,1):
/// - all mass from (0,0) to (1,1): Euclid sqrt(2), L1 2;
/// - top row [1/2, 1/2] to bottom row [1/2, 1/2]: each half moves one cell
///   down, cost 1 under both grounds;
/// - [1, 0, 0, 0] to [0, 1/2, 1/2, 0]: each half moves one cell, cost 1.
#[test]
fn hand_computed_2x2() {
    let g = Geometry::new(2, 2).unwrap();
    let cases: [([f64; 4], [f64; 4], f64, f64); 3] = [
        ([1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], 2f64.sqrt(), 2.0),
        ([3.0, 3.0, 0.0, 0.0], [0.0, 0.0, 5.0, 5.0], 1.0, 1.0),
        ([7.0, 0.0, 0.0, 0.0], [0.0, 1.0, 1.0, 0.0], 1.0, 1.0),
    ];
    for (a, b, euclid, l1) in cases {
        for (ground, want) in [(Ground::Euclid, euclid), (Ground::L1, l1)] {
            for d in [emd(g, ground, &a, &b), emd_independent(g, ground, &a, &b)] {
                assert!(
                    close(d, want, 1e-14, 1e-15),
                    "{a:?} {b:?} {ground:?}: {d} != {want}"
                );
            }
        }
    }
}

/// 1x4: [1,0,0,0] vs [0,0,0,1] moves everything 3 cells; CDF differences
/// 1, 1, 1, 0 sum to 3 as well.
#[test]
fn hand_computed_line() {
    let a = [1.0, 0.0, 0.0, 0.0];
    let b = [0.0, 0.0, 0.0, 1.0];
    assert_eq!(emd_1d_closed_form(&a, &b), 3.0);
    let g = Geometry::new(1, 4).unwrap();
    assert!(close(emd(g, Ground::Euclid, &a, &b), 3.0, 1e-14, 0.0));
}

#[test]
fn dark_map_convention() {
    let g = Geometry::new(9, 15).unwrap();
    let dark = vec![0.0; g.cells()];
    let mut lit = vec![0.0; g.cells()];
    lit[17] = 4.0;
    // Diameter of a 9x15 grid: from (0,0) to (8,14).
    let diag = (8f64 * 8.0 + 14.0 * 14.0).sqrt();
    assert!(close(
        dark_lit_distance(g, Ground::Euclid),
        diag,
        1e-15,
        0.0
    ));
    assert_eq!(dark_lit_distance(g, Ground::L1), 22.0);
    assert_eq!(emd(g, Ground::Euclid, &dark, &dark), 0.0);
    assert_eq!(emd(g, Ground::L1, &dark, &lit), 22.0);
    assert_eq!(emd(g, Ground::L1, &lit, &dark), 22.0);
    assert_eq!(mean_dir(g, &dark, &dark), 0.0);
    assert!(close(mean_dir(g, &dark, &lit), diag, 1e-15, 0.0));
    // A single cell still scores a lost beam.
    let one = Geometry::new(1, 1).unwrap();
    assert_eq!(emd(one, Ground::Euclid, &[0.0], &[5.0]), 1.0);
    assert_eq!(emd(one, Ground::Euclid, &[3.0], &[5.0]), 0.0);
}

fn emd_case() -> impl Strategy<Value = (Geometry, Vec<f64>, Vec<f64>)> {
    prop::sample::select(
        &[
            (1usize, 1usize),
            (2, 2),
            (1, 7),
            (3, 5),
            (6, 1),
            (9, 9),
            (4, 16),
        ][..],
    )
    .prop_flat_map(|j| {
        let g = geometry(j);
        (Just(g), map_pair(g.cells())).prop_map(|(g, (a, b))| (g, a, b))
    })
}

/// Absolute floor: rounding of the masses (1e-16 each) times the largest
/// ground distance, summed over cells.
fn floor(g: Geometry) -> f64 {
    1e-13 * g.cells() as f64 * dark_lit_distance(g, Ground::L1)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn simplex_matches_independent_solver((g, a, b) in emd_case()) {
        for ground in GROUNDS {
            let e = Emd::new(g, ground);
            let fast = e.distance_simplex_only(&e.prepare(&a), &e.prepare(&b));
            prop_assert!(fast.is_some(), "simplex ran out of pivots");
            let fast = fast.unwrap_or(f64::NAN);
            let slow = emd_independent(g, ground, &a, &b);
            prop_assert!(close(fast, slow, 1e-9, floor(g)), "{ground:?}: simplex {fast} vs ssp {slow}");
        }
    }

    #[test]
    fn line_matches_closed_form(n in 1usize..=16, vertical in any::<bool>(), seed in map_pair(16)) {
        let (a, b) = (&seed.0[..n], &seed.1[..n]);
        let g = if vertical { Geometry::new(n, 1) } else { Geometry::new(1, n) }.unwrap();
        let want = emd_1d_closed_form(a, b);
        for ground in GROUNDS {
            for d in [emd(g, ground, a, b), emd_independent(g, ground, a, b)] {
                prop_assert!(close(d, want, 1e-9, floor(g)), "{ground:?}: {d} vs closed form {want}");
            }
        }
    }

    #[test]
    fn metric_properties((g, a, b) in emd_case(), c_seed in raw_map(256), scale in 0.01f64..100.0) {
        let c = &c_seed[..g.cells()];
        for ground in GROUNDS {
            let e = Emd::new(g, ground);
            let (pa, pb, pc) = (e.prepare(&a), e.prepare(&b), e.prepare(c));
            let ab = e.distance(&pa, &pb);
            prop_assert!(ab >= 0.0);
            prop_assert_eq!(e.distance(&pa, &pa), 0.0);
            prop_assert!(close(ab, e.distance(&pb, &pa), 1e-9, floor(g)));
            let (ac, cb) = (e.distance(&pa, &pc), e.distance(&pc, &pb));
            prop_assert!(ab <= ac + cb + floor(g), "triangle: {ab} > {ac} + {cb}");
            let scaled: Vec<f64> = a.iter().map(|x| x * scale).collect();
            prop_assert!(close(ab, e.distance(&e.prepare(&scaled), &pb), 1e-9, floor(g)));
        }
        // City-block distances dominate Euclidean ones cell by cell, and so
        // does the optimum; the Euclidean EMD is at least the distance of
        // the means (moving mass shifts the mean by no more than its cost).
        let l1 = emd(g, Ground::L1, &a, &b);
        let eu = emd(g, Ground::Euclid, &a, &b);
        prop_assert!(eu <= l1 + floor(g));
        if lit(&a) && lit(&b) {
            prop_assert!(mean_dir(g, &a, &b) <= eu + floor(g));
        }
    }
}

/// The full-size geometry of the paper's simulation, dense random maps: the
/// largest problems the simplex meets (225 x 225 cells).
#[test]
fn simplex_matches_independent_solver_15x15_dense() {
    let g = Geometry::new(15, 15).unwrap();
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f64
    };
    for _ in 0..3 {
        let a: Vec<f64> = (0..g.cells()).map(|_| next()).collect();
        let b: Vec<f64> = (0..g.cells()).map(|_| next()).collect();
        for ground in GROUNDS {
            let e = Emd::new(g, ground);
            let fast = e
                .distance_simplex_only(&e.prepare(&a), &e.prepare(&b))
                .expect("simplex finishes within its budget");
            let slow = emd_independent(g, ground, &a, &b);
            assert!(close(fast, slow, 1e-9, 0.0), "{ground:?}: {fast} vs {slow}");
        }
    }
}

/// Many equal integer masses make most pivots degenerate: the anti-cycling
/// rule must still reach the optimum.
#[test]
fn degenerate_problems_reach_the_optimum() {
    let n = 12;
    let supply = vec![1.0; n];
    let demand = vec![1.0; n];
    // Cost |i - j| + 1 everywhere except a cheap anti-diagonal.
    let cost: Vec<f64> = (0..n * n)
        .map(|c| {
            let (i, j) = (c / n, c % n);
            if i + j == n - 1 {
                0.5
            } else {
                (i.abs_diff(j) + 1) as f64
            }
        })
        .collect();
    assert_eq!(
        transport_simplex_checked(&supply, &demand, &cost),
        Some(0.5 * n as f64)
    );
    assert_eq!(min_cost_transport(&supply, &demand, &cost), 0.5 * n as f64);
}

/// Assignment problems (unit supplies and demands, integer costs) are as
/// degenerate as transport gets: half the basic cells carry zero flow.
#[test]
fn random_assignment_problems_match_independent_solver() {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = |k: u64| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state % k
    };
    for trial in 0..200 {
        let n = 2 + (trial % 14);
        let ones = vec![1.0; n];
        let cost: Vec<f64> = (0..n * n).map(|_| next(5) as f64).collect();
        let fast = transport_simplex_checked(&ones, &ones, &cost).expect("within budget");
        let slow = min_cost_transport(&ones, &ones, &cost);
        assert!(
            close(fast, slow, 1e-12, 1e-12),
            "trial {trial}: {fast} vs {slow}"
        );
    }
}

#[test]
fn mean_direction_hand_values() {
    let g = Geometry::new(3, 4).unwrap();
    // Half the light in (0,0), half in (2,3): mean (1, 1.5).
    let mut a = vec![0.0; 12];
    a[g.index(0, 0)] = 2.0;
    a[g.index(2, 3)] = 2.0;
    assert_eq!(mean_direction(g, &a), Some([1.0, 1.5]));
    // Single cell (1, 1): mean (1, 1), distance to the above sqrt(0 + 0.25).
    let mut b = vec![0.0; 12];
    b[g.index(1, 1)] = 9.0;
    assert!(close(mean_dir(g, &a, &b), 0.5, 1e-15, 0.0));
    assert_eq!(mean_direction(g, &[0.0; 12]), None);
}
