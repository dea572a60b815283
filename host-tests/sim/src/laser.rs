//! Laser power: per-beam fluctuation and slow drift over a scan.
//!
//! A real source does not deliver the same power to every beam position:
//! its output fluctuates from one exposure to the next (relative intensity
//! noise integrated over a beam's dwell, plus pointing jitter on an
//! aperture), and drifts slowly over a scan (warm-up, temperature). Both
//! scale the whole deflection map of a position before the detector sees
//! it, so shot noise follows the delivered power. Normalisation (Eq. 5 of
//! docs/method.md) removes both; raw maps keep them.
//!
//! The factors come from hashes of the scan seed and the position, apart
//! from the generators that trace the rays and draw the detector noise:
//! turning laser noise off leaves every other random draw of a scan as it
//! was.

use crate::rng::{gaussian_pair, mix};

/// Relative power of the beam at each position of a scan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Laser {
    /// Per-beam fluctuation, relative rms (0.01 = 1 %), independent from
    /// beam to beam.
    pub rms: f64,
    /// Slow drift over the scan, relative peak amplitude (0.02 = up to
    /// +-2 % of the nominal power); its shape is [`drift_shape`].
    pub drift: f64,
}

/// Separates the laser's hashes from every other use of the scan seed.
const LASER_KEY: u64 = 0x4C41_5345_525F_5057; // "LASER_PW"

impl Laser {
    /// No fluctuation, no drift: every beam delivers the nominal power.
    pub const NONE: Laser = Laser {
        rms: 0.0,
        drift: 0.0,
    };

    pub fn validate(&self) -> Result<(), String> {
        if !(self.rms.is_finite() && (0.0..0.2).contains(&self.rms)) {
            return Err(format!(
                "laser power fluctuation must be 0 <= rms < 0.2 (relative), got {}",
                self.rms
            ));
        }
        if !(self.drift.is_finite() && (0.0..0.5).contains(&self.drift)) {
            return Err(format!(
                "laser drift must be 0 <= amplitude < 0.5 (relative), got {}",
                self.drift
            ));
        }
        Ok(())
    }

    /// Power factor (nominal 1) of position (row, col) of a `rows x cols`
    /// raster scanned row by row, left to right. Never below 0.
    pub fn factor(&self, seed: u64, rows: usize, cols: usize, row: usize, col: usize) -> f64 {
        let n = (rows * cols).max(2) as f64;
        let t = (row * cols + col) as f64 / (n - 1.0);
        let fluct = if self.rms > 0.0 {
            let key = ((row as u64) << 32) | (col as u64 & 0xFFFF_FFFF);
            gaussian_pair(mix(seed ^ LASER_KEY ^ mix(key))).0 * self.rms
        } else {
            0.0
        };
        let drift = if self.drift > 0.0 {
            self.drift * drift_shape(seed, t)
        } else {
            0.0
        };
        (1.0 + drift + fluct).max(0.0)
    }
}

/// Shape of the drift over the scan, `t` from 0 (first beam) to 1 (last):
/// `0.7 cos(pi t + a) + 0.3 cos(6 pi t + b)`, phases `a`, `b` drawn from the
/// seed. A slow swing of up to half a period over the scan (warm-up,
/// ambient temperature) with a faster ripple of three periods (a
/// thermo-electric controller hunting); |shape| <= 1.
pub fn drift_shape(seed: u64, t: f64) -> f64 {
    let h = mix(seed ^ mix(LASER_KEY));
    let a = (h >> 32) as f64 / 4_294_967_296.0 * std::f64::consts::TAU;
    let b = (h & 0xFFFF_FFFF) as f64 / 4_294_967_296.0 * std::f64::consts::TAU;
    let pi = std::f64::consts::PI;
    0.7 * (pi * t + a).cos() + 0.3 * (6.0 * pi * t + b).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn none_is_exactly_one() {
        for (r, c) in [(0, 0), (3, 7), (9, 9)] {
            assert_eq!(Laser::NONE.factor(5, 10, 10, r, c), 1.0);
        }
    }

    #[test]
    fn fluctuation_has_the_rms_asked_for() {
        let l = Laser {
            rms: 0.01,
            drift: 0.0,
        };
        let (rows, cols) = (200, 200);
        let v: Vec<f64> = (0..rows)
            .flat_map(|r| (0..cols).map(move |c| (r, c)))
            .map(|(r, c)| l.factor(3, rows, cols, r, c) - 1.0)
            .collect();
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let rms = (v.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
        assert!(mean.abs() < 2e-4, "{mean}");
        assert!((rms / 0.01 - 1.0).abs() < 0.02, "{rms}");
        // Neighbours are independent.
        let lag1: f64 = v.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / (n - 1.0);
        assert!(lag1.abs() < 0.02 * 1e-4, "{lag1}");
    }

    #[test]
    fn drift_is_slow_bounded_and_seeded() {
        let l = Laser {
            rms: 0.0,
            drift: 0.02,
        };
        let (rows, cols) = (100, 100);
        let f: Vec<f64> = (0..rows * cols)
            .map(|i| l.factor(1, rows, cols, i / cols, i % cols))
            .collect();
        assert!(f.iter().all(|&x| (x - 1.0).abs() <= 0.02 + 1e-12));
        // From one beam to the next it changes by at most
        // 0.02 * (0.7 pi + 0.3 * 6 pi) / (N - 1).
        let step = 0.02 * (0.7 + 1.8) * std::f64::consts::PI / (rows * cols - 1) as f64;
        assert!(f.windows(2).all(|w| (w[1] - w[0]).abs() <= step * 1.0001));
        let swing =
            f.iter().cloned().fold(f64::MIN, f64::max) - f.iter().cloned().fold(f64::MAX, f64::min);
        assert!(swing > 0.01, "{swing}");
        assert_ne!(drift_shape(1, 0.3), drift_shape(2, 0.3));
    }

    #[test]
    fn limits_are_checked() {
        assert!(
            Laser {
                rms: -0.1,
                drift: 0.0
            }
            .validate()
            .is_err()
        );
        assert!(
            Laser {
                rms: 0.0,
                drift: f64::NAN
            }
            .validate()
            .is_err()
        );
        assert!(
            Laser {
                rms: 0.01,
                drift: 0.02
            }
            .validate()
            .is_ok()
        );
    }
}
