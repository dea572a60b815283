//! Kernel sets and weights of the CVM distance (docs/method.md §3).

use crate::geometry::Geometry;
use std::fmt;

/// The box of centre `j` and size `b` on an axis of `len` cells (Eq. 6),
/// 1-based and inclusive: `[max(1, j - b), min(len, j + b)]`.
pub fn box_range(j: usize, b: usize, len: usize) -> (usize, usize) {
    (j.saturating_sub(b).max(1), (j + b).min(len))
}

/// Weights of the paper kernels `b in {1..n1} x {1..n2}`.
#[derive(Clone, Debug, PartialEq)]
pub enum PaperWeights {
    /// `w(b) = 1` (Eq. 8).
    Unit,
    /// `w(b) = 1 / (n1 * n2)`, summing to 1 as Eq. 10 asks (Eq. 9). Without a
    /// `bmax` cap this is `1 / (J1 * J2)`.
    Uniform,
    /// `w(b) = w1[b1 - 1] * w2[b2 - 1]`; `w1` has `n1` entries, `w2` has `n2`,
    /// all finite and non-negative.
    Separable {
        /// Weights of the sizes `1..=n1` on the first axis.
        w1: Vec<f64>,
        /// Weights of the sizes `1..=n2` on the second axis.
        w2: Vec<f64>,
    },
}

/// Which family of kernels a configuration uses, with its resolved weights.
#[derive(Clone, Debug, PartialEq)]
pub enum KernelFamily {
    /// Paper kernels: `b = (b1, b2)`, `b_i in 1..=n_i`, `n_i = min(J_i, bmax)`,
    /// weight `w1[b1 - 1] * w2[b2 - 1]`.
    Paper {
        /// Per-size weights on the first axis (length `n1`).
        w1: Vec<f64>,
        /// Per-size weights on the second axis (length `n2`).
        w2: Vec<f64>,
    },
    /// Square kernels `b = (k, k)`, `k = 0..=k_max`, all weights 1.
    Square {
        /// Largest kernel size `K`.
        k_max: usize,
    },
}

/// One kernel: box size `(b1, b2)` and its weight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Kernel {
    /// Size on the first axis.
    pub b1: usize,
    /// Size on the second axis.
    pub b2: usize,
    /// Weight `w(b)`.
    pub w: f64,
}

/// A rejected kernel configuration.
#[derive(Clone, Debug, PartialEq)]
pub enum ConfigError {
    /// `bmax` of 0 leaves no paper kernel.
    ZeroBmax,
    /// Separable weights of the wrong length for an axis.
    WeightLength {
        /// Axis (1 or 2).
        axis: usize,
        /// Number of kernel sizes on that axis.
        expected: usize,
        /// Number of weights given.
        got: usize,
    },
    /// A weight that is negative, NaN or infinite.
    BadWeight(f64),
    /// A square-kernel `K` at or beyond `max(J1, J2)`: such a box covers the
    /// whole map on both axes and adds nothing but a duplicate of the `K =
    /// max(J1, J2) - 1` term.
    SquareTooLarge {
        /// The requested `K`.
        k_max: usize,
        /// The largest meaningful `K`.
        limit: usize,
    },
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::ZeroBmax => write!(f, "bmax must be at least 1 for paper kernels"),
            Self::WeightLength {
                axis,
                expected,
                got,
            } => write!(
                f,
                "axis {axis} has {expected} kernel sizes but {got} weights were given"
            ),
            Self::BadWeight(w) => {
                write!(f, "kernel weight {w} is not a finite non-negative number")
            }
            Self::SquareTooLarge { k_max, limit } => write!(
                f,
                "square kernel size {k_max} exceeds max(J1, J2) - 1 = {limit}"
            ),
        }
    }
}

impl std::error::Error for ConfigError {}

/// Everything that fixes a CVM distance: geometry, kernels with weights, and
/// whether raw maps are normalised (Eq. 5) first.
#[derive(Clone, Debug, PartialEq)]
pub struct CvmConfig {
    geometry: Geometry,
    family: KernelFamily,
    normalise: bool,
}

impl CvmConfig {
    /// Paper kernels (docs/method.md §3) with `b_i in 1..=min(J_i, bmax)`
    /// (`bmax = None`: no cap), normalised maps.
    pub fn paper(
        geometry: Geometry,
        weights: PaperWeights,
        bmax: Option<usize>,
    ) -> Result<Self, ConfigError> {
        if bmax == Some(0) {
            return Err(ConfigError::ZeroBmax);
        }
        let cap = bmax.unwrap_or(usize::MAX);
        let n1 = geometry.j1().min(cap);
        let n2 = geometry.j2().min(cap);
        let (w1, w2) = match weights {
            PaperWeights::Unit => (vec![1.0; n1], vec![1.0; n2]),
            PaperWeights::Uniform => (vec![1.0 / n1 as f64; n1], vec![1.0 / n2 as f64; n2]),
            PaperWeights::Separable { w1, w2 } => {
                for (axis, w, n) in [(1, &w1, n1), (2, &w2, n2)] {
                    if w.len() != n {
                        return Err(ConfigError::WeightLength {
                            axis,
                            expected: n,
                            got: w.len(),
                        });
                    }
                    if let Some(&bad) = w.iter().find(|x| !(x.is_finite() && **x >= 0.0)) {
                        return Err(ConfigError::BadWeight(bad));
                    }
                }
                (w1, w2)
            }
        };
        Ok(Self {
            geometry,
            family: KernelFamily::Paper { w1, w2 },
            normalise: true,
        })
    }

    /// Square kernels `b = (k, k)`, `k = 0..=K`, unit weights, normalised
    /// maps. `K` defaults to `max(J1, J2) - 1`, the largest useful size.
    pub fn square(geometry: Geometry, k_max: Option<usize>) -> Result<Self, ConfigError> {
        let limit = geometry.j1().max(geometry.j2()) - 1;
        let k_max = k_max.unwrap_or(limit);
        if k_max > limit {
            return Err(ConfigError::SquareTooLarge { k_max, limit });
        }
        Ok(Self {
            geometry,
            family: KernelFamily::Square { k_max },
            normalise: true,
        })
    }

    /// The same configuration, with (`true`) or without (`false`, raw counts
    /// compared as they are) normalisation.
    pub fn with_normalise(mut self, normalise: bool) -> Self {
        self.normalise = normalise;
        self
    }

    /// The detector geometry.
    pub fn geometry(&self) -> Geometry {
        self.geometry
    }

    /// The kernel family and its weights.
    pub fn family(&self) -> &KernelFamily {
        &self.family
    }

    /// Whether maps are normalised (Eq. 5) before the LCDs are taken.
    pub fn normalises(&self) -> bool {
        self.normalise
    }

    /// Every kernel `b` with its weight `w(b)`, the `sum_b` of Eq. 9.
    pub fn kernels(&self) -> Vec<Kernel> {
        match &self.family {
            KernelFamily::Paper { w1, w2 } => w1
                .iter()
                .enumerate()
                .flat_map(|(i1, &x1)| {
                    w2.iter().enumerate().map(move |(i2, &x2)| Kernel {
                        b1: i1 + 1,
                        b2: i2 + 1,
                        w: x1 * x2,
                    })
                })
                .collect(),
            KernelFamily::Square { k_max } => (0..=*k_max)
                .map(|k| Kernel {
                    b1: k,
                    b2: k,
                    w: 1.0,
                })
                .collect(),
        }
    }

    /// The map the LCDs are taken of: `ã` when normalising, else the raw map.
    pub(crate) fn prepare(&self, raw: &[f64]) -> Vec<f64> {
        self.geometry.check_map(raw);
        if self.normalise {
            crate::normalise(raw).map
        } else {
            raw.to_vec()
        }
    }
}
