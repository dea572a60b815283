//! The CVM distance through summed-area tables (the "fast CMD"): every box
//! sum in O(1).

use crate::geometry::Geometry;
use crate::kernels::{CvmConfig, box_range};

/// Summed-area table of a map: `s[i1][i2]` is the sum of the cells `< (i1,
/// i2)`, stored `(J1 + 1) x (J2 + 1)` with a zero first row and column.
#[derive(Clone, Debug)]
pub struct SummedAreaTable {
    geometry: Geometry,
    s: Vec<f64>,
}

impl SummedAreaTable {
    /// The table of `map` (already normalised if that is wanted).
    ///
    /// # Panics
    /// If the map's length is not `J1 * J2`.
    pub fn new(geometry: Geometry, map: &[f64]) -> Self {
        geometry.check_map(map);
        let w = geometry.j2() + 1;
        let mut s = vec![0.0; (geometry.j1() + 1) * w];
        for i1 in 0..geometry.j1() {
            for i2 in 0..geometry.j2() {
                s[(i1 + 1) * w + i2 + 1] =
                    map[geometry.index(i1, i2)] + s[i1 * w + i2 + 1] + s[(i1 + 1) * w + i2]
                        - s[i1 * w + i2];
            }
        }
        Self { geometry, s }
    }

    /// `A(j, b)` (Eq. 6), `j` 1-based, from four table entries.
    pub fn lcd(&self, j: (usize, usize), b: (usize, usize)) -> f64 {
        let (lo1, hi1) = box_range(j.0, b.0, self.geometry.j1());
        let (lo2, hi2) = box_range(j.1, b.1, self.geometry.j2());
        let w = self.geometry.j2() + 1;
        self.s[hi1 * w + hi2] - self.s[(lo1 - 1) * w + hi2] - self.s[hi1 * w + lo2 - 1]
            + self.s[(lo1 - 1) * w + lo2 - 1]
    }
}

/// Eq. 9 with every LCD read from a summed-area table.
///
/// # Panics
/// If a map's length is not `J1 * J2`.
pub fn cvm_sat(config: &CvmConfig, a1: &[f64], a2: &[f64]) -> f64 {
    let g = config.geometry();
    let t1 = SummedAreaTable::new(g, &config.prepare(a1));
    let t2 = SummedAreaTable::new(g, &config.prepare(a2));
    let kernels = config.kernels();
    let mut d = 0.0;
    for j1 in 1..=g.j1() {
        for j2 in 1..=g.j2() {
            for k in &kernels {
                let diff = t1.lcd((j1, j2), (k.b1, k.b2)) - t2.lcd((j1, j2), (k.b1, k.b2));
                d += k.w * diff * diff;
            }
        }
    }
    d
}
