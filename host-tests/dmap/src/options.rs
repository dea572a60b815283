//! The command-line options that choose what a run scores and reports,
//! shared by `score`, `calibrate`, `stream`, `emulate`, `twin` and `bench`.
//! They are only what the user typed: [`crate::settings`] turns them (with
//! a calibration file, if given) into the core's configuration and the
//! pipeline's settings, and checks them there, once.

use clap::{Args, ValueEnum};
use std::path::PathBuf;

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

/// What the pipeline reports: shared by `stream`, `emulate` and `twin`.
#[derive(Args, Clone, Debug, PartialEq)]
pub struct OutputArgs {
    /// Defect threshold on the gradient magnitude, in distance units (default 0.5 for
    /// normalised maps; required with --raw, whose distances are in counts)
    #[arg(long)]
    pub threshold: Option<f64>,
    /// Also emit every position's score (S lines)
    #[arg(long)]
    pub scores: bool,
    /// Threshold of the power channel: the contrast |P+ - P-| / (P+ + P-) of the two
    /// neighbours' powers (default 0.1; inf turns the channel off)
    #[arg(long, value_name = "C")]
    pub power_threshold: Option<f64>,
    /// Threshold of the spread channel: the change of the light's share outside the maps'
    /// core box between the two neighbours (docs/method.md §8; default inf: the channel off,
    /// nothing measured)
    #[arg(long, value_name = "S")]
    pub spread_threshold: Option<f64>,
    /// List up to this many defective positions per row as D lines, the strongest (the row
    /// line has the full count; default 0: the object lines describe the defects)
    #[arg(long, default_value_t = 0)]
    pub max_defect_lines: u16,
    /// The channels' thresholds from a calibration file (`dmap calibrate`), the same
    /// integers as the calibration's (the spread channel off for a file before version 5);
    /// refused unless these scoring options are the ones it was made for
    #[arg(long, value_name = "CAL.json",
          conflicts_with_all = ["threshold", "power_threshold", "spread_threshold"])]
    pub calibration: Option<PathBuf>,
    /// Full scale of the detector: a sample at or above it flags its map saturated
    /// (header `fs`; 4095 for a 12-bit ADC)
    #[arg(long, value_name = "N", default_value_t = u16::MAX,
          value_parser = clap::value_parser!(u16).range(1..))]
    pub full_scale: u16,
    /// A runtime setting by its name, in its unit, as the board's command channel takes it
    /// (`dmap sensor set`) and its header shows it: `--set thr=4194304`, `--set mode=row`
    /// (repeatable, applied after the options above; the keys: `dmap sensor --help`)
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
}

impl Default for OutputArgs {
    fn default() -> Self {
        OutputArgs {
            threshold: None,
            power_threshold: None,
            spread_threshold: None,
            scores: false,
            max_defect_lines: 0,
            calibration: None,
            full_scale: u16::MAX,
            set: Vec::new(),
        }
    }
}
