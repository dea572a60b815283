//! The fixed-point formats of a configuration and why, at those formats,
//! no step of the embedding overflows.
//!
//! # Fixed-point formats
//!
//! | quantity | type | format |
//! |---|---|---|
//! | raw sample `a` | `u16` | counts |
//! | folded count `v = a[l] ± a[J2-1-l]` | `i32` | counts, exact, `\|v\| <= 2 * 65535` |
//! | input `y` | `i32` | `Q(f)`: normalised `y = round((v << k) * m / 2^32) ≈ v 2^f / S` (`S' = S << k` in `[2^30, 2^31)`, `m = floor(2^(32+f) / S')`, error below 1), raw `y = v 2^f`, exact (`f >= 0` always); `f = 28` normalised, `11` raw unless a bound below fails |
//! | factor blocks `R'` of axis `i` | `i32` | `Q(p_i)`, entries below `2^31 - 1` in magnitude, `p_i <= 62` |
//! | row pass `T = y R2'ᵀ` | `i32` | `Q(f + p2 - 32)`: one `round(r y / 2^32)` per term (`SMMLAR`) |
//! | `T` folded along axis 1 | `i32` | same, exact sums and differences |
//! | embedding `E = R1' T` | `i32` | `Q(e)`, `e = f + p1 + p2 - 64`, one rounding per term, `‖E‖_F < 2^30` |
//! | squared distance | `i64` | `Q(2e)` |
//! | score (gradient component, magnitude) | `u32` | `Q(q)`: real value = `s / 2^q` |
//!
//! # Why nothing overflows
//!
//! [`Scorer::new`](crate::scorer::Scorer::new) takes the finest `f` and,
//! for it, the finest `p1` for which every bound below holds (`p2` is the
//! finest that fits `i32`), and refuses the configuration
//! ([`ConfigError::Range`]) if none does. Let `ε = 8 / 2 = 4` bound the
//! rounding error of a sum of at most 8 rounded terms, `r2max`, `r1max` the
//! largest coefficient magnitudes and `‖R'q‖_F` the Frobenius norms of the
//! block-diagonal integer factors (at least their spectral norms).
//!
//! * Conversion: normalised `|v| <= S`, so `|v << k| <= S' < 2^31` and
//!   `m <= 2^(2+f) <= 2^30`; raw `|v << (f+2)| < 2^17 2^13 = 2^30`. A product
//!   of two `i32` always fits the 64-bit product of `SMMULR`/`SMMLAR`.
//! * Each sample lies in one entry of each block, so over one block of one
//!   row `Σ|y| <= Yrow = 2^f + 8` (raw: `J2 65535 2^f + 8`), and over one
//!   block of all rows `Σ|y| <= Yall = 2^f + 128` (raw: `N 65535 2^f + 128`).
//! * Row pass: every partial sum is at most `Yrow r2max / 2^32 + ε < 2^31`.
//! * Fold along axis 1: over one block, `Σ|T folded| <= Σ_i |T_ik| <=
//!   Tcol = Yall r2max / 2^32 + 16 ε < 2^31`, which bounds every folded value.
//! * Column pass: every partial sum is at most `Tcol r1max / 2^32 + ε < 2^31`.
//! * `‖F1 y‖_F <= 2 2^f + 32` (raw `2 √N 65535 2^f + 32`; folding both axes
//!   doubles the Euclidean norm, and `‖x‖_F <= ‖x‖_1 = 1`), so
//!   `‖E‖_F <= ‖R1'q‖_F ‖R2'q‖_F ‖F1 y‖_F / 2^64 + ‖R1'q‖_F √(2N) ε / 2^32 +
//!   √N ε < 2^30`: every entry and every difference of two entries fits
//!   `i32`, and the squared distance `‖E1 - E2‖²_F < 2^62` fits `i64`.
//! * Square kernels: the same conversion of counts folded on both axes
//!   (`|v| <= S`, raw `|v| < 2^18`, so raw `f <= 11`), then one dense
//!   factor per folded block, `N` words per map in `Q(f + p - 32)`: their
//!   formats and bounds are in the module `square`.
//!
//! The score format `q` is the largest with `D_max * 2^q <= 2^31 - 1`, where
//! `D_max = N * Σ_b w(b)` bounds the distance of normalised maps (every LCD
//! value lies in `[0, 1]`) and `N * Σ_b w(b) * (N * 65535)²` bounds it for raw
//! maps, so a score never exceeds `u32` and a magnitude of two scores never
//! exceeds `u32` either.

use crate::config::{Config, ConfigError, MAX_J};
use crate::scorer::embed::{MAX_H, RealFactor, TRI, precision, real_factor};
use crate::tables::{axis_kernel, pow2, sqrt};

/// Finest input format of normalised maps with paper kernels: the per-map
/// multiplier `2^(32+f) / S'` (`S' >= 2^30`) must stay below `2^31`.
const MAX_FRAC_NORM: i32 = 28;
/// Finest input format of raw maps with paper kernels: `v << (f + 2)` of a
/// folded count `|v| < 2^17` stays below `2^31`.
const MAX_FRAC_RAW: i32 = 11;
const I31: f64 = 2147483647.0;
const LIMIT_E: f64 = 1073741823.0; // 2^30 - 1

/// Formats of the folded embedding: the finest input format `f` and the
/// factor precisions `p1`, `p2` for which every bound of the module docs
/// holds.
pub const fn paper_formats(
    cfg: &Config,
    rf1: &RealFactor,
    rf2: &RealFactor,
) -> Result<(i32, u32, u32, Bounds), ConfigError> {
    let (j1, j2) = (rf1.h + rf1.g, rf2.h + rf2.g);
    let n = (j1 * j2) as f64;
    let (Some(p1max), Some(p2)) = (precision(rf1), precision(rf2)) else {
        return Err(ConfigError::Range);
    };
    let fro1 = frobenius(rf1);
    let fro2 = frobenius(rf2);
    // Coefficient magnitudes and norms, with the rounding of every entry
    // (at most 2 * TRI entries of 1/2 each).
    let slack = sqrt(2.0 * TRI as f64) * 0.5;
    let r2max = rf2.max * pow2(p2 as i32) + 0.5;
    let r2fro = fro2 * pow2(p2 as i32) + slack;
    let mut f = if cfg.normalise {
        MAX_FRAC_NORM
    } else {
        MAX_FRAC_RAW
    };
    // Not below 0, so that raw counts convert exactly, by a left shift
    // (every configuration finds a format at f >= 8 raw, far more
    // normalised: `every_configuration_has_formats` in the tests).
    while f >= 0 {
        let scale = pow2(f);
        // Bounds on Σ|y| over one block of a row, on Σ|y| over one block of
        // all rows, and on ‖F1 y‖_F, for the converted map y folded along
        // axis 2 (F1 y: also folded along axis 1).
        let (yrow, yhalf, yfro) = if cfg.normalise {
            (scale + 8.0, scale + 128.0, 2.0 * scale + 32.0)
        } else {
            let c = 65535.0 * scale;
            (j2 as f64 * c + 8.0, n * c + 128.0, 2.0 * sqrt(n) * c + 32.0)
        };
        // Every term of a pass is rounded on its own: a sum of at most
        // MAX_H terms is within MAX_H / 2 of the exact one.
        let err = MAX_H as f64 * 0.5;
        let row = yrow * r2max * pow2(-32) + err;
        // Σ over a column block of |T| after the fold along axis 1.
        let tcol = yhalf * r2max * pow2(-32) + MAX_J as f64 * err;
        let row_ok = row < I31 && tcol < I31;
        let mut p1 = p1max as i32;
        while row_ok && p1 >= 0 {
            let r1max = rf1.max * pow2(p1) + 0.5;
            let r1fro = fro1 * pow2(p1) + slack;
            let e = r1fro * r2fro * yfro * pow2(-64)
                + r1fro * sqrt(2.0 * n) * err * pow2(-32)
                + sqrt(n) * err;
            let column = tcol * r1max * pow2(-32) + err;
            if column < I31 && e < LIMIT_E {
                let bounds = Bounds {
                    row,
                    fold: tcol,
                    column,
                    embedding: e,
                };
                return Ok((f, p1 as u32, p2, bounds));
            }
            p1 -= 1;
        }
        f -= 1;
    }
    Err(ConfigError::Range)
}

/// The fixed-point formats of a configuration
/// ([`Scorer::formats`](crate::scorer::Scorer::formats); the table in the
/// module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Formats {
    /// `f`: the input `y` is in `Q(f)`.
    pub input: i32,
    /// `p1`, `p2`: the factor blocks of axis 1 and 2 are in `Q(p)` (paper
    /// kernels; square kernels: their one factor format twice).
    pub factors: [u32; 2],
    /// `e`: the embedding is in `Q(e)`.
    pub embedding: i32,
    /// `q`: scores are in `Q(q)`.
    pub score: i32,
    /// The proof's bounds at these formats (paper kernels).
    pub bounds: Option<Bounds>,
}

/// The bounds of the paper kernels' overflow proof at the chosen formats
/// (module docs, "Why nothing overflows"), each below its limit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// Every partial sum of the row pass: `Yrow r2max / 2^32 + ε < 2^31`.
    pub row: f64,
    /// Every value of `T` folded along axis 1: `Tcol < 2^31`.
    pub fold: f64,
    /// Every partial sum of the column pass: `Tcol r1max / 2^32 + ε < 2^31`.
    pub column: f64,
    /// `‖E‖_F < 2^30`.
    pub embedding: f64,
}

/// The real folded factors of both axes' paper kernels.
pub const fn paper_factors(
    j1: usize,
    w1: &[f64; MAX_J],
    n1: usize,
    j2: usize,
    w2: &[f64; MAX_J],
    n2: usize,
) -> (RealFactor, RealFactor) {
    (
        real_factor(&axis_kernel(j1, w1, n1), j1),
        real_factor(&axis_kernel(j2, w2, n2), j2),
    )
}

/// Frobenius norm of both blocks of a real factor.
const fn frobenius(r: &RealFactor) -> f64 {
    let fe = crate::tables::frobenius(&r.even, r.h);
    let fo = crate::tables::frobenius(&r.odd, r.g);
    sqrt(fe * fe + fo * fo)
}

/// The score format `q` for a configuration whose embedding is in
/// `Q(e_frac)` and whose weights sum to `wsum`: the largest with
/// `D_max 2^q <= 2^31 - 1` (module docs). Inlined into its one caller,
/// [`Scorer::new`](crate::scorer::Scorer::new).
#[inline(always)]
pub const fn score_format(cfg: &Config, wsum: f64, e_frac: i32) -> Result<i32, ConfigError> {
    let n = (cfg.geometry.j1 as usize * cfg.geometry.j2 as usize) as f64;
    // Distance bound in real units, then the largest score format for it.
    let dmax = if cfg.normalise {
        n * wsum
    } else {
        let s = n * 65535.0;
        n * wsum * s * s
    };
    let mut q: i32 = 62;
    while q > -120 && dmax * pow2(q) > I31 {
        q -= 1;
    }
    // A distance in `Q(2 e_frac)` becomes a score by a rounding right
    // shift of `2 e_frac - q` bits: 15 to 34 over every configuration
    // (core-tests/tests/formats.rs builds them all, separable weights
    // included), so one that would need another kind of conversion is
    // refused rather than supported untested.
    let shift = 2 * e_frac - q;
    if shift < 1 || shift > 63 {
        return Err(ConfigError::Range);
    }
    Ok(q)
}
