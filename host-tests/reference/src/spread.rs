//! Spread of a map: how widely the light is spread over the detector,
//! whatever its position, and the two ways of deciding on it over a scan.
//!
//! A scattering defect keeps the spot where it is and adds a faint, wide
//! halo: the normalised map's distance to its neighbours hardly changes,
//! but its second moment about its own centroid grows with the halo's
//! share times the halo's extent squared.

use crate::geometry::Geometry;

/// Second moment of the normalised map about its centroid, summed over both
/// axes, in detector cells squared:
/// `Σ ã(j) ((j1 - μ1)² + (j2 - μ2)²)` with `μ = Σ ã(j) j`. It is 0 for a
/// single lit cell, and does not depend on the map's power or position.
/// `None` for a dark map.
///
/// # Panics
/// If the map's length is not `J1 * J2`.
pub fn spread_moment(geometry: Geometry, raw: &[f64]) -> Option<f64> {
    geometry.check_map(raw);
    let total: f64 = raw.iter().sum();
    if total == 0.0 {
        return None;
    }
    let mut mu = [0.0; 2];
    for (c, &a) in raw.iter().enumerate() {
        let (i1, i2) = geometry.cell(c);
        mu[0] += a * i1 as f64;
        mu[1] += a * i2 as f64;
    }
    mu = [mu[0] / total, mu[1] / total];
    // About the centroid rather than E|j|² - |μ|², which cancels badly for
    // a compact spot far from cell 0.
    let mut m = 0.0;
    for (c, &a) in raw.iter().enumerate() {
        let (i1, i2) = geometry.cell(c);
        let (d1, d2) = (i1 as f64 - mu[0], i2 as f64 - mu[1]);
        m += a * (d1 * d1 + d2 * d2);
    }
    Some(m / total)
}

/// Fraction of the map's power outside its core: the box of `half` cells to
/// each side of the brightest cell (the first in row-major order on ties),
/// clipped at the detector's edges. `None` for a dark map.
///
/// # Panics
/// If the map's length is not `J1 * J2`.
pub fn outside_core(geometry: Geometry, raw: &[f64], half: usize) -> Option<f64> {
    geometry.check_map(raw);
    let total: f64 = raw.iter().sum();
    if total == 0.0 {
        return None;
    }
    let mut peak = 0;
    for (c, &a) in raw.iter().enumerate() {
        if a > raw[peak] {
            peak = c;
        }
    }
    let (p1, p2) = geometry.cell(peak);
    let mut core = 0.0;
    for (c, &a) in raw.iter().enumerate() {
        let (i1, i2) = geometry.cell(c);
        if i1.abs_diff(p1) <= half && i2.abs_diff(p2) <= half {
            core += a;
        }
    }
    Some((total - core) / total)
}

fn check_values(values: &[f64], rows: usize, cols: usize) {
    assert_eq!(
        values.len(),
        rows * cols,
        "{rows}x{cols} values, one per position"
    );
}

/// Decision rule (a), Eq. 1 applied to a per-position value `v` (row-major
/// `rows x cols`): `hypot(|v(r, c+1) - v(r, c-1)|, |v(r+1, c) - v(r-1, c)|)`,
/// a neighbour outside the scan replaced by the position itself, as in the
/// CVM and power channels.
///
/// # Panics
/// If `values.len() != rows * cols`.
pub fn neighbour_gradient(values: &[f64], rows: usize, cols: usize) -> Vec<f64> {
    check_values(values, rows, cols);
    let at = |r: usize, c: usize| values[r * cols + c];
    let mut out = Vec::with_capacity(values.len());
    for r in 0..rows {
        for c in 0..cols {
            let g0 = at(r, (c + 1).min(cols - 1)) - at(r, c.saturating_sub(1));
            let g1 = at((r + 1).min(rows - 1), c) - at(r.saturating_sub(1), c);
            out.push(g0.hypot(g1));
        }
    }
    out
}

/// Decision rule (b): `v(m)` minus the lower median of `v` over the
/// `(2 half + 1)²` window centred on `m` (the position included), clipped
/// at the scan's edges. Positive where a position stands above its
/// surroundings.
///
/// # Panics
/// If `values.len() != rows * cols`.
pub fn local_deviation(values: &[f64], rows: usize, cols: usize, half: usize) -> Vec<f64> {
    check_values(values, rows, cols);
    let mut window = Vec::with_capacity((2 * half + 1) * (2 * half + 1));
    let mut out = Vec::with_capacity(values.len());
    for r in 0..rows {
        for c in 0..cols {
            window.clear();
            for rr in r.saturating_sub(half)..(r + half + 1).min(rows) {
                for cc in c.saturating_sub(half)..(c + half + 1).min(cols) {
                    window.push(values[rr * cols + cc]);
                }
            }
            window.sort_by(f64::total_cmp);
            out.push(values[r * cols + c] - window[(window.len() - 1) / 2]);
        }
    }
    out
}
