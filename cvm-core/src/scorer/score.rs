//! Distances of prepared maps as integer scores in `Q(q)`, and scores in
//! the real units of the f64 distance.

use crate::scorer::setup::Scorer;
use crate::scorer::words::squared_difference;
use crate::tables::pow2;

impl Scorer {
    /// Integer scores are real distances times `2^q`.
    pub const fn score_frac_bits(&self) -> i32 {
        self.q
    }

    /// Real value of an integer score, in the units of the f64 distance.
    pub fn score_to_units(&self, s: u32) -> f64 {
        s as f64 * pow2(-self.q)
    }

    /// The smallest integer score at or above `t` real units (saturating).
    pub fn threshold_from_units(&self, t: f64) -> u32 {
        if t.is_nan() {
            return u32::MAX;
        }
        let v = t * pow2(self.q);
        if v <= 0.0 {
            0
        } else if v >= u32::MAX as f64 {
            u32::MAX
        } else {
            let fl = v as u32;
            if (fl as f64) < v { fl + 1 } else { fl }
        }
    }

    /// Score of the distance between two prepared maps, `Q(q)`, saturating.
    pub fn distance(&self, a: &[i32], b: &[i32]) -> u32 {
        let n = self.state_words();
        let (Some(a), Some(b)) = (a.get(..n), b.get(..n)) else {
            return u32::MAX;
        };
        // Both kernel sets store an embedding whose squared Euclidean
        // distance is the CVM distance.
        self.to_score(squared_difference(a, b))
    }

    /// `Q(2e)` squared distance to a `Q(q)` score, rounded, saturating.
    pub(super) fn to_score(&self, acc: u64) -> u32 {
        // Squared distances are in Q(2 e_frac); `1 <= s <= 63` (see
        // `Scorer::new`), and `acc >> s` plus the rounding bit cannot wrap.
        let s = ((2 * self.e_frac - self.q) as u32).clamp(1, 63);
        let v = (acc >> s) + ((acc >> (s - 1)) & 1);
        // Below 2^31 for every pair of maps (`q` is chosen so), saturating
        // all the same.
        u32::try_from(v).unwrap_or(u32::MAX)
    }
}
