//! Scoring options shared by `score`, `stream` and `emulate`, and their
//! translation into the fixed-point core's and the f64 reference's
//! configurations, so that every command means the same thing by them.

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum KernelArg {
    /// b in {1..J1} x {1..J2} (docs/method.md §3)
    Paper,
    /// b = (k, k), k = 0..K, unit weights
    Square,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum WeightArg {
    /// w(b) = 1 / (n1 n2), summing to 1 (Eq. 9/10)
    Uniform,
    /// w(b) = 1 (Eq. 8)
    Unit,
}

#[derive(Args, Clone, Debug, PartialEq)]
pub struct ScoringArgs {
    /// Kernel set
    #[arg(long, value_enum, default_value = "paper")]
    pub kernels: KernelArg,
    /// Kernel weights (paper kernels; default uniform). Square kernels always use unit weights.
    #[arg(long, value_enum)]
    pub weights: Option<WeightArg>,
    /// Largest kernel size: caps b on each axis (paper) or sets K (square; default max(J1,J2)-1)
    #[arg(long, value_name = "K")]
    pub bmax: Option<usize>,
    /// Skip normalisation (Eq. 5): compare raw counts
    #[arg(long)]
    pub raw: bool,
}

impl Default for ScoringArgs {
    fn default() -> Self {
        ScoringArgs {
            kernels: KernelArg::Paper,
            weights: None,
            bmax: None,
            raw: false,
        }
    }
}

impl ScoringArgs {
    fn check(&self, j1: usize, j2: usize) -> Result<()> {
        if !(1..=16).contains(&j1) || !(1..=16).contains(&j2) {
            bail!("detector geometry {j1}x{j2} is not supported (each axis must be 1..=16)");
        }
        match self.kernels {
            KernelArg::Paper => {
                if self.bmax == Some(0) {
                    bail!("--bmax must be at least 1 for paper kernels");
                }
            }
            KernelArg::Square => {
                if self.weights == Some(WeightArg::Uniform) {
                    bail!(
                        "square kernels use unit weights (docs/method.md §3); drop --weights uniform"
                    );
                }
                let limit = j1.max(j2) - 1;
                if let Some(k) = self.bmax
                    && k > limit
                {
                    bail!(
                        "--bmax {k} is too large for square kernels on {j1}x{j2} maps (at most {limit})"
                    );
                }
            }
        }
        Ok(())
    }

    /// The fixed-point core's configuration for `j1 x j2` maps.
    pub fn core_config(&self, j1: usize, j2: usize) -> Result<cvm_core::Config> {
        self.check(j1, j2)?;
        let geometry = cvm_core::Geometry::new(j1 as u8, j2 as u8)
            .map_err(|e| anyhow::anyhow!("geometry {j1}x{j2}: {e}"))?;
        let kernels = match self.kernels {
            KernelArg::Paper => cvm_core::Kernels::Paper {
                bmax: self.bmax.unwrap_or(0).min(16) as u8,
            },
            KernelArg::Square => match self.bmax {
                Some(k) => cvm_core::Kernels::Square { kmax: k as u8 },
                None => cvm_core::Kernels::square_default(geometry),
            },
        };
        let weights = match (self.kernels, self.weights) {
            (KernelArg::Square, _) | (_, Some(WeightArg::Unit)) => cvm_core::Weights::Unit,
            _ => cvm_core::Weights::Uniform,
        };
        Ok(cvm_core::Config {
            geometry,
            kernels,
            weights,
            normalise: !self.raw,
            full_scale: u16::MAX,
        })
    }

    /// The fixed-point scorer, with a readable error if the core refuses it.
    pub fn scorer(&self, j1: usize, j2: usize) -> Result<cvm_core::Scorer> {
        let cfg = self.core_config(j1, j2)?;
        crate::fixed::scorer(&cfg)
            .map_err(|e| anyhow::anyhow!("fixed-point scorer refused the configuration: {e}"))
    }

    /// Warnings for configurations under which part or all of the gradient
    /// is zero whatever the scan (see [`crate::score::blind_axes`]).
    pub fn warnings(&self, j1: usize, j2: usize) -> Result<Vec<String>> {
        let e = cvm_reference::CvmEmbedding::new(&self.reference_config(j1, j2)?);
        Ok(crate::score::blind_axes(j1, j2, |a, b| {
            e.distance(&e.embed(a), &e.embed(b))
        }))
    }

    /// The f64 reference configuration for `j1 x j2` maps.
    pub fn reference_config(&self, j1: usize, j2: usize) -> Result<cvm_reference::CvmConfig> {
        self.check(j1, j2)?;
        let g = cvm_reference::Geometry::new(j1, j2)?;
        let cfg = match self.kernels {
            KernelArg::Paper => {
                let w = match self.weights {
                    Some(WeightArg::Unit) => cvm_reference::PaperWeights::Unit,
                    _ => cvm_reference::PaperWeights::Uniform,
                };
                cvm_reference::CvmConfig::paper(g, w, self.bmax)?
            }
            KernelArg::Square => cvm_reference::CvmConfig::square(g, self.bmax)?,
        };
        Ok(cfg.with_normalise(!self.raw))
    }
}
