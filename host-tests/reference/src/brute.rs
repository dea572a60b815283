//! The CVM distance straight from its definition (Eq. 6, 8, 9).

use crate::kernels::{CvmConfig, box_range};

/// `A(j, b)` of Eq. 6: the sum of `map` over the box of centre `j` and size
/// `b`, with `j` and `b` as in the paper (1-based centre).
pub fn lcd_brute(
    geometry: crate::Geometry,
    map: &[f64],
    j: (usize, usize),
    b: (usize, usize),
) -> f64 {
    let (lo1, hi1) = box_range(j.0, b.0, geometry.j1());
    let (lo2, hi2) = box_range(j.1, b.1, geometry.j2());
    let mut sum = 0.0;
    for i1 in lo1..=hi1 {
        for i2 in lo2..=hi2 {
            sum += map[geometry.index(i1 - 1, i2 - 1)];
        }
    }
    sum
}

/// Eq. 9: `sum_j sum_b w(b) (A1(j, b) - A2(j, b))^2`, every LCD summed cell
/// by cell. Slow (`O(J^6)` at worst) and deliberately free of any trick.
///
/// # Panics
/// If a map's length is not `J1 * J2`.
pub fn cvm_brute(config: &CvmConfig, a1: &[f64], a2: &[f64]) -> f64 {
    let g = config.geometry();
    let m1 = config.prepare(a1);
    let m2 = config.prepare(a2);
    let kernels = config.kernels();
    let mut d = 0.0;
    for j1 in 1..=g.j1() {
        for j2 in 1..=g.j2() {
            for k in &kernels {
                let diff = lcd_brute(g, &m1, (j1, j2), (k.b1, k.b2))
                    - lcd_brute(g, &m2, (j1, j2), (k.b1, k.b2));
                d += k.w * diff * diff;
            }
        }
    }
    d
}
