//! [`Scorer`]: the tables and fixed-point formats of one configuration,
//! built once (in `const` context on the firmware), and what can be asked
//! of them.

use crate::config::{Config, ConfigError, Geometry, Kernels, MAX_J};
use crate::scorer::embed::{Factor, Passes, TRI, quantise};
use crate::scorer::formats::{Formats, paper_factors, paper_formats, score_format};
use crate::scorer::square;
use crate::tables::{axis_weights, pow2, weight_sum};

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Kind {
    Paper,
    Square { kmax: u8 },
}

/// Tables and fixed-point formats for one configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct Scorer {
    pub(super) config: Config,
    pub(super) kind: Kind,
    /// Input format `Q(f)`.
    pub(super) frac: i32,
    /// Folded factors of axis 1 and axis 2 (paper kernels), in `Q(p1)`, `Q(p2)`.
    pub(super) f1: Factor,
    pub(super) f2: Factor,
    /// Embedding format `Q(f + p1 + p2 - 64)` (paper kernels; `f` for square).
    pub(super) e_frac: i32,
    /// `2^(32+f)`: numerator of the per-map scale of normalised maps.
    pub(super) scale_num: f32,
    /// Score format `Q(q)`.
    pub(super) q: i32,
    /// The unrolled passes of this geometry (paper kernels).
    pub(super) passes: Passes,
    /// Factor format `Q(p)` of the square kernels.
    pub(super) square_p: u32,
    /// The square kernels' factor table, once attached
    /// ([`Scorer::with_factors`]); empty otherwise.
    pub(super) factors: &'static [i32],
    /// Half-width `h` of the spread channel's core box
    /// ([`crate::channels::spread`]).
    pub(super) spread_half: u8,
}

/// Words of the largest square kernels' factor table (16x16 maps):
/// [`Scorer::factor_words`] of any configuration is at most this.
pub const MAX_FACTOR_WORDS: usize = square::Blocks {
    j1: MAX_J,
    j2: MAX_J,
}
.table_words();

/// The kernel set of `kernels` and its largest box of the paper kernels
/// (0 for the square kernels, whose weights are all 1).
#[inline(always)]
const fn kind_of(kernels: Kernels) -> Result<(Kind, usize), ConfigError> {
    match kernels {
        Kernels::Paper { bmax } => Ok((Kind::Paper, bmax as usize)),
        Kernels::Square { kmax } => {
            if kmax as usize >= MAX_J {
                return Err(ConfigError::KernelSize);
            }
            Ok((Kind::Square { kmax }, 0))
        }
    }
}

impl Scorer {
    /// Builds the tables for `cfg`. Usable in `const` context, so a firmware
    /// configuration that cannot be scored fails to compile.
    pub const fn new(cfg: &Config) -> Result<Scorer, ConfigError> {
        let g = cfg.geometry;
        if g.j1 == 0 || g.j2 == 0 || g.j1 as usize > MAX_J || g.j2 as usize > MAX_J {
            return Err(ConfigError::Geometry);
        }
        if cfg.full_scale == 0 {
            return Err(ConfigError::FullScale);
        }
        let (j1, j2) = (g.j1 as usize, g.j2 as usize);
        let Some(passes) = Passes::new(j1, j2) else {
            return Err(ConfigError::Geometry);
        };
        let (kind, bmax) = match kind_of(cfg.kernels) {
            Ok(v) => v,
            Err(e) => return Err(e),
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
        // The formats, and the paper kernels' factors quantised at them:
        // chosen here rather than in a helper, which would return both
        // factors by value (one more copy of each where a board builds its
        // scorer at run time).
        let empty = Factor {
            h: 0,
            g: 0,
            even: [0; TRI],
            odd: [0; TRI],
        };
        let mut square_p = 0;
        let (frac, f1, f2, e_frac) = match kind {
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
        let q = match score_format(cfg, wsum, e_frac) {
            Ok(v) => v,
            Err(e) => return Err(e),
        };
        Ok(Scorer {
            config: *cfg,
            kind,
            frac,
            f1,
            f2,
            e_frac,
            scale_num: pow2(32 + frac) as f32,
            q,
            passes,
            square_p,
            factors: &[],
            spread_half: crate::channels::spread::CORE_HALF,
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

    pub(super) const fn blocks(&self) -> square::Blocks {
        square::Blocks {
            j1: self.config.geometry.j1 as usize,
            j2: self.config.geometry.j2 as usize,
        }
    }

    pub const fn config(&self) -> &Config {
        &self.config
    }

    /// This scorer with the spread channel's core half-width `h` (the box
    /// of `2h + 1` cells a side; [`crate::channels::spread::CORE_HALF`] by default).
    pub const fn with_spread_half(mut self, half: u8) -> Scorer {
        self.spread_half = half;
        self
    }

    /// The spread channel's core half-width.
    pub const fn spread_half(&self) -> u8 {
        self.spread_half
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
    /// `formats`, "Why nothing overflows"). Recomputed from the configuration,
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
}
