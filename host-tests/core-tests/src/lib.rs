//! Helpers shared by the core's host tests: random maps and scans, and the
//! translation of one scoring configuration into both the fixed-point core
//! and the f64 reference.

use dmap::options::{KernelArg, ScoringArgs, WeightArg};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// The geometries every property is checked on.
pub const GEOMETRIES: &[(usize, usize)] =
    &[(1, 1), (1, 5), (2, 2), (2, 7), (7, 2), (3, 3), (4, 6), (9, 9), (9, 15), (15, 15), (16, 16)];

/// Every scoring variant the CLI offers.
pub fn variants(j1: usize, j2: usize) -> Vec<ScoringArgs> {
    let mut v = Vec::new();
    for raw in [false, true] {
        for w in [WeightArg::Uniform, WeightArg::Unit] {
            v.push(ScoringArgs { kernels: KernelArg::Paper, weights: Some(w), bmax: None, raw });
        }
        v.push(ScoringArgs { kernels: KernelArg::Paper, weights: None, bmax: Some(3), raw });
        v.push(ScoringArgs { kernels: KernelArg::Square, weights: None, bmax: None, raw });
        if j1.max(j2) > 2 {
            v.push(ScoringArgs { kernels: KernelArg::Square, weights: None, bmax: Some(1), raw });
        }
    }
    v
}

/// A deflection-map-like random map: a blurred spot at a random place plus
/// background, with a chance of a sparse or a dark map.
pub fn random_map(rng: &mut impl Rng, cells: usize, j2: usize) -> Vec<u16> {
    let j1 = cells / j2;
    match rng.random_range(0..10) {
        0 => vec![0; cells],
        1 => (0..cells).map(|_| if rng.random_bool(0.1) { rng.random() } else { 0 }).collect(),
        2 => (0..cells).map(|_| rng.random()).collect(),
        _ => {
            let (c1, c2) = (rng.random_range(0.0..j1 as f64), rng.random_range(0.0..j2 as f64));
            let s = rng.random_range(0.3..3.0);
            let peak = rng.random_range(100.0..60000.0);
            (0..cells)
                .map(|i| {
                    let (a, b) = ((i / j2) as f64 - c1, (i % j2) as f64 - c2);
                    let v = peak * (-(a * a + b * b) / (2.0 * s * s)).exp() + rng.random_range(0.0..20.0);
                    v.min(65535.0) as u16
                })
                .collect()
        }
    }
}

/// A neighbour of `a`: the same map slightly moved and with noise, as
/// neighbouring beams are.
pub fn perturb(rng: &mut impl Rng, a: &[u16]) -> Vec<u16> {
    a.iter()
        .map(|&v| {
            let f = rng.random_range(0.9..1.1);
            ((v as f64) * f + rng.random_range(0.0..5.0)).min(65535.0) as u16
        })
        .collect()
}

pub fn to_f64(a: &[u16]) -> Vec<f64> {
    a.iter().map(|&v| v as f64).collect()
}
