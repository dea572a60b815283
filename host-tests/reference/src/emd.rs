//! Earth mover's distance between normalised deflection maps.

use crate::geometry::Geometry;
use crate::gradient::MapDistance;
use crate::normalise::normalise;

/// Ground distance between two cells, in cell units (cell centres one unit
/// apart on each axis).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ground {
    /// Euclidean distance between the cell centres.
    Euclid,
    /// City-block (L1) distance between the cell centres.
    L1,
}

impl Ground {
    /// Distance between 0-based cells `a` and `b`.
    pub fn between(self, a: (usize, usize), b: (usize, usize)) -> f64 {
        let d1 = a.0.abs_diff(b.0) as f64;
        let d2 = a.1.abs_diff(b.1) as f64;
        match self {
            Self::Euclid => d1.hypot(d2),
            Self::L1 => d1 + d2,
        }
    }
}

/// The distance between a dark map (no light, docs/method.md §3) and a lit one,
/// for EMD and mean deflection: the grid's diameter (largest ground distance
/// between two cells), but at least one cell.
///
/// Every EMD between lit maps is at most the diameter, so losing the beam
/// scores at least as high as any redistribution of it; the floor of 1 keeps
/// `d(dark, lit) > 0` on a 1x1 detector. Dark against dark is 0.
pub fn dark_lit_distance(geometry: Geometry, ground: Ground) -> f64 {
    ground
        .between((0, 0), (geometry.j1() - 1, geometry.j2() - 1))
        .max(1.0)
}

/// A map prepared for EMD: normalised (Eq. 5), with its dark flag.
#[derive(Clone, Debug, PartialEq)]
pub struct EmdMap {
    /// The normalised map `ã`.
    pub map: Vec<f64>,
    /// The raw map summed to 0.
    pub dark: bool,
}

/// Exact EMD for one geometry and ground distance, with the ground-cost
/// table computed once.
#[derive(Clone, Debug)]
pub struct Emd {
    geometry: Geometry,
    ground: Ground,
    cost: Vec<f64>,
}

impl Emd {
    /// Tables for `geometry` and `ground`.
    pub fn new(geometry: Geometry, ground: Ground) -> Self {
        let n = geometry.cells();
        let mut cost = vec![0.0; n * n];
        for a in 0..n {
            for b in 0..n {
                cost[a * n + b] = ground.between(geometry.cell(a), geometry.cell(b));
            }
        }
        Self {
            geometry,
            ground,
            cost,
        }
    }

    /// Normalise a raw map.
    ///
    /// # Panics
    /// If the map's length is not `J1 * J2`.
    pub fn prepare(&self, raw: &[f64]) -> EmdMap {
        self.geometry.check_map(raw);
        let nm = normalise(raw);
        EmdMap {
            map: nm.map,
            dark: nm.dark,
        }
    }

    fn dark_rule(&self, a: &EmdMap, b: &EmdMap) -> Option<f64> {
        match (a.dark, b.dark) {
            (false, false) => None,
            (true, true) => Some(0.0),
            _ => Some(dark_lit_distance(self.geometry, self.ground)),
        }
    }

    fn sub_cost(&self, from: &[usize], to: &[usize]) -> Vec<f64> {
        let n = self.geometry.cells();
        from.iter()
            .flat_map(|&a| to.iter().map(move |&b| self.cost[a * n + b]))
            .collect()
    }

    /// The exact EMD of two prepared maps, by [`crate::transport_simplex`].
    ///
    /// For a metric ground distance the optimal cost depends only on the
    /// difference `ã1 - ã2` (Kantorovich-Rubinstein duality): mass present in
    /// both maps stays where it is. So only the cells where `ã1` exceeds
    /// `ã2` ship, only those where it falls short receive, and neighbouring
    /// maps of a scan, which differ in few cells, give small problems.
    pub fn distance(&self, a: &EmdMap, b: &EmdMap) -> f64 {
        if let Some(d) = self.dark_rule(a, b) {
            return d;
        }
        let (from, supply, to, demand) = split_difference(a, b);
        crate::transport_simplex(&supply, &demand, &self.sub_cost(&from, &to))
    }

    /// As [`Emd::distance`], but `None` if the simplex ran out of its
    /// iteration budget instead of falling back to the slow solver.
    pub fn distance_simplex_only(&self, a: &EmdMap, b: &EmdMap) -> Option<f64> {
        if let Some(d) = self.dark_rule(a, b) {
            return Some(d);
        }
        let (from, supply, to, demand) = split_difference(a, b);
        crate::transport_simplex_checked(&supply, &demand, &self.sub_cost(&from, &to))
    }

    /// The exact EMD of two prepared maps by the independent
    /// successive-shortest-path solver [`crate::min_cost_transport`], on the
    /// full supports (no difference trick). For checking only: slow.
    pub fn distance_independent(&self, a: &EmdMap, b: &EmdMap) -> f64 {
        if let Some(d) = self.dark_rule(a, b) {
            return d;
        }
        let support = |m: &EmdMap| -> (Vec<usize>, Vec<f64>) {
            m.map
                .iter()
                .enumerate()
                .filter(|(_, x)| **x > 0.0)
                .map(|(c, &x)| (c, x))
                .unzip()
        };
        let (from, supply) = support(a);
        let (to, demand) = support(b);
        crate::min_cost_transport(&supply, &demand, &self.sub_cost(&from, &to))
    }
}

type Split = (Vec<usize>, Vec<f64>, Vec<usize>, Vec<f64>);

/// Cells where `ã1 > ã2` with their excess, and cells where `ã1 < ã2` with
/// their shortfall.
fn split_difference(a: &EmdMap, b: &EmdMap) -> Split {
    let (mut from, mut supply, mut to, mut demand) = (vec![], vec![], vec![], vec![]);
    for (c, (x, y)) in a.map.iter().zip(&b.map).enumerate() {
        let diff = x - y;
        if diff > 0.0 {
            from.push(c);
            supply.push(diff);
        } else if diff < 0.0 {
            to.push(c);
            demand.push(-diff);
        }
    }
    (from, supply, to, demand)
}

impl MapDistance for Emd {
    type Prepared = EmdMap;
    fn prepare(&self, raw: &[f64]) -> EmdMap {
        Emd::prepare(self, raw)
    }
    fn distance(&self, a: &EmdMap, b: &EmdMap) -> f64 {
        Emd::distance(self, a, b)
    }
}

/// Exact EMD of two raw maps (normalised first), transportation simplex.
pub fn emd(geometry: Geometry, ground: Ground, a1: &[f64], a2: &[f64]) -> f64 {
    let e = Emd::new(geometry, ground);
    e.distance(&e.prepare(a1), &e.prepare(a2))
}

/// Exact EMD of two raw maps by the independent min-cost-flow solver.
pub fn emd_independent(geometry: Geometry, ground: Ground, a1: &[f64], a2: &[f64]) -> f64 {
    let e = Emd::new(geometry, ground);
    e.distance_independent(&e.prepare(a1), &e.prepare(a2))
}

/// EMD on a line of cells (a `1 x N` or `N x 1` map), where either ground
/// distance is `|i - j|`: the L1 distance of the two cumulative
/// distributions, `sum_k |F1(k) - F2(k)|`. Same dark-map rule as [`Emd`].
pub fn emd_1d_closed_form(a1: &[f64], a2: &[f64]) -> f64 {
    let (n1, n2) = (normalise(a1), normalise(a2));
    match (n1.dark, n2.dark) {
        (true, true) => return 0.0,
        (true, false) | (false, true) => return (a1.len().saturating_sub(1) as f64).max(1.0),
        (false, false) => {}
    }
    let (mut f1, mut f2, mut d) = (0.0, 0.0, 0.0);
    for (x, y) in n1.map.iter().zip(&n2.map) {
        f1 += x;
        f2 += y;
        d += (f1 - f2).abs();
    }
    d
}
