//! The fixed-point scorer: normalise a raw map, embed it once, and score a
//! pair of embedded maps in `O(J1*J2)`. The square kernels' embedding is
//! in the module `square`; what follows is the paper kernels'.
//!
//! # The folded embedding (paper kernels)
//!
//! `d = ‖R1 D R2ᵀ‖²_F` with `Ki = Riᵀ Ri` (docs/method.md §4). Each axis kernel
//! is centrosymmetric, so folding an axis (`u[l] = x[l] + x[J-1-l]`,
//! `v[l] = x[l] - x[J-1-l]`, the middle cell in `u`) splits it into an even
//! and an odd block of at most 8 x 8 that do not interact; the factors `R'`
//! are the Cholesky factors of those blocks (module `embed`). A map costs
//! about `J1 J2 (J1 + J2 + 4) / 4` multiply-adds instead of
//! `J1 J2 (J1 + J2 + 2) / 2` (450 instead of 810 at 9x9), and every block
//! size has its own fully unrolled code.
//!
//! Per map: the sample sum `S` (and the saturation flag) first; then the row
//! pass folds each detector row along axis 2, converts it to `Q(f)` and
//! applies `R2'`; the column pass folds each column of that along axis 1,
//! applies `R1'` and stores `E`. In the streaming engine the column pass
//! also sums `(old - new)²` over the words it overwrites, which is the
//! vertical gradient component ([`Scorer::prepare_replacing`]).
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
//! [`Scorer::new`] takes the finest `f` and, for it, the finest `p1` for
//! which every bound below holds (`p2` is the finest that fits `i32`), and
//! refuses the configuration ([`ConfigError::Range`]) if none does. Let
//! `ε = 8 / 2 = 4` bound the rounding error of a sum of at most 8 rounded
//! terms, `r2max`, `r1max` the largest coefficient magnitudes and `‖R'q‖_F`
//! the Frobenius norms of the block-diagonal integer factors (at least their
//! spectral norms).
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

use crate::config::{Config, ConfigError, Geometry, Kernels, MAX_J};
use crate::flags;
use crate::tables::{axis_kernel, axis_weights, pow2, sqrt, weight_sum};

/// Why a frame could not be scored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// The frame or the state buffer does not hold `J1 * J2` values.
    Length,
    /// Square kernels without their factor table ([`Scorer::with_factors`]).
    Factors,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            FrameError::Length => "frame or state buffer of the wrong length",
            FrameError::Factors => "square kernels without their factor table",
        })
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Paper,
    Square { kmax: u8 },
}

/// What [`Scorer::prepare_map`] learnt about one map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Prepared {
    /// [`flags::DARK`], [`flags::SATURATED`].
    pub flags: u8,
    /// The map's power: the sum of its samples, below `256 * 65535 < 2^24`.
    pub power: u32,
    /// With `replacing`: the score of the distance between the map the
    /// state held and the new one; 0 otherwise.
    pub score: u32,
}

/// Tables and fixed-point formats for one configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct Scorer {
    config: Config,
    kind: Kind,
    /// Input format `Q(f)`.
    frac: i32,
    /// Folded factors of axis 1 and axis 2 (paper kernels), in `Q(p1)`, `Q(p2)`.
    f1: Factor,
    f2: Factor,
    /// Embedding format `Q(f + p1 + p2 - 64)` (paper kernels; `f` for square).
    e_frac: i32,
    /// `2^(32+f)`: numerator of the per-map scale of normalised maps.
    scale_num: f32,
    /// Score format `Q(q)`.
    q: i32,
    /// The unrolled passes of this geometry (paper kernels).
    passes: Passes,
    /// Factor format `Q(p)` of the square kernels.
    square_p: u32,
    /// The square kernels' factor table, once attached
    /// ([`Scorer::with_factors`]); empty otherwise.
    factors: &'static [i32],
}

mod embed;
mod square;

/// Words of the largest square kernels' factor table (16x16 maps):
/// [`Scorer::factor_words`] of any configuration is at most this.
pub const MAX_FACTOR_WORDS: usize = square::Blocks {
    j1: MAX_J,
    j2: MAX_J,
}
.table_words();

use embed::{Factor, MAX_H, Passes, TRI};
/// The sum pass, exposed for the test that checks when it copies the frame.
#[doc(hidden)]
pub use embed::{FrameCopy, sum_and_saturation};
use embed::{RealFactor, precision, quantise, real_factor};

/// Finest input format of normalised maps with paper kernels: the per-map
/// multiplier `2^(32+f) / S'` (`S' >= 2^30`) must stay below `2^31`.
const MAX_FRAC_NORM: i32 = 28;
/// Finest input format of raw maps with paper kernels: `v << (f + 2)` of a
/// folded count `|v| < 2^17` stays below `2^31`.
const MAX_FRAC_RAW: i32 = 11;
const I31: f64 = 2147483647.0;
const LIMIT_E: f64 = 1073741823.0; // 2^30 - 1

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
        let Some(passes) = Passes::new(j1, j2) else {
            return Err(ConfigError::Geometry);
        };

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

        let mut square_p = 0;
        let empty = Factor {
            h: 0,
            g: 0,
            even: [0; TRI],
            odd: [0; TRI],
        };
        let (f, f1, f2, e_frac) = match kind {
            Kind::Paper => {
                let (rf1, rf2) = paper_factors(j1, &w1, n1, j2, &w2, n2);
                let (f, p1, p2, _) = match paper_formats(cfg, &rf1, &rf2) {
                    Ok(v) => v,
                    Err(e) => return Err(e),
                };
                (
                    f,
                    quantise(&rf1, p1),
                    quantise(&rf2, p2),
                    f + p1 as i32 + p2 as i32 - 64,
                )
            }
            Kind::Square { kmax } => {
                let blocks = square::Blocks { j1, j2 };
                let Some((f, p)) = square::formats(&blocks, kmax as usize, cfg.normalise) else {
                    return Err(ConfigError::Range);
                };
                square_p = p;
                (f, empty, empty, f + p as i32 - 32)
            }
        };

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

        Ok(Scorer {
            config: *cfg,
            kind,
            frac: f,
            f1,
            f2,
            e_frac,
            scale_num: pow2(32 + f) as f32,
            q,
            passes,
            square_p,
            factors: &[],
        })
    }

    /// Words of the square kernels' factor table ([`Scorer::with_factors`]);
    /// 0 for the paper kernels, whose factors the `Scorer` holds.
    pub const fn factor_words(&self) -> usize {
        match self.kind {
            Kind::Square { .. } => self.blocks().table_words(),
            Kind::Paper => 0,
        }
    }

    /// Whether this scorer still needs [`Scorer::with_factors`] before it
    /// can prepare a map.
    pub const fn needs_factors(&self) -> bool {
        matches!(self.kind, Kind::Square { .. }) && self.factors.is_empty()
    }

    /// Builds the square kernels' factors into `table` (at least
    /// [`Scorer::factor_words`] words; the rest is left alone) and returns
    /// the scorer that embeds with them. Done once, at start-up: an f64
    /// Cholesky factorisation of four blocks of up to 64 cells, on 16.6 KB
    /// of stack. The paper kernels need no table: `self` is returned as it
    /// is.
    pub fn with_factors(mut self, table: &'static mut [i32]) -> Result<Scorer, ConfigError> {
        let Kind::Square { kmax } = self.kind else {
            return Ok(self);
        };
        let words = self.factor_words();
        let Some(table) = table.get_mut(..words) else {
            return Err(ConfigError::Table);
        };
        if !square::build(&self.blocks(), kmax as usize, self.square_p, table) {
            return Err(ConfigError::Table);
        }
        self.factors = table;
        Ok(self)
    }

    /// `self` with the factor table of `other`, a scorer of the same
    /// geometry, kernels and factor format that has one
    /// ([`Scorer::with_factors`]): for a host that builds many scorers of
    /// one configuration (the full scale, the thresholds or the weights
    /// aside) and one table.
    pub fn with_factors_of(mut self, other: &Scorer) -> Result<Scorer, ConfigError> {
        if !matches!(self.kind, Kind::Square { .. }) {
            return Ok(self);
        }
        let same = self.kind == other.kind
            && self.config.geometry == other.config.geometry
            && self.square_p == other.square_p
            && other.factors.len() == self.factor_words();
        if !same {
            return Err(ConfigError::Table);
        }
        self.factors = other.factors;
        Ok(self)
    }

    const fn blocks(&self) -> square::Blocks {
        square::Blocks {
            j1: self.config.geometry.j1 as usize,
            j2: self.config.geometry.j2 as usize,
        }
    }

    pub const fn config(&self) -> &Config {
        &self.config
    }

    pub const fn geometry(&self) -> Geometry {
        self.config.geometry
    }

    /// `J1 * J2`: length of a frame.
    pub const fn cells(&self) -> usize {
        self.config.geometry.cells()
    }

    /// `i32` words of one prepared map ([`Config::state_words`]).
    pub const fn state_words(&self) -> usize {
        self.config.state_words()
    }

    /// The fixed-point formats of this configuration and, for the paper
    /// kernels, the bounds of the overflow proof at those formats (module
    /// docs, "Why nothing overflows"). Recomputed from the configuration,
    /// as [`Scorer::new`] computes them: for diagnostics and for the tests
    /// that pin the proof, not for the per-beam path.
    pub fn formats(&self) -> Formats {
        let (mut factors, mut bounds) = ([0, 0], None);
        if let (Kind::Paper, Kernels::Paper { bmax }) = (self.kind, self.config.kernels) {
            let g = self.config.geometry;
            let (j1, j2) = (g.j1 as usize, g.j2 as usize);
            // `new` accepted these weights, so neither axis fails here.
            let a1 = axis_weights(&self.config.weights, 0, j1, bmax as usize);
            let a2 = axis_weights(&self.config.weights, 1, j2, bmax as usize);
            if let (Ok((w1, n1)), Ok((w2, n2))) = (a1, a2) {
                let (rf1, rf2) = paper_factors(j1, &w1, n1, j2, &w2, n2);
                if let Ok((_, p1, p2, b)) = paper_formats(&self.config, &rf1, &rf2) {
                    factors = [p1, p2];
                    bounds = Some(b);
                }
            }
        }
        if let Kind::Square { .. } = self.kind {
            factors = [self.square_p; 2];
        }
        Formats {
            input: self.frac,
            factors,
            embedding: self.e_frac,
            score: self.q,
            bounds,
        }
    }

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

    /// Normalises `frame` (Eq. 5) into `x` (`J1 * J2` values, row-major) in
    /// `Q(f)` and returns its flags ([`flags::DARK`], [`flags::SATURATED`]).
    pub fn normalise(&self, frame: &[u16], x: &mut [i32]) -> Result<u8, FrameError> {
        self.normalise_power(frame, x).map(|(fl, _)| fl)
    }

    /// [`Scorer::normalise`], also returning the map's sample sum.
    fn normalise_power(&self, frame: &[u16], x: &mut [i32]) -> Result<(u8, u32), FrameError> {
        let n = self.cells();
        let (Some(frame), Some(x)) = (frame.get(..n), x.get_mut(..n)) else {
            return Err(FrameError::Length);
        };
        if frame.len() != n {
            return Err(FrameError::Length);
        }
        let (fl, sum, conv) = self.converter(frame);
        match conv {
            Conv::Zero => x.fill(0),
            Conv::Recip(r) => fill(x, frame, |a| recip_sample(a, r)),
            Conv::Shl(s) => fill(x, frame, |a| (a as i32) << s),
        }
        Ok((fl, sum))
    }

    /// Flags and sample sum of a frame, and how its samples become `Q(f)` values.
    fn converter(&self, frame: &[u16]) -> (u8, u32, Conv) {
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
        } else {
            // `frac >= 0` (see `Scorer::new`).
            Conv::Shl(self.frac as u32)
        };
        (fl, sum, conv)
    }

    /// Normalises and embeds one raw frame into `state`
    /// ([`Scorer::state_words`] words): the per-map work, done once per
    /// beam. Returns the map's flags.
    pub fn prepare(&self, frame: &[u16], state: &mut [i32]) -> Result<u8, FrameError> {
        self.prepare_with(frame, state, &mut Scratch::new())
    }

    /// [`Scorer::prepare`] with caller-owned scratch space, so that the
    /// per-beam path does not clear 4.5 KiB of stack for every map.
    pub fn prepare_with(
        &self,
        frame: &[u16],
        state: &mut [i32],
        scratch: &mut Scratch,
    ) -> Result<u8, FrameError> {
        self.prepare_map(frame, state, scratch, false)
            .map(|p| p.flags)
    }

    /// [`Scorer::prepare_with`] into a `state` that holds a prepared map:
    /// also returns the score of the distance between that map and the new
    /// one, computed while the new one overwrites it (the streaming engine's
    /// vertical component, without a copy of the new map or a second pass).
    /// Equal to `distance(old, new)`.
    pub fn prepare_replacing(
        &self,
        frame: &[u16],
        state: &mut [i32],
        scratch: &mut Scratch,
    ) -> Result<(u8, u32), FrameError> {
        self.prepare_map(frame, state, scratch, true)
            .map(|p| (p.flags, p.score))
    }

    /// The per-map work of the streaming engine: [`Scorer::prepare_with`]
    /// (`replacing` false) or [`Scorer::prepare_replacing`] (true), with the
    /// map's power (sample sum) that the normalisation computes anyway.
    pub fn prepare_map(
        &self,
        frame: &[u16],
        state: &mut [i32],
        scratch: &mut Scratch,
        diff: bool,
    ) -> Result<Prepared, FrameError> {
        self.prepare_map_near(frame, state, &mut [], scratch, diff)
    }

    /// [`Scorer::prepare_map`] that also writes the prepared map to `near`
    /// when it holds [`Scorer::state_words`] words (else not): the
    /// streaming engine keeps the current row's last maps there, in memory
    /// it reads faster than the row buffers (DTCM on the H743), for the
    /// horizontal distances. With paper kernels the copy is one more store
    /// per word in the column pass; square kernels copy the state after.
    pub fn prepare_map_near(
        &self,
        frame: &[u16],
        state: &mut [i32],
        near: &mut [i32],
        scratch: &mut Scratch,
        diff: bool,
    ) -> Result<Prepared, FrameError> {
        let n = self.cells();
        if frame.len() != n {
            return Err(FrameError::Length);
        }
        let Some(state) = state.get_mut(..self.state_words()) else {
            return Err(FrameError::Length);
        };
        match self.kind {
            Kind::Square { .. } => {
                if self.factors.is_empty() {
                    return Err(FrameError::Factors);
                }
                let blocks = self.blocks();
                let mut copy = embed::FrameCopy::new();
                let (power, fl, frame) = self.sum_pass(frame, &mut copy);
                square::fold(&blocks, frame, self.scale(power), &mut scratch.z);
                if !square::embed(&blocks, self.factors, &mut scratch.z) {
                    return Err(FrameError::Factors);
                }
                let e = scratch.z.get(..n).unwrap_or(&[]);
                let acc = if diff {
                    squared_difference(state, e)
                } else {
                    0
                };
                embed::copy_words(e, state);
                if let Some(near) = near.get_mut(..n) {
                    embed::copy_words(e, near);
                }
                Ok(Prepared {
                    flags: fl,
                    power,
                    score: if diff { self.to_score(acc) } else { 0 },
                })
            }
            Kind::Paper => {
                let mut copy = embed::FrameCopy::new();
                let (sum, fl, frame) = self.sum_pass(frame, &mut copy);
                let conv = self.scale(sum);
                let acc = embed::embed(
                    &self.passes,
                    &self.f1,
                    &self.f2,
                    frame,
                    conv,
                    state,
                    near,
                    diff,
                );
                Ok(Prepared {
                    flags: fl,
                    power: sum,
                    score: if diff { self.to_score(acc) } else { 0 },
                })
            }
        }
    }

    /// The sample sum of `frame`, its flags ([`flags::SATURATED`],
    /// [`flags::DARK`]) and the frame to read from then (`copy` once the
    /// sum pass has copied it there): the first pass of both kernel sets.
    #[inline(always)]
    fn sum_pass<'c>(&self, frame: &'c [u16], copy: &'c mut FrameCopy) -> (u32, u8, &'c [u16]) {
        let (sum, sat, frame) = embed::sum_and_saturation(frame, self.config.full_scale, copy);
        let mut fl = 0;
        if sat {
            fl |= flags::SATURATED;
        }
        if sum == 0 {
            fl |= flags::DARK;
        }
        (sum, fl, frame)
    }

    /// How the folded counts `v` of a map with sample sum `sum` become
    /// `Q(f)` values: `y = round((v << k) * m / 2^32)`, returned as `(k, m)`.
    ///
    /// Normalised (`y ≈ v 2^f / S`): `k` puts `S' = S << k` in
    /// `[2^30, 2^31)` (so `|v << k| <= S' < 2^31`) and
    /// `m = floor(2^(32+f) / S') <= 2^30`, so `|y - v 2^f / S| < 1`. A dark
    /// map gets `m = 0`. Raw (`y = v 2^f`): `k = f + 2`, `m = 2^30`, exact.
    fn scale(&self, sum: u32) -> (u32, i32) {
        let f = self.frac;
        if self.config.normalise {
            if sum == 0 {
                return (0, 0);
            }
            let k = sum.leading_zeros().saturating_sub(1);
            let s = sum << k;
            (k, reciprocal(self.scale_num, f, s))
        } else {
            // `f >= 0` (see `Scorer::new`), so `k = f + 2 <= 30`.
            ((f + 2) as u32, 1 << 30)
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
    fn to_score(&self, acc: u64) -> u32 {
        // Squared distances are in Q(2 e_frac); `1 <= s <= 63` (see
        // `Scorer::new`), and `acc >> s` plus the rounding bit cannot wrap.
        let s = ((2 * self.e_frac - self.q) as u32).clamp(1, 63);
        let v = (acc >> s) + ((acc >> (s - 1)) & 1);
        // Below 2^31 for every pair of maps (`q` is chosen so), saturating
        // all the same.
        u32::try_from(v).unwrap_or(u32::MAX)
    }
}

/// Formats of the folded embedding: the finest input format `f` and the
/// factor precisions `p1`, `p2` for which every bound of the module docs
/// holds.
const fn paper_formats(
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

/// The fixed-point formats of a configuration ([`Scorer::formats`]; the
/// table in the module docs).
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
const fn paper_factors(
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

/// `floor(2^(32+f) / s)` for `s` in `[2^30, 2^31)` and `f = 28` (the only
/// format of normalised paper-kernel maps), without a 64-bit division (a
/// library call on the Cortex-M4): a single-precision estimate
/// (`num = 2^(32+f)` as `f32`), refined once through its exact remainder,
/// then at most one step down. Exact for every `s`, checked exhaustively
/// (`reciprocal_is_exact_for_every_sum` in core-tests, 2^30 cases), so the
/// host and the target agree however `f32` rounds.
#[inline(always)]
fn reciprocal(num: f32, f: i32, s: u32) -> i32 {
    let n = 1i64 << (32 + f).clamp(0, 60);
    // Within 2^-22 of the quotient (at most 2^30): off by at most 2^9.
    let mut m = (num / s as f32) as i32 as i64;
    let r = n - m * s as i64;
    // |r| < 2^41: its top bits over those of s give the correction to
    // within one (only `f32 <-> i32` conversions, single instructions);
    // truncation leaves the remainder at most one `s` below 0, never at or
    // above `s` (the exhaustive check counts both).
    let c = ((r >> 20) as i32 as f32 / (s >> 20) as f32) as i32 as i64;
    m += c;
    if r - c * (s as i64) < 0 {
        m -= 1;
    }
    m as i32
}

/// [`reciprocal`] as the scorer calls it for normalised paper-kernel maps
/// (`f = 28`), for the exhaustive test.
#[doc(hidden)]
pub fn reciprocal_q60(s: u32) -> i32 {
    reciprocal(pow2(60) as f32, 28, s)
}

/// How samples become `Q(f)` values for one frame.
#[derive(Clone, Copy)]
enum Conv {
    /// A dark map, normalised: all zero.
    Zero,
    /// Normalised: `round(a * recip / 2^32)`, `recip = floor(2^(32+f) / Σa)`.
    Recip(u64),
    /// Raw (`f >= 0` always): `a << f`.
    Shl(u32),
}

/// `round(a * 2^f / S)`: `a <= S`, so `a * recip + 2^31 <= 2^(32+f) + 2^31 < 2^57`.
/// Rounding (not truncating) keeps `Σx` within `N/2` of `2^f` instead of
/// biasing every map's mass low.
#[inline(always)]
fn recip_sample(a: u16, recip: u64) -> i32 {
    ((a as u64 * recip + (1 << 31)) >> 32) as i32
}

#[inline(always)]
fn fill(x: &mut [i32], frame: &[u16], f: impl Fn(u16) -> i32) {
    for (xv, &a) in x.iter_mut().zip(frame) {
        *xv = f(a);
    }
}

/// `Σ (a - b)²` of two embeddings: `|a|, |b| < 2^30`, so each difference
/// fits `i32` and the sum (below `2^62`) fits `i64`: one `SUB` and one
/// `SMLAL` per word. Kept out of line so that its registers are not shared
/// with the square-kernel path.
#[inline(never)]
fn squared_difference(a: &[i32], b: &[i32]) -> u64 {
    let (mut acc, done) = squared_difference_blocks(a, b);
    for (&x, &y) in a.iter().zip(b).skip(done) {
        let d = x.wrapping_sub(y) as i64;
        acc = acc.wrapping_add(d * d);
    }
    acc as u64
}

/// The sum of [`squared_difference`] over the first `4 * (n / 4)` words
/// (`n` the shorter length) and that number of words. On the Cortex-M:
/// four words of each map per `LDM` (`cvm_squared_difference_4`), 12
/// instructions per four words instead of about 19 compiled, and a
/// quarter of the bus accesses where a map is in a row buffer.
#[cfg(target_arch = "arm")]
#[inline(always)]
fn squared_difference_blocks(a: &[i32], b: &[i32]) -> (i64, usize) {
    let blocks = a.len().min(b.len()) / 4;
    if blocks == 0 {
        return (0, 0);
    }
    // SAFETY: `a` and `b` hold at least `4 * blocks` words; the function
    // reads exactly those, writes registers only and preserves the
    // callee-saved ones (AAPCS).
    let acc = unsafe { distance_arm::cvm_squared_difference_4(a.as_ptr(), b.as_ptr(), blocks) };
    (acc as i64, 4 * blocks)
}

#[cfg(target_arch = "arm")]
mod distance_arm {
    // `(a, b, blocks) -> Σ (a - b)²` over `4 blocks` words (`blocks > 0`),
    // wrapping (see `squared_difference`): r0-r3 hold `a`, `b`, the count
    // and the low word, r12 and lr the high word and a spare.
    core::arch::global_asm!(
        ".section .text.cvm_squared_difference_4,\"ax\",%progbits",
        ".global cvm_squared_difference_4",
        ".type cvm_squared_difference_4,%function",
        ".p2align 2",
        ".thumb_func",
        "cvm_squared_difference_4:",
        "    push {{r4, r5, r6, r7, r8, r9, r10, r11, lr}}",
        "    movs r3, #0",
        "    mov r12, #0",
        "1:",
        "    ldm r0!, {{r4, r5, r6, r7}}",
        "    ldm r1!, {{r8, r9, r10, r11}}",
        "    sub r4, r4, r8",
        "    smlal r3, r12, r4, r4",
        "    sub r5, r5, r9",
        "    smlal r3, r12, r5, r5",
        "    sub r6, r6, r10",
        "    smlal r3, r12, r6, r6",
        "    sub r7, r7, r11",
        "    smlal r3, r12, r7, r7",
        "    subs r2, r2, #1",
        "    bne 1b",
        "    mov r0, r3",
        "    mov r1, r12",
        "    pop {{r4, r5, r6, r7, r8, r9, r10, r11, pc}}",
        ".size cvm_squared_difference_4, . - cvm_squared_difference_4",
    );

    unsafe extern "C" {
        pub fn cvm_squared_difference_4(a: *const i32, b: *const i32, blocks: usize) -> u64;
    }
}

#[cfg(not(target_arch = "arm"))]
#[inline(always)]
fn squared_difference_blocks(_a: &[i32], _b: &[i32]) -> (i64, usize) {
    (0, 0)
}

/// Scratch space of the square kernels: a map's folded blocks, which the
/// embedding overwrites in place. (The paper kernels' row pass keeps its
/// output on the stack: see `embed::embed`.)
#[derive(Clone)]
pub struct Scratch {
    z: [i32; square::FOLD_WORDS],
}

impl Scratch {
    pub const fn new() -> Self {
        Scratch {
            z: [0; square::FOLD_WORDS],
        }
    }
}

impl Default for Scratch {
    fn default() -> Self {
        Self::new()
    }
}

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
