//! The mean-deflection baseline: distance between the mean deflection
//! directions of two maps.

use crate::emd::{Ground, dark_lit_distance};
use crate::geometry::Geometry;
use crate::gradient::MapDistance;
use crate::normalise::normalise;

/// Mean deflection direction of a raw map: the mean 0-based cell coordinate
/// `(sum ã(j) j1, sum ã(j) j2)` in cell units, `None` for a dark map.
///
/// # Panics
/// If the map's length is not `J1 * J2`.
pub fn mean_direction(geometry: Geometry, raw: &[f64]) -> Option<[f64; 2]> {
    geometry.check_map(raw);
    let nm = normalise(raw);
    if nm.dark {
        return None;
    }
    let mut mu = [0.0; 2];
    for (c, &x) in nm.map.iter().enumerate() {
        let (i1, i2) = geometry.cell(c);
        mu[0] += x * i1 as f64;
        mu[1] += x * i2 as f64;
    }
    Some(mu)
}

/// Euclidean length of the difference of the two maps' mean directions.
///
/// Dark maps: dark vs dark is 0; dark vs lit is
/// [`dark_lit_distance`]`(geometry, Ground::Euclid)` (the grid diagonal, at
/// least 1), which bounds every lit-vs-lit value because means lie inside
/// the grid.
pub fn mean_dir(geometry: Geometry, a1: &[f64], a2: &[f64]) -> f64 {
    let m = MeanDir(geometry);
    m.distance(&m.prepare(a1), &m.prepare(a2))
}

/// [`mean_dir`] as a [`MapDistance`] (prepared form: the mean direction).
#[derive(Clone, Copy, Debug)]
pub struct MeanDir(pub Geometry);

impl MapDistance for MeanDir {
    type Prepared = Option<[f64; 2]>;
    fn prepare(&self, raw: &[f64]) -> Option<[f64; 2]> {
        mean_direction(self.0, raw)
    }
    fn distance(&self, a: &Option<[f64; 2]>, b: &Option<[f64; 2]>) -> f64 {
        match (a, b) {
            (Some(p), Some(q)) => (p[0] - q[0]).hypot(p[1] - q[1]),
            (None, None) => 0.0,
            _ => dark_lit_distance(self.0, Ground::Euclid),
        }
    }
}
