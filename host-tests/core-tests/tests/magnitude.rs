//! The gradient magnitude against the integer square root: exactly
//! `floor(sqrt(g0² + g1²))`, saturating at `u32::MAX`.

use cvm_core::magnitude;
use proptest::prelude::*;

fn reference(g0: u32, g1: u32) -> u32 {
    let s = (g0 as u128 * g0 as u128) + (g1 as u128 * g1 as u128);
    let m = s.isqrt();
    u32::try_from(m).unwrap_or(u32::MAX)
}

#[test]
fn small_values_exhaustively() {
    for g0 in 0..600u32 {
        for g1 in 0..600u32 {
            assert_eq!(magnitude(g0, g1), reference(g0, g1), "{g0} {g1}");
        }
    }
}

#[test]
fn perfect_squares_and_their_neighbours() {
    // Pythagorean triples (3k, 4k, 5k) and roots of every size, where an
    // estimate off by one would show.
    for k in 1..=200_000u32 {
        let (a, b) = (3 * k, 4 * k);
        assert_eq!(magnitude(a, b), 5 * k);
        assert_eq!(magnitude(a, b - 1), reference(a, b - 1));
    }
    for e in 0..32 {
        for d in 0..8u32 {
            let a = (1u32 << e).wrapping_sub(4).wrapping_add(d);
            assert_eq!(magnitude(a, 0), a, "{a}");
            assert_eq!(magnitude(a, 1), reference(a, 1), "{a}");
            assert_eq!(magnitude(a, a), reference(a, a), "{a}");
        }
    }
}

#[test]
fn saturates_at_the_top() {
    assert_eq!(magnitude(u32::MAX, 0), u32::MAX);
    assert_eq!(magnitude(u32::MAX, u32::MAX), u32::MAX);
    for g in [0, 1, 1 << 31, u32::MAX - 1] {
        assert_eq!(magnitude(g, u32::MAX), u32::MAX, "{g}");
    }
    assert_eq!(
        magnitude(u32::MAX - 1, 1 << 16),
        reference(u32::MAX - 1, 1 << 16)
    );
    assert_eq!(
        magnitude(3_037_000_499, 3_037_000_499),
        reference(3_037_000_499, 3_037_000_499)
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20_000))]
    #[test]
    fn any_pair(g0: u32, g1: u32, s0 in 0u32..32, s1 in 0u32..32) {
        let (a, b) = (g0 >> s0, g1 >> s1);
        prop_assert_eq!(magnitude(a, b), reference(a, b));
        // The engine flags a clipped score by the magnitude alone.
        prop_assert!(magnitude(a, b) >= a.max(b));
    }
}
