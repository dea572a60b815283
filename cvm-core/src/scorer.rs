//! The fixed-point scorer: normalise a raw map, embed it once, and score a
//! pair of embedded maps in `O(J1*J2)`.
//!
//! # Fixed-point formats
//!
//! | quantity | type | format |
//! |---|---|---|
//! | raw sample `a` | `u16` | counts |
//! | input map `x` | `i32` | `Q(f)`: normalised `x = round(ã * 2^f)`, raw `x = round(a * 2^f)`; `f` per configuration (at most 24; 22 for the paper's default at 15x15) |
//! | factor `R_i` | `i32` | `Q(p_i)`, entries below 2^30, `p_i <= 40` per axis |
//! | row pass `T = x R2ᵀ` | `i32` | `Q(f)` (i64 accumulator, rounded) |
//! | embedding `E = R1 T` | `i32` | `Q(f - s)` (i64 accumulator, rounded), `‖E‖_F < 2^30`, `s >= 0` per configuration |
//! | squared distance | `i64` | `Q(2(f - s))` (square kernels: `s = 0`) |
//! | score (gradient component, magnitude) | `u32` | `Q(q)`: real value = `s / 2^q` |
//!
//! # Why nothing overflows
//!
//! [`Scorer::new`] picks the largest `f` (at most 24) for which these bounds
//! hold and refuses the configuration if none does. With `X` the largest
//! possible `Σ x` (`2^f + N/2` normalised, bounded by `2^f + N`, `N * 65535 * 2^f` raw) and `R̂` the
//! dequantised factors:
//!
//! * `|x| <= 2^f` (normalised) or `65535 * 2^f` (raw), below 2^31;
//! * row pass accumulator: `|Σ x R2q| <= X * 2^30 < 2^62`; after rounding,
//!   `|T| <= X max|R̂2| + 1/2 < 2^31`;
//! * column pass accumulator: `|Σ R1q T| <= 2^30 Σ_l |T_lk| <= 2^30 (X max|R̂2| + J1) < 2^62`;
//! * `‖E‖_F <= (‖R̂1‖_F ‖R̂2‖_F ‖x‖_F + √N ‖R̂1‖_∞/2) / 2^s + √N/2 < 2^30`, so every
//!   entry and every difference of two entries fits `i32`, and the squared
//!   distance `‖E1 - E2‖²_F < 2^62` fits `i64`;
//! * square kernels: `|SAT| <= 2X < 2^31` and `(K+1) N (2X)² < 2^63` (`u64` accumulator).
//!
//! The score format `q` is the largest with `D_max * 2^q <= 2^31 - 1`, where
//! `D_max = N * Σ_b w(b)` bounds the distance of normalised maps (every LCD
//! value lies in `[0, 1]`) and `N * Σ_b w(b) * (N * 65535)²` bounds it for raw
//! maps, so a score never exceeds `u32` and a magnitude of two scores never
//! exceeds `u32` either.

use crate::config::{Config, ConfigError, Geometry, Kernels, MAX_J};
use crate::flags;
use crate::tables::{
    axis_kernel, axis_weights, cholesky_psd, norms, pow2, quantise, sqrt, weight_sum,
};

/// Why a frame could not be scored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// The frame or the state buffer does not hold `J1 * J2` values.
    Length,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Paper,
    Square { kmax: u8 },
}

/// Tables and fixed-point formats for one configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct Scorer {
    config: Config,
    kind: Kind,
    /// Input format `Q(f)`.
    frac: i32,
    r1: [[i32; MAX_J]; MAX_J],
    /// `R2` transposed: `r2t[l][k] = R2[k][l]`, zero outside `J2 x J2`.
    r2t: [[i32; MAX_J]; MAX_J],
    p1: u32,
    p2: u32,
    /// Extra right shift of the embedding: `E` is in `Q(f - e_shift)`.
    e_shift: u32,
    /// Score format `Q(q)`.
    q: i32,
}

/// Finest input format tried; `2^(32+f)` must fit the reciprocal's `u64`.
const MAX_FRAC: i32 = 24;
const I31: f64 = 2147483647.0;
const LIMIT_E: f64 = 1073741823.0; // 2^30 - 1
const LIMIT_ACC: f64 = (1u64 << 62) as f64;
/// For the `u64` accumulator of square kernels.
const LIMIT_SQUARE: f64 = (1u64 << 63) as f64;

impl Scorer {
    /// Builds the tables for `cfg`. Usable in `const` context, so a firmware
    /// configuration that cannot be scored fails to compile.
    pub const fn new(cfg: &Config) -> Result<Scorer, ConfigError> {
        let g = cfg.geometry;
        if g.j1 == 0 || g.j2 == 0 || g.j1 as usize > MAX_J || g.j2 as usize > MAX_J {
            return Err(ConfigError::Geometry);
        }
        let (j1, j2) = (g.j1 as usize, g.j2 as usize);
        let n = (j1 * j2) as f64;

        let (kind, bmax) = match cfg.kernels {
            Kernels::Paper { bmax } => (Kind::Paper, bmax as usize),
            Kernels::Square { kmax } => {
                if kmax as usize >= MAX_J {
                    return Err(ConfigError::KernelSize);
                }
                (Kind::Square { kmax }, 0)
            }
        };
        let (w1, n1) = match axis_weights(&cfg.weights, 0, j1, bmax) {
            Ok(v) => v,
            Err(e) => return Err(e),
        };
        let (w2, n2) = match axis_weights(&cfg.weights, 1, j2, bmax) {
            Ok(v) => v,
            Err(e) => return Err(e),
        };
        let wsum = weight_sum(&cfg.kernels, &w1, n1, &w2, n2);
        if wsum.is_nan() || wsum <= 0.0 {
            return Err(ConfigError::Weights);
        }

        let (r1, p1, r2, p2, rb1, rb2) = match kind {
            Kind::Paper => {
                let (r1, p1) = quantise(&cholesky_psd(&axis_kernel(j1, &w1, n1), j1), j1);
                let (r2, p2) = quantise(&cholesky_psd(&axis_kernel(j2, &w2, n2), j2), j2);
                let b1 = norms(&dequantise(&r1, p1), j1);
                let b2 = norms(&dequantise(&r2, p2), j2);
                (r1, p1, r2, p2, b1, b2)
            }
            Kind::Square { .. } => (
                [[0; MAX_J]; MAX_J],
                0,
                [[0; MAX_J]; MAX_J],
                0,
                (0.0, 0.0, 0.0),
                (0.0, 0.0, 0.0),
            ),
        };

        // Largest input format whose accumulators provably stay in range.
        let mut f: i32 = MAX_FRAC;
        loop {
            if f < -16 {
                return Err(ConfigError::Range);
            }
            let scale = pow2(f);
            let cell = 65535.0 * scale + 1.0;
            let xsum = if cfg.normalise { scale + n } else { n * cell };
            let xmax = if cfg.normalise { scale } else { cell };
            let ok = xmax < I31
                && match kind {
                    Kind::Paper => {
                        let t = xsum * rb2.0 + 1.0;
                        xsum * 1073741824.0 < LIMIT_ACC && t < I31
                    }
                    Kind::Square { kmax } => {
                        let box_max = 2.0 * xsum;
                        box_max < I31 && (kmax as f64 + 1.0) * n * box_max * box_max < LIMIT_SQUARE
                    }
                };
            if ok {
                break;
            }
            f -= 1;
        }

        // The embedding keeps `Q(f - s)`: the smallest extra shift `s` that
        // keeps ‖E‖_F below 2^30, so that a large kernel (unit weights) costs
        // precision of E relative to its own size, not of the input map.
        let mut e_shift: u32 = 0;
        if let Kind::Paper = kind {
            let scale = pow2(f);
            let xfro = if cfg.normalise {
                scale + n
            } else {
                sqrt(n) * (65535.0 * scale + 1.0)
            };
            loop {
                let e = (rb1.1 * rb2.1 * xfro + sqrt(n) * 0.5 * rb1.2) * pow2(-(e_shift as i32))
                    + sqrt(n) * 0.5;
                if e < LIMIT_E {
                    break;
                }
                e_shift += 1;
                if e_shift > 60 {
                    return Err(ConfigError::Range);
                }
            }
        }

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

        Ok(Scorer {
            config: *cfg,
            kind,
            frac: f,
            r1,
            r2t: transpose(&r2),
            p1,
            p2,
            e_shift,
            q,
        })
    }

    pub const fn config(&self) -> &Config {
        &self.config
    }

    pub const fn geometry(&self) -> Geometry {
        self.config.geometry
    }

    /// `J1 * J2`: length of a frame and of a map's state.
    pub const fn cells(&self) -> usize {
        self.config.geometry.cells()
    }

    /// Integer scores are real distances times `2^q`.
    pub const fn score_frac_bits(&self) -> i32 {
        self.q
    }

    /// Input format `Q(f)` of the normalised (or raw) map.
    pub const fn input_frac_bits(&self) -> i32 {
        self.frac
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

    /// Normalises `frame` (Eq. 5) into `x` (`J1 * J2` values, row-major) in
    /// `Q(f)` and returns its flags ([`flags::DARK`], [`flags::SATURATED`]).
    pub fn normalise(&self, frame: &[u16], x: &mut [i32]) -> Result<u8, FrameError> {
        let n = self.cells();
        let (Some(frame), Some(x)) = (frame.get(..n), x.get_mut(..n)) else {
            return Err(FrameError::Length);
        };
        if frame.len() != n {
            return Err(FrameError::Length);
        }
        let (fl, conv) = self.converter(frame);
        match conv {
            Conv::Zero => x.fill(0),
            Conv::Recip(r) => fill(x, frame, |a| recip_sample(a, r)),
            Conv::Shl(s) => fill(x, frame, |a| (a as i32) << s),
            Conv::Shr(s) => fill(x, frame, |a| shr_sample(a, s)),
        }
        Ok(fl)
    }

    /// Flags of a frame and how its samples become `Q(f)` values.
    fn converter(&self, frame: &[u16]) -> (u8, Conv) {
        let mut fl = 0;
        let mut sum: u32 = 0;
        let mut peak: u16 = 0;
        for &a in frame {
            // At most 256 * 65535 < 2^24: no overflow.
            sum += a as u32;
            peak = peak.max(a);
        }
        if peak >= self.config.full_scale {
            fl |= flags::SATURATED;
        }
        if sum == 0 {
            fl |= flags::DARK;
        }
        let conv = if self.config.normalise {
            if sum == 0 {
                Conv::Zero
            } else {
                // One division per map, then a multiply per sample.
                Conv::Recip((1u64 << (32 + self.frac as u32)) / sum as u64)
            }
        } else if self.frac >= 0 {
            Conv::Shl(self.frac as u32)
        } else {
            Conv::Shr((-self.frac) as u32)
        };
        (fl, conv)
    }

    /// Normalises and embeds one raw frame into `state` (`J1 * J2` words):
    /// the per-map work, done once per beam. Returns the map's flags.
    pub fn prepare(&self, frame: &[u16], state: &mut [i32]) -> Result<u8, FrameError> {
        self.prepare_with(frame, state, &mut Scratch::new())
    }

    /// [`Scorer::prepare`] with caller-owned scratch space, so that the
    /// per-beam path does not clear 2 KiB of stack for every map.
    pub fn prepare_with(
        &self,
        frame: &[u16],
        state: &mut [i32],
        scratch: &mut Scratch,
    ) -> Result<u8, FrameError> {
        let n = self.cells();
        if frame.len() != n {
            return Err(FrameError::Length);
        }
        let Some(state) = state.get_mut(..n) else {
            return Err(FrameError::Length);
        };
        match self.kind {
            Kind::Square { .. } => self.normalise(frame, state),
            Kind::Paper => {
                let (fl, conv) = self.converter(frame);
                let j2 = (self.config.geometry.j2 as usize).max(1);
                let x = &mut scratch.x;
                match conv {
                    Conv::Zero => x.iter_mut().for_each(|r| r.fill(0)),
                    Conv::Recip(r) => fill_rows(x, frame, j2, |a| recip_sample(a, r)),
                    Conv::Shl(s) => fill_rows(x, frame, j2, |a| (a as i32) << s),
                    Conv::Shr(s) => fill_rows(x, frame, j2, |a| shr_sample(a, s)),
                }
                self.embed(scratch, state);
                Ok(fl)
            }
        }
    }

    /// `E = R1 x R2ᵀ`, exploiting that both factors are upper triangular.
    ///
    /// Outputs are computed in pairs of neighbouring columns so that each
    /// loaded coefficient serves two multiply-accumulates (`SMLAL` on the
    /// Cortex-M) and the pair's operands sit next to each other in memory.
    /// The padding column of an odd `J2` is computed too (from zero
    /// coefficients, so it is 0) and never stored in `E`.
    fn embed(&self, scratch: &mut Scratch, e: &mut [i32]) {
        let j1 = (self.config.geometry.j1 as usize).min(MAX_J);
        let j2 = (self.config.geometry.j2 as usize).clamp(1, MAX_J);
        let Scratch { x, t } = scratch;
        // Row pass: T[i][k] = Σ_{l>=k} x[i][l] R2[k][l] = Σ_{l>=k} x[i][l] R2ᵀ[l][k].
        for (xr, tr) in x.iter().zip(t.iter_mut()).take(j1) {
            for kp in (0..j2).step_by(2) {
                let k = kp & (MAX_J - 2);
                let (mut a0, mut a1) = (0i64, 0i64);
                let (Some(xs), Some(rs)) = (xr.get(k..j2), self.r2t.get(k..j2)) else {
                    continue;
                };
                for (&xv, rr) in xs.iter().zip(rs) {
                    a0 += xv as i64 * rr[k] as i64;
                    a1 += xv as i64 * rr[k + 1] as i64;
                }
                tr[k] = round_shift(a0, self.p2) as i32;
                tr[k + 1] = round_shift(a1, self.p2) as i32;
            }
        }
        // Column pass: E[i][k] = Σ_{l>=i} R1[i][l] T[l][k].
        let shift = self.p1 + self.e_shift;
        for (i, (er, r1r)) in e
            .chunks_exact_mut(j2)
            .zip(self.r1.iter())
            .take(j1)
            .enumerate()
        {
            let (Some(rs), Some(ts)) = (r1r.get(i..j1), t.get(i..j1)) else {
                continue;
            };
            for kp in (0..j2).step_by(2) {
                let k = kp & (MAX_J - 2);
                let (mut a0, mut a1) = (0i64, 0i64);
                for (&r, tr) in rs.iter().zip(ts) {
                    a0 += r as i64 * tr[k] as i64;
                    a1 += r as i64 * tr[k + 1] as i64;
                }
                if let Some(v) = er.get_mut(k) {
                    *v = round_shift(a0, shift) as i32;
                }
                if let Some(v) = er.get_mut(k + 1) {
                    *v = round_shift(a1, shift) as i32;
                }
            }
        }
    }

    /// Score of the distance between two prepared maps, `Q(q)`, saturating.
    pub fn distance(&self, a: &[i32], b: &[i32]) -> u32 {
        let n = self.cells();
        let (Some(a), Some(b)) = (a.get(..n), b.get(..n)) else {
            return u32::MAX;
        };
        let acc = match self.kind {
            Kind::Paper => {
                let mut acc: i64 = 0;
                for (&x, &y) in a.iter().zip(b) {
                    // |x|, |y| < 2^30: the difference fits i32.
                    let d = x.wrapping_sub(y) as i64;
                    acc += d * d;
                }
                acc as u64
            }
            Kind::Square { kmax } => self.square_distance(a, b, kmax as usize),
        };
        self.to_score(acc)
    }

    /// Σ_k Σ_j (box sum of D = a - b)² through a summed-area table of `D`.
    fn square_distance(&self, a: &[i32], b: &[i32], kmax: usize) -> u64 {
        let j1 = self.config.geometry.j1 as usize;
        let j2 = self.config.geometry.j2 as usize;
        let w = j2 + 1;
        // sat[(i+1)*w + (k+1)] = Σ_{i'<=i, k'<=k} D[i'][k'].
        let mut sat = [0i32; (MAX_J + 1) * (MAX_J + 1)];
        for i in 0..j1 {
            let mut row = 0i32;
            for k in 0..j2 {
                let idx = i * j2 + k;
                let d = match (a.get(idx), b.get(idx)) {
                    (Some(&x), Some(&y)) => x - y,
                    _ => 0,
                };
                row += d;
                let above = sat.get(i * w + k + 1).copied().unwrap_or(0);
                if let Some(s) = sat.get_mut((i + 1) * w + k + 1) {
                    *s = above + row;
                }
            }
        }
        let at = |i: usize, k: usize| sat.get(i * w + k).copied().unwrap_or(0) as i64;
        let mut acc: u64 = 0;
        for h in 0..=kmax {
            for i in 0..j1 {
                let (ilo, ihi) = crate::tables::box_range(i, h, j1);
                for k in 0..j2 {
                    let (klo, khi) = crate::tables::box_range(k, h, j2);
                    let s =
                        at(ihi + 1, khi + 1) - at(ilo, khi + 1) - at(ihi + 1, klo) + at(ilo, klo);
                    acc += (s * s) as u64;
                }
            }
        }
        acc
    }

    /// `Q(2f)` squared distance to a `Q(q)` score, rounded, saturating.
    fn to_score(&self, acc: u64) -> u32 {
        // Squared distances are in Q(2(f - e_shift)).
        let shift = 2 * (self.frac - self.e_shift as i32) - self.q;
        let v = if shift > 0 {
            let s = shift as u32;
            if s >= 64 {
                0
            } else {
                (acc >> s) + ((acc >> (s - 1)) & 1)
            }
        } else {
            let s = (-shift) as u32;
            if s >= 64 || acc.leading_zeros() < s {
                if acc == 0 { 0 } else { u64::MAX }
            } else {
                acc << s
            }
        };
        if v > u32::MAX as u64 {
            u32::MAX
        } else {
            v as u32
        }
    }
}

/// How samples become `Q(f)` values for one frame.
#[derive(Clone, Copy)]
enum Conv {
    /// A dark map, normalised: all zero.
    Zero,
    /// Normalised: `round(a * recip / 2^32)`, `recip = floor(2^(32+f) / Σa)`.
    Recip(u64),
    /// Raw, `f >= 0`: `a << f`.
    Shl(u32),
    /// Raw, `f < 0`: `round(a / 2^-f)`.
    Shr(u32),
}

/// `round(a * 2^f / S)`: `a <= S`, so `a * recip + 2^31 <= 2^(32+f) + 2^31 < 2^57`.
/// Rounding (not truncating) keeps `Σx` within `N/2` of `2^f` instead of
/// biasing every map's mass low.
#[inline(always)]
fn recip_sample(a: u16, recip: u64) -> i32 {
    ((a as u64 * recip + (1 << 31)) >> 32) as i32
}

#[inline(always)]
fn shr_sample(a: u16, s: u32) -> i32 {
    (a as i32 + (1i32 << (s - 1))) >> s
}

#[inline(always)]
fn fill(x: &mut [i32], frame: &[u16], f: impl Fn(u16) -> i32) {
    for (xv, &a) in x.iter_mut().zip(frame) {
        *xv = f(a);
    }
}

/// Row-major frame into the padded `MAX_J`-stride scratch.
#[inline(always)]
fn fill_rows(x: &mut [[i32; MAX_J]; MAX_J], frame: &[u16], j2: usize, f: impl Fn(u16) -> i32) {
    for (xr, fr) in x.iter_mut().zip(frame.chunks_exact(j2)) {
        fill(xr, fr, &f);
    }
}

/// Scratch space of the embedding (the input map and the row pass), in a
/// fixed `MAX_J` stride so that the inner loops need no index arithmetic.
#[derive(Clone)]
pub struct Scratch {
    x: [[i32; MAX_J]; MAX_J],
    t: [[i32; MAX_J]; MAX_J],
}

impl Scratch {
    pub const fn new() -> Self {
        Scratch {
            x: [[0; MAX_J]; MAX_J],
            t: [[0; MAX_J]; MAX_J],
        }
    }
}

impl Default for Scratch {
    fn default() -> Self {
        Self::new()
    }
}

const fn transpose(r: &[[i32; MAX_J]; MAX_J]) -> [[i32; MAX_J]; MAX_J] {
    let mut t = [[0; MAX_J]; MAX_J];
    let mut i = 0;
    while i < MAX_J {
        let mut l = 0;
        while l < MAX_J {
            t[l][i] = r[i][l];
            l += 1;
        }
        i += 1;
    }
    t
}

/// `round(acc / 2^p)`, half up, for `p >= 1` (p = 0 is the identity).
#[inline(always)]
fn round_shift(acc: i64, p: u32) -> i64 {
    if p == 0 {
        acc
    } else {
        (acc + (1i64 << (p - 1))) >> p
    }
}

const fn dequantise(r: &[[i32; MAX_J]; MAX_J], p: u32) -> crate::tables::Mat {
    let mut m = [[0.0; MAX_J]; MAX_J];
    let s = pow2(-(p as i32));
    let mut i = 0;
    while i < MAX_J {
        let mut l = 0;
        while l < MAX_J {
            m[i][l] = r[i][l] as f64 * s;
            l += 1;
        }
        i += 1;
    }
    m
}

/// Gradient magnitude `floor(sqrt(g0² + g1²))` of two scores, same format.
pub fn magnitude(g0: u32, g1: u32) -> u32 {
    let s = (g0 as u64 * g0 as u64).saturating_add(g1 as u64 * g1 as u64);
    let m = s.isqrt();
    if m > u32::MAX as u64 {
        u32::MAX
    } else {
        m as u32
    }
}
