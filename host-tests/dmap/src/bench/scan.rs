//! The synthetic scan every implementation is timed on.

use cvm_sim::rng::{gaussian_pair, mix};

/// Seed of the synthetic scan: fixed, so every run times the same maps.
pub const SEED: u64 = 0x5CA7_7E12;

/// A synthetic scan, raster order, `J1 * J2` counts per position.
#[derive(Clone, Debug)]
pub struct SampleScan {
    pub j1: usize,
    pub j2: usize,
    pub rows: usize,
    pub cols: usize,
    pub counts: Vec<u16>,
    pub values: Vec<f64>,
}

impl SampleScan {
    pub fn cells(&self) -> usize {
        self.j1 * self.j2
    }

    pub fn maps(&self) -> usize {
        self.rows * self.cols
    }

    pub(super) fn map(&self, r: usize, c: usize) -> &[f64] {
        let n = self.cells();
        &self.values[(r * self.cols + c) * n..(r * self.cols + c + 1) * n]
    }
}

/// The scan of `rows x cols` positions. Each position's map depends on the
/// seed and the position only, so a smaller scan is the top-left block of a
/// larger one.
///
/// A spot of about one cell's width whose centre moves smoothly with the
/// position, as the deflection of a smooth surface does; one position in
/// about 30 scatters (a wider, dimmer spot, as on a bubble); every cell gets
/// detector noise (Gaussian, clipped at zero counts).
pub fn synthetic_scan(j1: usize, j2: usize, rows: usize, cols: usize, seed: u64) -> SampleScan {
    let n = j1 * j2;
    let mut counts = Vec::with_capacity(rows * cols * n);
    for r in 0..rows {
        for c in 0..cols {
            let key = mix(seed ^ mix(((r as u64) << 32) | c as u64));
            let (rf, cf) = (r as f64, c as f64);
            let cy = (j1 as f64 - 1.0) * (0.5 + 0.2 * (0.11 * cf + 0.07 * rf).sin());
            let cx = (j2 as f64 - 1.0) * (0.5 + 0.2 * (0.09 * cf - 0.05 * rf).cos());
            let scatter = key.is_multiple_of(30);
            let (sigma, peak) = if scatter {
                (2.5, 4_000.0)
            } else {
                (0.9, 30_000.0)
            };
            for i in 0..n {
                let (y, x) = ((i / j2) as f64, (i % j2) as f64);
                let d2 = (y - cy).powi(2) + (x - cx).powi(2);
                let (g, _) = gaussian_pair(mix(key ^ (i as u64 + 1)));
                let v = peak * (-d2 / (2.0 * sigma * sigma)).exp() + 2.0 + 3.0 * g;
                counts.push(v.round().clamp(0.0, 65535.0) as u16);
            }
        }
    }
    let values = counts.iter().map(|&a| a as f64).collect();
    SampleScan {
        j1,
        j2,
        rows,
        cols,
        counts,
        values,
    }
}
