//! The gradient of Eq. 1 over a whole scan, with the border rule.

use crate::geometry::Geometry;
use crate::kernels::CvmConfig;

/// A distance between deflection maps that can do per-map work once: each
/// map of a scan is [`prepare`](MapDistance::prepare)d once and the prepared
/// forms are compared ([`distance`](MapDistance::distance)) with each
/// neighbour.
pub trait MapDistance {
    /// What a raw map turns into before comparison.
    type Prepared;
    /// Per-map work (normalisation, embedding, ...).
    fn prepare(&self, raw: &[f64]) -> Self::Prepared;
    /// The distance of two prepared maps.
    fn distance(&self, a: &Self::Prepared, b: &Self::Prepared) -> f64;
}

/// The CVM distance by [`cvm_brute`](crate::cvm_brute), as a
/// [`MapDistance`] (prepared form: the raw map itself).
#[derive(Clone, Debug)]
pub struct BruteCvm(pub CvmConfig);

impl MapDistance for BruteCvm {
    type Prepared = Vec<f64>;
    fn prepare(&self, raw: &[f64]) -> Vec<f64> {
        raw.to_vec()
    }
    fn distance(&self, a: &Vec<f64>, b: &Vec<f64>) -> f64 {
        crate::cvm_brute(&self.0, a, b)
    }
}

impl MapDistance for crate::CvmEmbedding {
    type Prepared = Vec<f64>;
    fn prepare(&self, raw: &[f64]) -> Vec<f64> {
        self.embed(raw)
    }
    fn distance(&self, a: &Vec<f64>, b: &Vec<f64>) -> f64 {
        crate::CvmEmbedding::distance(self, a, b)
    }
}

fn check_scan(scan: &[f64], rows: usize, cols: usize, geometry: Geometry) {
    assert_eq!(
        scan.len(),
        rows * cols * geometry.cells(),
        "scan of {rows}x{cols} maps of {} cells",
        geometry.cells()
    );
}

/// Eq. 1 over a scan `scan[row, col, j1, j2]` (C order): for each position
/// `[g0, g1, sqrt(g0^2 + g1^2)]` with `g0 = d(left, right)` (neighbours in
/// the same row, the fast axis `m1`) and `g1 = d(up, down)` (neighbours in
/// the same column). A neighbour outside the scan is replaced by the map
/// itself. Output: `rows * cols * 3` values, row-major.
///
/// Calls `distance` on raw maps, twice per position, with no caching: the
/// plainest possible statement of Eq. 1.
///
/// # Panics
/// If `scan.len() != rows * cols * J1 * J2`.
pub fn gradient_image_fn(
    scan: &[f64],
    rows: usize,
    cols: usize,
    geometry: Geometry,
    distance: impl Fn(&[f64], &[f64]) -> f64,
) -> Vec<f64> {
    check_scan(scan, rows, cols, geometry);
    let n = geometry.cells();
    let map = |r: usize, c: usize| &scan[(r * cols + c) * n..(r * cols + c + 1) * n];
    let mut out = Vec::with_capacity(rows * cols * 3);
    for r in 0..rows {
        for c in 0..cols {
            let left = if c > 0 { map(r, c - 1) } else { map(r, c) };
            let right = if c + 1 < cols {
                map(r, c + 1)
            } else {
                map(r, c)
            };
            let up = if r > 0 { map(r - 1, c) } else { map(r, c) };
            let down = if r + 1 < rows {
                map(r + 1, c)
            } else {
                map(r, c)
            };
            let g0 = distance(left, right);
            let g1 = distance(up, down);
            out.extend([g0, g1, g0.hypot(g1)]);
        }
    }
    out
}

/// Eq. 1 over a scan as [`gradient_image_fn`], but preparing every map once
/// through a [`MapDistance`].
///
/// # Panics
/// If `scan.len() != rows * cols * J1 * J2`.
pub fn gradient_image<D: MapDistance>(
    scan: &[f64],
    rows: usize,
    cols: usize,
    geometry: Geometry,
    distance: &D,
) -> Vec<f64> {
    check_scan(scan, rows, cols, geometry);
    let n = geometry.cells();
    let prepared: Vec<D::Prepared> = if n == 0 {
        Vec::new()
    } else {
        scan.chunks_exact(n).map(|m| distance.prepare(m)).collect()
    };
    let at = |r: usize, c: usize| &prepared[r * cols + c];
    let mut out = Vec::with_capacity(rows * cols * 3);
    for r in 0..rows {
        for c in 0..cols {
            let left = at(r, c.saturating_sub(1));
            let right = at(r, (c + 1).min(cols - 1));
            let up = at(r.saturating_sub(1), c);
            let down = at((r + 1).min(rows - 1), c);
            let g0 = distance.distance(left, right);
            let g1 = distance.distance(up, down);
            out.extend([g0, g1, g0.hypot(g1)]);
        }
    }
    out
}
