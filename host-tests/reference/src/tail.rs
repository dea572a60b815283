//! The exponential tail of a set of magnitudes (peaks over a threshold) and
//! the threshold for a target rate of false positions per part, in `f64`
//! from the formulas (docs/method.md, "Thresholds from a target rate"):
//! the yardstick of the integer fit in `cvm_core::calibration::tail`.
//!
//! Over `n` values from `S` parts, with a tail start `u`:
//!
//! - `N_u` values lie above `u`, with mean excess `s` (the maximum
//!   likelihood scale of an exponential excess);
//! - a position of a part is at or above `t >= u` with probability
//!   `(N_u / n) exp(-(t - u) / s)`, so a part of `n / S` positions has
//!   `(N_u / S) exp(-(t - u) / s)` of them there on average;
//! - that equals the target `a` at `t = u + s ln(N_u / (a S))`.

/// The tail above a start.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExpTail {
    /// `u`.
    pub start: f64,
    /// `N_u`: values strictly above `u`.
    pub count: usize,
    /// `s`: their mean excess over `u` (0 without a tail).
    pub scale: f64,
}

/// The nearest-rank `p` quantile of `values` (not empty): the value of
/// 1-based rank `ceil(p n)`, clamped to `1..=n`.
pub fn nearest_rank(values: &[f64], p: f64) -> f64 {
    let mut v = values.to_vec();
    v.sort_unstable_by(f64::total_cmp);
    let n = v.len();
    let rank = ((p * n as f64).ceil() as usize).clamp(1, n);
    v[rank - 1]
}

/// The tail of `values` above `start`.
pub fn exp_tail(values: &[f64], start: f64) -> ExpTail {
    let above: Vec<f64> = values.iter().filter(|&&v| v > start).copied().collect();
    let count = above.len();
    let scale = if count == 0 {
        0.0
    } else {
        above.iter().map(|v| v - start).sum::<f64>() / count as f64
    };
    ExpTail {
        start,
        count,
        scale,
    }
}

impl ExpTail {
    /// The threshold at which `scans` parts' worth of tail expects `rate`
    /// positions per part: `u + s ln(N_u / (rate S))`, not below `u`.
    pub fn threshold(&self, scans: usize, rate: f64) -> f64 {
        if self.count == 0 {
            return self.start;
        }
        let ln = (self.count as f64 / (rate * scans as f64)).ln();
        self.start + self.scale * ln.max(0.0)
    }

    /// Expected positions per part at or above `t >= u`.
    pub fn rate_at(&self, scans: usize, t: f64) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        self.count as f64 / scans as f64 * (-(t - self.start) / self.scale).exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_tail() {
        // Above 10: 12, 14, 19: N_u = 3, excesses 2 4 9, s = 5.
        let t = exp_tail(&[1.0, 5.0, 10.0, 12.0, 14.0, 19.0], 10.0);
        assert_eq!((t.count, t.scale), (3, 5.0));
        // One scan, rate 3 / e^2: ln(3 / (3 / e^2)) = 2, t = 10 + 10.
        let r = 3.0 / (2.0f64).exp();
        assert!((t.threshold(1, r) - 20.0).abs() < 1e-12);
        assert!((t.rate_at(1, 20.0) - r).abs() < 1e-15);
        // Three scans: a third of the rate per part at the same t.
        assert!((t.rate_at(3, 20.0) - r / 3.0).abs() < 1e-15);
        // A target above N_u / S: the tail's start.
        assert_eq!(t.threshold(1, 5.0), 10.0);
        assert_eq!(nearest_rank(&[3.0, 1.0, 2.0, 4.0], 0.5), 2.0);
        assert_eq!(nearest_rank(&[3.0, 1.0, 2.0, 4.0], 0.51), 3.0);
    }
}
