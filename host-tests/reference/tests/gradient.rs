//! Eq. 1 over a scan: the border rule, and prepared distances matching the
//! plain per-pair definition.

mod common;

use common::*;
use cvm_reference::*;
use proptest::prelude::*;

/// One row of three maps on a 1x3 detector: a, b, c = single cells 0, 1, 2.
/// g0 (horizontal, neighbours in the row, the border replaced by the map
/// itself): col 0 -> d(a, b), col 1 -> d(a, c), col 2 -> d(b, c); g1 is 0
/// everywhere (one row: both vertical neighbours are the map itself).
/// With unit paper kernels (b in {1,2,3}, only b = 1 informative; see the
/// 1x3 hand case in cvm.rs): d(a, b): b=1 boxes [1,2],[1,3],[2,3] give
/// (1-1)^2 + 0 + (0-1)^2 = 1; d(a, c) = 2; d(b, c) = 1.
#[test]
fn border_rule_by_hand() {
    let g = Geometry::new(1, 3).unwrap();
    let scan = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    let c = CvmConfig::paper(g, PaperWeights::Unit, None).unwrap();
    let want = [1.0, 0.0, 1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 1.0];
    let fast = gradient_image(&scan, 1, 3, g, &CvmEmbedding::new(&c));
    let plain = gradient_image_fn(&scan, 1, 3, g, |x, y| cvm_brute(&c, x, y));
    for (got, want) in fast.iter().chain(&plain).zip(want.iter().cycle()) {
        assert!(close(*got, *want, 1e-14, 1e-15), "{fast:?} / {plain:?}");
    }
    // The same maps as one column: the components swap.
    let col = gradient_image_fn(&scan, 3, 1, g, |x, y| cvm_brute(&c, x, y));
    for p in 0..3 {
        assert_eq!(col[p * 3], 0.0);
        assert!(close(col[p * 3 + 1], want[p * 3], 1e-14, 0.0));
    }
}

fn scan_case() -> impl Strategy<Value = (Geometry, usize, usize, Vec<f64>)> {
    (
        prop::sample::select(&[(1usize, 1usize), (2, 3), (3, 3), (5, 4)][..]),
        1usize..5,
        1usize..5,
    )
        .prop_flat_map(|(j, rows, cols)| {
            let g = geometry(j);
            let maps = prop::collection::vec(raw_map(g.cells()), rows * cols);
            (Just(g), Just(rows), Just(cols), maps)
        })
        .prop_map(|(g, rows, cols, maps)| (g, rows, cols, maps.concat()))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(100))]

    #[test]
    fn prepared_gradient_matches_plain_definition((g, rows, cols, scan) in scan_case()) {
        let configs = [
            CvmConfig::paper(g, PaperWeights::Uniform, None).unwrap(),
            CvmConfig::square(g, None).unwrap().with_normalise(false),
        ];
        for c in &configs {
            let fast = gradient_image(&scan, rows, cols, g, &CvmEmbedding::new(c));
            let plain = gradient_image_fn(&scan, rows, cols, g, |x, y| cvm_brute(c, x, y));
            prop_assert_eq!(fast.len(), rows * cols * 3);
            let t: f64 = scan.iter().sum::<f64>().max(1.0);
            let abs = if c.normalises() { 1e-12 } else { 1e-12 * t * t };
            for (f, p) in fast.iter().zip(&plain) {
                prop_assert!(close(*f, *p, 1e-9, abs), "{f} vs {p}");
            }
        }
        let e = Emd::new(g, Ground::Euclid);
        let fast = gradient_image(&scan, rows, cols, g, &e);
        let plain = gradient_image_fn(&scan, rows, cols, g, |x, y| emd_independent(g, Ground::Euclid, x, y));
        for (f, p) in fast.iter().zip(&plain) {
            prop_assert!(close(*f, *p, 1e-9, 1e-12), "emd {f} vs {p}");
        }
        let fast = gradient_image(&scan, rows, cols, g, &MeanDir(g));
        let plain = gradient_image_fn(&scan, rows, cols, g, |x, y| mean_dir(g, x, y));
        prop_assert_eq!(fast, plain);
    }
}
