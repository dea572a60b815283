//! Detector read-out: photo-electrons, shot noise, read noise, ADC.

use rand::Rng;
use rand_distr::{Distribution, Normal, Poisson};

/// Noise and conversion model of the detector chain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Noise {
    /// Photo-electrons the whole beam would produce if it all reached the array.
    pub photons: f64,
    /// Electrons per ADC count.
    pub gain: f64,
    /// Read noise, electrons rms (0 = none).
    pub read_noise: f64,
    /// ADC bit depth (1..=16): counts clip at 2^bits - 1.
    pub bits: u32,
    /// Dark offset added before conversion, in counts.
    pub bias: f64,
    /// Draw Poisson shot noise on the photo-electrons.
    pub shot: bool,
}

impl Noise {
    pub fn full_scale(&self) -> u16 {
        ((1u32 << self.bits) - 1) as u16
    }

    pub fn validate(&self) -> Result<(), String> {
        if !(1..=16).contains(&self.bits) {
            return Err(format!("ADC bit depth must be 1..=16, got {}", self.bits));
        }
        if !(self.photons.is_finite() && self.photons >= 0.0) {
            return Err(format!("photon count must be >= 0, got {}", self.photons));
        }
        if !(self.gain.is_finite() && self.gain > 0.0) {
            return Err(format!("gain must be positive, got {}", self.gain));
        }
        if !(self.read_noise.is_finite() && self.read_noise >= 0.0) {
            return Err(format!("read noise must be >= 0, got {}", self.read_noise));
        }
        if !self.bias.is_finite() {
            return Err("bias must be finite".into());
        }
        Ok(())
    }

    /// Convert a map of power fractions into ADC counts.
    pub fn digitize<R: Rng>(&self, map: &[f64], rng: &mut R, out: &mut [u16]) {
        let fs = f64::from(self.full_scale());
        for (o, &p) in out.iter_mut().zip(map) {
            let lambda = p * self.photons;
            let mut e = if self.shot && lambda > 0.0 {
                match Poisson::new(lambda) {
                    Ok(d) => d.sample(rng),
                    Err(_) => lambda,
                }
            } else {
                lambda
            };
            if self.read_noise > 0.0
                && let Ok(d) = Normal::new(0.0, self.read_noise)
            {
                e += d.sample(rng);
            }
            *o = (self.bias + e / self.gain).round().clamp(0.0, fs) as u16;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn ideal() -> Noise {
        Noise {
            photons: 1000.0,
            gain: 2.0,
            read_noise: 0.0,
            bits: 8,
            bias: 3.0,
            shot: false,
        }
    }

    #[test]
    fn noiseless_conversion_rounds_and_clips() {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(0);
        let mut out = [0u16; 4];
        // 0.1 * 1000 / 2 + 3 = 53; 0.001 * 500 + 3 = 3.5 -> 4; 1.0 -> 503 clips to 255.
        ideal().digitize(&[0.1, 0.001, 1.0, 0.0], &mut rng, &mut out);
        assert_eq!(out, [53, 4, 255, 3]);
    }

    #[test]
    fn shot_noise_has_poisson_variance() {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(9);
        let n = Noise {
            photons: 400.0,
            gain: 1.0,
            read_noise: 0.0,
            bits: 16,
            bias: 0.0,
            shot: true,
        };
        let mut out = [0u16; 1];
        let (mut s, mut s2) = (0.0, 0.0);
        let k = 20_000;
        for _ in 0..k {
            n.digitize(&[0.25], &mut rng, &mut out);
            let v = f64::from(out[0]);
            s += v;
            s2 += v * v;
        }
        let mean = s / k as f64;
        let var = s2 / k as f64 - mean * mean;
        // lambda = 100: mean 100, variance 100 (std error of the variance ~1 %).
        assert!((mean - 100.0).abs() < 0.5, "{mean}");
        assert!((var / 100.0 - 1.0).abs() < 0.05, "{var}");
    }

    #[test]
    fn read_noise_adds_gaussian_spread() {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(5);
        let n = Noise {
            photons: 0.0,
            gain: 1.0,
            read_noise: 10.0,
            bits: 16,
            bias: 1000.0,
            shot: true,
        };
        let mut out = [0u16; 1];
        let (mut s, mut s2) = (0.0, 0.0);
        let k = 20_000;
        for _ in 0..k {
            n.digitize(&[0.0], &mut rng, &mut out);
            let v = f64::from(out[0]);
            s += v;
            s2 += v * v;
        }
        let mean = s / k as f64;
        // Rounding adds 1/12 to the variance.
        let var = s2 / k as f64 - mean * mean;
        assert!((mean - 1000.0).abs() < 0.3);
        assert!((var / (100.0 + 1.0 / 12.0) - 1.0).abs() < 0.05, "{var}");
    }
}
