//! Helpers shared by the reference tests (included with `mod common;`).
#![allow(dead_code)]

use cvm_reference::Geometry;
use proptest::prelude::*;

/// Geometries the agreement tests sweep (docs/method.md §3 edge cases included:
/// 1x1, 2-cell axes, non-square, the paper's 9x9 and 15x15, the 16x16 limit).
pub const GEOMETRIES: &[(usize, usize)] = &[
    (1, 1),
    (2, 2),
    (2, 5),
    (2, 16),
    (7, 2),
    (16, 2),
    (3, 3),
    (9, 9),
    (9, 15),
    (15, 15),
    (16, 16),
];

pub fn geometry(j: (usize, usize)) -> Geometry {
    Geometry::new(j.0, j.1).expect("test geometry is valid")
}

/// `|a - b| <= rel * max(|a|, |b|) + abs`.
pub fn close(a: f64, b: f64, rel: f64, abs: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()) + abs
}

/// Raw maps like a detector gives: counts, often sparse (a focused beam
/// lights few cells), sometimes dense.
pub fn raw_map(cells: usize) -> impl Strategy<Value = Vec<f64>> {
    prop_oneof![
        prop::collection::vec(0u32..=65535, cells)
            .prop_map(|v| v.into_iter().map(f64::from).collect()),
        prop::collection::vec(prop_oneof![3 => Just(0u32), 1 => 1u32..5000], cells)
            .prop_map(|v| v.into_iter().map(f64::from).collect()),
        prop::collection::vec(0u32..4, cells).prop_map(|v| v.into_iter().map(f64::from).collect()),
    ]
}

/// Two raw maps of the same geometry, the second at times a small
/// perturbation of the first (like neighbouring beam positions).
pub fn map_pair(cells: usize) -> impl Strategy<Value = (Vec<f64>, Vec<f64>)> {
    prop_oneof![
        (raw_map(cells), raw_map(cells)),
        (raw_map(cells), prop::collection::vec(-3i32..=3, cells)).prop_map(|(a, dv)| {
            let b = a
                .iter()
                .zip(dv)
                .map(|(x, d)| (x + f64::from(d)).max(0.0))
                .collect();
            (a, b)
        }),
    ]
}

pub fn lit(map: &[f64]) -> bool {
    map.iter().any(|&x| x > 0.0)
}
