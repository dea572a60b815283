//! The gradient magnitude of two scores, exact in integer arithmetic.

/// Gradient magnitude `floor(sqrt(g0² + g1²))` of two scores, same format
/// (saturating at `u32::MAX`).
///
/// Exact, without a 64-bit integer square root (about 120 instructions on
/// the Cortex-M4): a single-precision estimate (bit-level seed and three
/// Newton steps, all single instructions on the FPU; within `2^-21` of the
/// root), one correction from the exact integer residual `s - m²`, and unit
/// steps that settle `m² <= s < (m+1)²` with integer arithmetic only, so
/// the result does not depend on how `f32` rounds.
pub fn magnitude(g0: u32, g1: u32) -> u32 {
    let s = (g0 as u64 * g0 as u64).saturating_add(g1 as u64 * g1 as u64);
    if s == u64::MAX {
        return u32::MAX;
    }
    let (a, b) = (g0 as f32, g1 as f32);
    let x = a * a + b * b;
    let mut y = f32::from_bits((x.to_bits() >> 1) + 0x1FBB_4F2E);
    for _ in 0..3 {
        y = 0.5 * (y + x / y);
    }
    let mut m = y as u32;
    let sq = |m: u32| m as u64 * m as u64;
    // |s - m²| < 2^45: exact in i64, and in f32 from its two halves.
    let r = s.wrapping_sub(sq(m)) as i64;
    let rf = ((r >> 32) as i32 as f32) * 4294967296.0 + (r as u32) as f32;
    if m > 0 {
        let c = (rf / (2.0 * m as f32)) as i32;
        m = m.saturating_add_signed(c);
    }
    for _ in 0..4 {
        if sq(m) > s {
            m -= 1;
        } else if m < u32::MAX && sq(m + 1) <= s {
            m += 1;
        } else {
            break;
        }
    }
    m
}
