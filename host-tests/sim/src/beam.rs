//! Sampling a collimated Gaussian beam by rays.

use rand::{Rng, RngExt};

/// Beam radius beyond which rays are not sampled, in units of the waist:
/// exp(-2 * 2^2) = 3.4e-4 of the power lies outside; the kept rays are
/// renormalised to carry the whole beam power.
const TRUNCATION: f64 = 2.0;

/// Cells per side of the sampling grid for about `rays` rays inside the
/// truncation disc (the disc holds pi/4 of the square's cells).
pub fn grid_side(rays: usize) -> usize {
    ((4.0 * rays as f64 / std::f64::consts::PI).sqrt().ceil() as usize).max(1)
}

/// Ray offsets `(dx, dy, weight)` of a Gaussian beam of 1/e^2 intensity
/// radius `waist` (mm): a stratified grid with one jittered sample per cell
/// (jitter drawn from `rng`), weighted by the intensity there; weights sum to 1.
pub fn sample<R: Rng>(waist: f64, rays: usize, rng: &mut R, out: &mut Vec<(f64, f64, f64)>) {
    out.clear();
    let k = grid_side(rays);
    let r_max = TRUNCATION * waist;
    let cell = 2.0 * r_max / k as f64;
    let mut total = 0.0;
    for a in 0..k {
        for b in 0..k {
            let x = -r_max + (a as f64 + rng.random::<f64>()) * cell;
            let y = -r_max + (b as f64 + rng.random::<f64>()) * cell;
            let r2 = x * x + y * y;
            if r2 <= r_max * r_max {
                let w = (-2.0 * r2 / (waist * waist)).exp();
                total += w;
                out.push((x, y, w));
            }
        }
    }
    for s in out.iter_mut() {
        s.2 /= total;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn samples_have_gaussian_second_moment() {
        // Intensity exp(-2 r^2 / w^2) has per-axis variance w^2 / 4 (truncation
        // at 2w lowers it by under 1 %).
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(3);
        let mut v = Vec::new();
        let w = 0.5;
        sample(w, 4000, &mut rng, &mut v);
        let sum: f64 = v.iter().map(|s| s.2).sum();
        assert!((sum - 1.0).abs() < 1e-12);
        let var_x: f64 = v.iter().map(|s| s.2 * s.0 * s.0).sum();
        assert!((var_x / (w * w / 4.0) - 1.0).abs() < 0.02, "{var_x}");
        assert!(v.len() > 3500 && v.len() < 4500);
    }
}
