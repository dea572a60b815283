//! The power channel's fixed point against its definition in f64 and
//! exhaustive integer square roots.

use cvm_core::power::{self, POWER_MAX, POWER_OFF};
use cvm_core_tests::{contrast_f64, power_magnitude_ref};
use proptest::prelude::*;

/// Largest map power: 256 cells at full scale.
const P_MAX: u32 = 256 * 65_535;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20_000))]

    /// `floor(2^15 |a - b| / (a + b))` exactly, for any two map powers.
    #[test]
    fn contrast_is_exact(a in 0..=P_MAX, b in 0..=P_MAX) {
        prop_assert_eq!(power::contrast(a, b), contrast_f64(a.into(), b.into()));
        prop_assert_eq!(power::contrast(a, b), power::contrast(b, a));
    }

    /// Close powers (the common case) with small differences.
    #[test]
    fn contrast_of_close_powers(a in 1000..=P_MAX, d in 0u32..2000) {
        let b = (a + d).min(P_MAX);
        prop_assert_eq!(power::contrast(a, b), contrast_f64(a.into(), b.into()));
    }

    #[test]
    fn magnitude_is_the_floor_of_the_root(c0 in 0u16..=32_768, c1 in 0u16..=32_768) {
        prop_assert_eq!(power::magnitude(c0, c1), power_magnitude_ref(c0, c1));
    }
}

#[test]
fn contrast_edges() {
    // Both dark; one dark; equal; the largest powers.
    assert_eq!(power::contrast(0, 0), 0);
    assert_eq!(power::contrast(0, 5), 32_768);
    assert_eq!(power::contrast(P_MAX, 0), 32_768);
    assert_eq!(power::contrast(P_MAX, P_MAX), 0);
    // 3 against 1: |3 - 1| / 4 = 0.5.
    assert_eq!(power::contrast(3, 1), 16_384);
    // 101 against 99: 0.01 -> floor(327.68).
    assert_eq!(power::contrast(101_000, 99_000), 327);
    assert_eq!(
        power::contrast(P_MAX, P_MAX - 1),
        contrast_f64(P_MAX.into(), (P_MAX - 1).into())
    );
    // Every contrast stays within Q15's range; the magnitude's top.
    assert_eq!(power::magnitude(32_768, 32_768), POWER_MAX as u16);
    assert_eq!(power_magnitude_ref(32_768, 32_768), 46_340);
}

/// Thresholds round up to the next Q15 step; above the largest magnitude
/// the channel is off.
#[test]
fn threshold_from_units_rounds_up() {
    assert_eq!(power::threshold_from_units(0.0), 0);
    assert_eq!(power::threshold_from_units(-1.0), 0);
    assert_eq!(power::threshold_from_units(0.5), 16_384);
    // 0.1 * 2^15 = 3276.8.
    assert_eq!(power::threshold_from_units(0.1), 3277);
    assert_eq!(power::threshold_from_units(f64::INFINITY), POWER_OFF);
    assert_eq!(power::threshold_from_units(f64::NAN), POWER_OFF);
    assert_eq!(power::threshold_from_units(1.5), POWER_OFF);
    assert_eq!(power::threshold_from_units(46_340.0 / 32_768.0), 46_340);
    assert!((power::to_units(3277) - 0.100_006_103_515_625).abs() < 1e-15);
}

/// Whole lines of the magnitude's domain against the reference: every
/// exact root `(k, 0)` and `(0, k)`, the near-squares `(1, k)` (where
/// `1 + k²` lies just above `k²`), the diagonal and the top row.
#[test]
fn magnitude_is_exact_on_whole_lines() {
    for k in 0..=32_768u16 {
        assert_eq!(power::magnitude(k, 0), k);
        assert_eq!(power::magnitude(0, k), k);
        assert_eq!(power::magnitude(1, k), power_magnitude_ref(1, k));
        assert_eq!(power::magnitude(k, k), power_magnitude_ref(k, k));
        assert_eq!(power::magnitude(32_768, k), power_magnitude_ref(32_768, k));
    }
}
