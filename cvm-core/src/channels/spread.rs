//! The spread channel: how much of a beam's light lies outside the spot.
//!
//! A scattering defect (a cloud of inclusions, haze) keeps the spot where
//! it is and sends a share of the beam into a faint halo several cells
//! wide. Normalisation removes the power it costs, the distance between
//! normalised neighbours hardly changes (the spot has not moved or changed
//! shape), and the power channel sees only the small part of the halo that
//! leaves the detector. The share of the map's power outside a small box
//! around the brightest cell does change: on a part without defects it is
//! the noise floor (the box holds the whole spot), a halo puts most of its
//! light there (docs/method.md §8).
//!
//! Per map, with `P` its power (sample sum) and `C` the sum of the samples
//! in the core, the box of `h` cells to each side of the brightest cell
//! (the first in raster order on ties), clipped at the map's edges:
//!
//! `q = floor(2^16 (P - C) / P)`, 0 for a dark map (`P = 0`, flagged
//! [`crate::channels::flags::DARK`] by the scorer as for the other channels).
//!
//! Per position, as the power channel does, the two differences of Eq. 1,
//! `s0 = |q(right) - q(left)|` and `s1 = |q(below) - q(above)|`, a missing
//! neighbour (scan border or gap) replaced by the position itself, and the
//! magnitude `floor(sqrt(s0² + s1²))`. The differences are the plain
//! differences of the two neighbours' `q`, not a contrast: `q` is already
//! a fraction of each map's own power.
//!
//! # Fixed point and bounds
//!
//! `q` is `Q16` (`SPREAD_FRAC` = 16) in a `u16`, exact:
//!
//! - samples are `u16` and a map has at most [`MAX_CELLS`] = 256 cells,
//!   so `P <= 256 * 65535 < 2^24`, and `C <= P`, both in `u32`;
//! - the brightest cell is in the core, and it is positive when `P > 0`,
//!   so `P - C <= P - max < P` and `2^16 (P - C) / P < 2^16`:
//!   `q <= 65535`;
//! - the quotient is a long division in base `2^8`, two steps: the
//!   remainder is below `P` before each shift, so below `2^8 P < 2^32`
//!   after it; each step's quotient digit is below `2^8`. Two hardware
//!   divisions (`UDIV`), no 64-bit arithmetic.
//!
//! The differences `s0`, `s1` are at most 65535 (`u16`). The magnitude is
//! at most `floor(65535 sqrt 2) = 92680` ([`SPREAD_MAX`]), so it takes a
//! `u32`. Each square is below `2^32`; when their sum is too (both
//! differences below 46 341, every pair of neighbours on a part without
//! defects, whose `q` are a few hundred) the root is a 32-bit Newton
//! iteration as the power channel's, otherwise the scorer's exact 64-bit
//! magnitude.
//!
//! The half-width is the scorer's ([`crate::Scorer::with_spread_half`],
//! default [`CORE_HALF`]); the engine measures `q` only while its spread
//! channel is on ([`crate::Engine::set_spread_threshold`]).

use super::magnitude::magnitude as magnitude64;
use super::power::{fixed_threshold, isqrt};
use crate::config::MAX_CELLS;

/// Fraction bits of the spread channel's values.
pub const SPREAD_FRAC: u32 = 16;
/// Largest spread magnitude: `floor(sqrt(2) * 65535)`.
pub const SPREAD_MAX: u32 = 92680;
/// The spread threshold of a channel that is off: nothing is measured and
/// nothing fires.
pub const SPREAD_OFF: u32 = u32::MAX;
/// The core's default half-width `h`: a 5x5 box, which holds a spot of
/// half a cell rms (its edge is 4 rms from the spot's centre or more).
pub const CORE_HALF: u8 = 2;

/// `q` of a `j1 x j2` map stored row-major (cell `(i1, i2)` at
/// `i1 j2 + i2`) with power `power` (its sample sum) and core half-width
/// `half`. 0 for a dark map and for a frame whose length is not `j1 j2`
/// (the scorer rejects those before).
pub fn outside_core(frame: &[u16], j1: usize, j2: usize, half: usize, power: u32) -> u16 {
    let top = frame.iter().copied().max().unwrap_or(0);
    outside_core_of_peak(frame, j1, j2, half, power, top)
}

/// [`outside_core`] of a map whose largest sample is `top`, which the
/// scorer's sum pass finds on the way (two instructions per two samples,
/// `scorer::sum`), so that only the search for the first cell holding it
/// is left here: it stops at the spot, on average half-way through the
/// map. A `top` that no cell holds (not the scorer's) centres the core on
/// the first cell.
pub fn outside_core_of_peak(
    frame: &[u16],
    j1: usize,
    j2: usize,
    half: usize,
    power: u32,
    top: u16,
) -> u16 {
    if power == 0 || j1 == 0 || j2 == 0 || frame.len() != j1 * j2 || frame.len() > MAX_CELLS {
        return 0;
    }
    let peak = first_of(frame, top);
    let (p1, p2) = (peak / j2, peak % j2);
    let (r0, r1) = (
        p1.saturating_sub(half),
        (p1 + half).min(j1.saturating_sub(1)),
    );
    let (c0, c1) = (
        p2.saturating_sub(half),
        (p2 + half).min(j2.saturating_sub(1)),
    );
    let mut core = 0u32;
    for r in r0..=r1 {
        let start = r * j2;
        if let Some(row) = frame.get(start + c0..=start + c1) {
            for &a in row {
                core += a as u32;
            }
        }
    }
    share(power.saturating_sub(core), power)
}

/// Index of the first cell holding `top`, the map's largest sample (0 if
/// none does). Two cells a word: a lane of [`at_least2`] is non-zero
/// exactly where a sample reaches `top`, which for the largest sample
/// means equals it.
fn first_of(frame: &[u16], top: u16) -> usize {
    // SAFETY: every bit pattern is a valid `u32`; `align_to` only splits
    // off the unaligned ends (the scorer's copy of a frame has none).
    let (head, words, _) = unsafe { frame.align_to::<u32>() };
    let by_cell = |from: usize| {
        frame
            .iter()
            .skip(from)
            .position(|&a| a == top)
            .map_or(0, |i| from + i)
    };
    if !head.is_empty() {
        return by_cell(0);
    }
    let top2 = top as u32 * 0x0001_0001;
    for (i, &w) in words.iter().enumerate() {
        let m = at_least2(w, top2);
        if m != 0 {
            // The first cell of a word is its low half (little-endian).
            return 2 * i + (m & 0xFFFF == 0) as usize;
        }
    }
    by_cell(2 * words.len())
}

/// Each 16-bit half of `w` that is at least the matching half of `t`
/// as all ones, the others 0: `USUB16` sets a half's GE flags when the
/// subtraction does not borrow, `SEL` picks ones there. Two
/// instructions for two samples.
#[cfg(target_arch = "arm")]
#[inline(always)]
fn at_least2(w: u32, t: u32) -> u32 {
    let r: u32;
    // SAFETY: register operations only (`USUB16` and `SEL` are part of
    // the Cortex-M4/M7 DSP extension of thumbv7em); `d` is written before
    // the inputs are read again, so it gets a register of its own.
    unsafe {
        core::arch::asm!(
            "usub16 {d}, {w}, {t}",
            "sel {r}, {ones}, {zero}",
            d = out(reg) _,
            r = lateout(reg) r,
            w = in(reg) w,
            t = in(reg) t,
            ones = in(reg) u32::MAX,
            zero = in(reg) 0u32,
            options(pure, nomem, nostack)
        );
    }
    r
}

/// Each 16-bit half of `w` that is at least the matching half of `t`
/// as all ones, the others 0.
#[cfg(not(target_arch = "arm"))]
#[inline(always)]
fn at_least2(w: u32, t: u32) -> u32 {
    let lo = if w & 0xFFFF >= t & 0xFFFF { 0xFFFF } else { 0 };
    let hi = if w >> 16 >= t >> 16 { 0xFFFF_0000 } else { 0 };
    lo | hi
}

/// `floor(2^16 o / p)` for `o < p < 2^24`, by long division in base `2^8`
/// (module doc); 0 when `p = 0`, 65535 when `o >= p` (not reached by
/// [`outside_core`]).
pub fn share(o: u32, p: u32) -> u16 {
    if p == 0 {
        return 0;
    }
    if o >= p || p >= 1 << 24 {
        return u16::MAX;
    }
    let mut r = o;
    let mut q = 0u32;
    for _ in 0..2 {
        // r < p < 2^24: r << 8 < 2^32.
        r <<= 8;
        q = (q << 8) | (r / p);
        r %= p;
    }
    q.min(u16::MAX as u32) as u16
}

/// `floor(sqrt(s0² + s1²))` of two `Q16` differences, exact, at most
/// [`SPREAD_MAX`].
pub fn magnitude(s0: u16, s1: u16) -> u32 {
    let (a, b) = (s0 as u32, s1 as u32);
    // Each square is below 2^32; their sum may not be.
    match (a * a).checked_add(b * b) {
        Some(s) => isqrt(s),
        None => magnitude64(a, b),
    }
}

/// The smallest `Q16` threshold at or above `t` (a share of the power; 0
/// for `t <= 0`, [`SPREAD_OFF`] for `t` above every magnitude or NaN).
pub fn threshold_from_units(t: f64) -> u32 {
    fixed_threshold(t, SPREAD_FRAC, SPREAD_MAX, SPREAD_OFF)
}

/// A `Q16` spread value as a share of the power.
pub fn to_units(s: u32) -> f64 {
    s as f64 / (1u32 << SPREAD_FRAC) as f64
}
