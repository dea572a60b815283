//! The box bounds of Eq. 6 against a definition written differently: a box
//! is the set of cells within distance `b` of its centre on each axis,
//! found by testing every cell. `cvm_brute`, `cvm_sat` and the embedding
//! share `box_range`, so their agreement alone cannot catch a wrong bound;
//! here each of them is compared with a distance summed over enumerated
//! cells.

mod common;

use common::*;
use cvm_reference::*;
use proptest::prelude::*;

/// Cells (1-based) of the box of centre `j` and size `b` on an axis of
/// `len` cells: every cell `i` with `|i - j| <= b`.
fn box_cells(j: usize, b: usize, len: usize) -> Vec<usize> {
    (1..=len).filter(|&i| i.abs_diff(j) <= b).collect()
}

/// `A(j, b)` of Eq. 6 summed over the enumerated cells of both axes.
fn lcd_by_cells(g: Geometry, map: &[f64], j: (usize, usize), b: (usize, usize)) -> f64 {
    let mut s = 0.0;
    for i1 in box_cells(j.0, b.0, g.j1()) {
        for i2 in box_cells(j.1, b.1, g.j2()) {
            s += map[(i1 - 1) * g.j2() + (i2 - 1)];
        }
    }
    s
}

/// Eq. 9 with every LCD over enumerated cells, normalising by hand.
fn cvm_by_cells(c: &CvmConfig, a: &[f64], b: &[f64]) -> f64 {
    let g = c.geometry();
    let prep = |m: &[f64]| -> Vec<f64> {
        let t: f64 = m.iter().sum();
        if !c.normalises() {
            m.to_vec()
        } else if t == 0.0 {
            vec![0.0; m.len()]
        } else {
            m.iter().map(|x| x / t).collect()
        }
    };
    let (pa, pb) = (prep(a), prep(b));
    let mut d = 0.0;
    for j1 in 1..=g.j1() {
        for j2 in 1..=g.j2() {
            for k in c.kernels() {
                let diff = lcd_by_cells(g, &pa, (j1, j2), (k.b1, k.b2))
                    - lcd_by_cells(g, &pb, (j1, j2), (k.b1, k.b2));
                d += k.w * diff * diff;
            }
        }
    }
    d
}

/// Every centre, size and axis length the detector allows.
#[test]
fn box_range_is_the_set_of_cells_within_b() {
    for len in 1..=16 {
        for j in 1..=len {
            for b in 0..=17 {
                let cells = box_cells(j, b, len);
                let (lo, hi) = box_range(j, b, len);
                assert_eq!(
                    (lo, hi),
                    (cells[0], *cells.last().unwrap()),
                    "j={j} b={b} len={len}"
                );
                // Contiguous, so the bounds describe the whole set.
                assert_eq!(cells.len(), hi - lo + 1);
            }
        }
    }
}

/// `lcd_brute` and the summed-area table's `lcd` on a map whose cells are
/// distinct powers of two, so that any cell added or left out shows.
#[test]
fn lcds_sum_exactly_the_enumerated_cells() {
    for (j1, j2) in [(1, 1), (1, 4), (3, 1), (3, 5), (6, 6), (9, 15), (16, 16)] {
        let g = geometry((j1, j2));
        let map: Vec<f64> = (0..g.cells()).map(|i| (2.0f64).powi(i as i32)).collect();
        let sat = SummedAreaTable::new(g, &map);
        for c1 in 1..=j1 {
            for c2 in 1..=j2 {
                for b1 in 0..=j1 {
                    for b2 in 0..=j2 {
                        let want = lcd_by_cells(g, &map, (c1, c2), (b1, b2));
                        let (j, b) = ((c1, c2), (b1, b2));
                        assert_eq!(lcd_brute(g, &map, j, b), want, "{g:?} {j:?} {b:?}");
                        // Four table entries of sums below 2^256: exact
                        // while the box sum fits the 53-bit mantissa
                        // relative to the largest cell it touches.
                        let s = sat.lcd(j, b);
                        assert!(close(s, want, 1e-15, 0.0), "{g:?} {j:?} {b:?}: {s} {want}");
                    }
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// All three implementations against the distance over enumerated cells.
    #[test]
    fn every_implementation_matches_enumerated_boxes(
        j in prop::sample::select(GEOMETRIES),
        kind in 0usize..3,
        cap in proptest::option::of(1usize..=4),
        normalise in any::<bool>(),
        seed in any::<u64>(),
    ) {
        let g = geometry(j);
        let c = match kind {
            0 => CvmConfig::paper(g, PaperWeights::Unit, cap),
            1 => CvmConfig::paper(g, PaperWeights::Uniform, cap),
            _ => CvmConfig::square(g, cap.map(|k| k.min(g.j1().max(g.j2()) - 1))),
        }
        .unwrap()
        .with_normalise(normalise);
        // Two maps from a small generator: counts 0..1000, some cells dark.
        let mut s = seed | 1;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let mut map = || -> Vec<f64> {
            (0..g.cells())
                .map(|_| {
                    let v = next();
                    if v % 4 == 0 { 0.0 } else { (v >> 8) as f64 % 1000.0 }
                })
                .collect()
        };
        let (a, b) = (map(), map());
        let want = cvm_by_cells(&c, &a, &b);
        let scale = if normalise { 1.0 } else { (1000.0 * g.cells() as f64).powi(2) };
        let wsum: f64 = c.kernels().iter().map(|k| k.w).sum();
        let abs = 1e-13 * scale * wsum * g.cells() as f64;
        for (name, d) in [
            ("brute", cvm_brute(&c, &a, &b)),
            ("sat", cvm_sat(&c, &a, &b)),
            ("embedding", cvm_embedding(&c, &a, &b)),
        ] {
            prop_assert!(close(d, want, 1e-9, abs), "{name}: {d} vs {want} ({c:?})");
        }
    }
}
