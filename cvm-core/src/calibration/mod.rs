//! Calibration on defect-free reference scans, in bounded memory and
//! integers only: the very code the board runs on live scans (`calibrate
//! N`, through the pipeline's hook, [`crate::Pipeline::attach_calibrator`])
//! and `dmap calibrate` runs on scan files, so both give the same
//! thresholds from the same scans.
//!
//! # The rules
//!
//! [`Rule::Spread`] (below) or [`Rule::Tail`] ([`tail`]: the threshold at
//! which an exponential fit of the channel's upper tail expects a target
//! rate of false positions per part, at least the maximum plus one).
//! Whichever sets the threshold, each [`Channel`] also carries the tail
//! fit, the false positions per part it predicts at the threshold, and the
//! smallest rise above the median the threshold detects.
//!
//! The spread rule: per channel, over the magnitudes of every position with data of every
//! reference scan (the CVM gradient magnitudes `mag` in the scorer's
//! `Q(q)` format, the power magnitudes `pmag` in `Q15`,
//! [`crate::channels::power`], and the spread magnitudes `smag` in `Q16`,
//! [`crate::channels::spread`]; dark, saturated, clipped and border positions
//! included, positions without a frame left out):
//!
//! ```text
//! thr = Q_p + ceil(k * 1.4826 * MAD) + 1        defaults p = 1, k = 3
//! ```
//!
//! where, with each magnitude replaced by the representative of its
//! histogram bin ([`histogram`]: itself below 256, else the middle of a
//! bin under 0.8 % of the value wide):
//!
//! - `Q_p` is the top of the bin holding the nearest-rank `p` quantile
//!   (rank `ceil(p n)`), capped at the exact maximum: for `p = 1` the
//!   maximum itself, so no reference position reaches `thr`;
//! - the median is the lower median of the representatives (rank
//!   `ceil(n / 2)`), the MAD the lower median of their absolute deviations
//!   from it;
//! - `k = K / 1000`, `p = P / 10^6` and 1.4826 `= 14826 / 10^4` are exact
//!   rationals ([`rule`]), the sum saturates at `u32::MAX`, a power
//!   threshold above [`power::POWER_MAX`] (reachable only next to a dark
//!   map) becomes [`power::POWER_OFF`] and a spread threshold above
//!   [`spread::SPREAD_MAX`] becomes [`spread::SPREAD_OFF`]: the channel
//!   is off.
//!
//! The spread magnitudes are measured only while the engine's spread
//! channel is on; the pipeline measures them (without deciding anything)
//! during every scan a calibration takes, so that a calibration with the
//! channel off still sets its threshold ([`crate::Pipeline::begin`]).
//!
//! A position is defective when a channel's magnitude reaches its `thr`.
//! This replaces the rule of exact medians over all magnitudes, which
//! needs every magnitude kept and sorted; the maximum, which sets the
//! threshold, stays exact (docs/experiments.md, "Calibration", compares
//! the two).
//!
//! # Memory and cost
//!
//! A [`Calibrator`] is [`CALIBRATOR_BYTES`] bytes (13 312 for the CVM
//! channel's 3 328 bins, 5 120 for the power channel's 1 280, 5 632 for
//! the spread channel's 1 408, and a few words), whatever the scan size or
//! the number of scans; a position costs three bin lookups (a
//! count-leading-zeros and shifts) and increments, and
//! [`Calibrator::finish`] one pass over the bins.

pub mod histogram;
mod result;
pub mod rule;
pub mod tail;

use crate::channels::flags;
use crate::channels::power;
use crate::channels::spread;
use crate::stream::PositionScore;
use histogram::{Histogram, bins};
pub use result::Calibration;
pub use rule::{Channel, Rule};

/// Bins of the CVM channel: 32-bit magnitudes.
pub const CVM_BINS: usize = bins(32);
/// Bins of the power channel: magnitudes below `2^16` (at most
/// [`power::POWER_MAX`]).
pub const POWER_BINS: usize = bins(16);
/// Bins of the spread channel: magnitudes below `2^17` (at most
/// [`spread::SPREAD_MAX`]).
pub const SPREAD_BINS: usize = bins(17);
/// Size of a [`Calibrator`].
pub const CALIBRATOR_BYTES: usize = core::mem::size_of::<Calibrator>();

/// Why a calibration has no result.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalibrationError {
    /// No position with data was taken (every beam of the scans lost).
    NoPositions,
    /// More than `u32::MAX` positions: the counts would wrap.
    TooManyPositions,
}

impl core::fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            CalibrationError::NoPositions => "no position with data",
            CalibrationError::TooManyPositions => "more positions than a calibration counts",
        })
    }
}

/// The three channels' statistics and thresholds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Statistics {
    /// Scans taken.
    pub scans: u16,
    pub cvm: Channel,
    /// The power channel; its `threshold` is already [`power::POWER_OFF`]
    /// when above [`power::POWER_MAX`].
    pub power: Channel,
    /// The spread channel; its `threshold` is already
    /// [`spread::SPREAD_OFF`] when above [`spread::SPREAD_MAX`].
    pub spread: Channel,
}

impl Statistics {
    /// The result as the board reports it, the thresholds set by `rule`.
    pub fn calibration(&self, rule: &Rule) -> Calibration {
        Calibration {
            scans: self.scans,
            positions: self.cvm.positions,
            threshold: self.cvm.threshold,
            power_threshold: self.power.threshold,
            median: self.cvm.median,
            mad: self.cvm.mad,
            power_median: self.power.median,
            power_mad: self.power.mad,
            spread_threshold: self.spread.threshold,
            spread_median: self.spread.median,
            spread_mad: self.spread.mad,
            rate_ppm: match *rule {
                // The rule takes 0 as 1.
                Rule::Tail { rate_ppm, .. } => rate_ppm.max(1),
                Rule::Spread { .. } => 0,
            },
        }
    }
}

/// Where a calibration on live scans stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Progress {
    /// Not calibrating.
    Idle,
    /// Starts at the next scan's begin.
    Armed { target: u16 },
    /// `taken` of `target` scans have ended.
    Running { taken: u16, target: u16 },
    /// The `target` scans have ended: [`Calibrator::finish`] has the
    /// result, and later scans are not taken.
    Done { taken: u16 },
}

/// The histograms of the three channels, and the state of a calibration on
/// live scans.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Calibrator {
    cvm: Histogram<CVM_BINS>,
    power: Histogram<POWER_BINS>,
    spread: Histogram<SPREAD_BINS>,
    scans: u16,
    progress: Progress,
}

impl Default for Calibrator {
    fn default() -> Self {
        Self::new()
    }
}

impl Calibrator {
    pub const fn new() -> Self {
        Calibrator {
            cvm: Histogram::new(),
            power: Histogram::new(),
            spread: Histogram::new(),
            scans: 0,
            progress: Progress::Idle,
        }
    }

    /// Forgets every position and scan taken (the progress stays).
    pub fn clear(&mut self) {
        self.cvm.clear();
        self.power.clear();
        self.spread.clear();
        self.scans = 0;
    }

    /// Takes one position's magnitudes.
    #[inline]
    pub fn add(&mut self, mag: u32, pmag: u16, smag: u32) {
        self.cvm.add(mag);
        self.power.add(pmag as u32);
        // At most SPREAD_MAX from the engine; a larger value would only
        // land in the top bin, never out of the histogram.
        self.spread.add(smag.min(spread::SPREAD_MAX));
    }

    /// Takes every position of `scores` that has data.
    pub fn add_row(&mut self, scores: &[PositionScore]) {
        for s in scores {
            if s.flags & flags::NO_DATA == 0 {
                self.add(s.mag, s.pmag, s.smag);
            }
        }
    }

    /// Counts one more scan taken (saturating).
    pub fn end_scan(&mut self) {
        self.scans = self.scans.saturating_add(1);
    }

    /// Takes `other`'s positions and scans as well.
    pub fn merge(&mut self, other: &Calibrator) {
        self.cvm.merge(&other.cvm);
        self.power.merge(&other.power);
        self.spread.merge(&other.spread);
        self.scans = self.scans.saturating_add(other.scans);
    }

    /// Scans taken.
    pub fn scans(&self) -> u16 {
        self.scans
    }

    /// Positions taken.
    pub fn positions(&self) -> u32 {
        self.cvm.len()
    }

    /// The CVM channel's histogram.
    pub fn cvm(&self) -> &Histogram<CVM_BINS> {
        &self.cvm
    }

    /// The power channel's histogram.
    pub fn power(&self) -> &Histogram<POWER_BINS> {
        &self.power
    }

    /// The spread channel's histogram.
    pub fn spread(&self) -> &Histogram<SPREAD_BINS> {
        &self.spread
    }

    /// The three channels' statistics and thresholds under `rule`.
    pub fn statistics(&self, rule: &Rule) -> Result<Statistics, CalibrationError> {
        if self.cvm.lost() || self.power.lost() || self.spread.lost() {
            return Err(CalibrationError::TooManyPositions);
        }
        let (Some(cvm), Some(mut power), Some(mut spread)) = (
            rule::channel(&self.cvm, rule, self.scans),
            rule::channel(&self.power, rule, self.scans),
            rule::channel(&self.spread, rule, self.scans),
        ) else {
            return Err(CalibrationError::NoPositions);
        };
        if power.threshold > power::POWER_MAX {
            // Off: no magnitude reaches it.
            power.threshold = power::POWER_OFF;
            power.rate_ppb = power.rate_ppb.map(|_| 0);
            power.min_strength = u32::MAX;
        }
        if spread.threshold > spread::SPREAD_MAX {
            spread.threshold = spread::SPREAD_OFF;
            spread.rate_ppb = spread.rate_ppb.map(|_| 0);
            spread.min_strength = u32::MAX;
        }
        Ok(Statistics {
            scans: self.scans,
            cvm,
            power,
            spread,
        })
    }

    /// The result as the board reports it (`calibrated` reply).
    pub fn finish(&self, rule: &Rule) -> Result<Calibration, CalibrationError> {
        self.statistics(rule).map(|s| s.calibration(rule))
    }

    /// Calibrates on the `scans` scans that begin next (0: stops
    /// calibrating). Arming again restarts.
    pub fn arm(&mut self, scans: u16) {
        self.progress = match scans {
            0 => Progress::Idle,
            target => Progress::Armed { target },
        };
    }

    /// Stops calibrating; what was taken stays until the next one starts.
    pub fn disarm(&mut self) {
        self.progress = Progress::Idle;
    }

    pub fn progress(&self) -> Progress {
        self.progress
    }

    /// The pipeline's hook at a scan's begin: an armed calibration starts
    /// from nothing.
    pub fn scan_begins(&mut self) {
        if let Progress::Armed { target } = self.progress {
            self.clear();
            self.progress = Progress::Running { taken: 0, target };
        }
    }

    /// The pipeline's hook for every finished row.
    #[inline]
    pub fn scan_row(&mut self, scores: &[PositionScore]) {
        if let Progress::Running { .. } = self.progress {
            self.add_row(scores);
        }
    }

    /// The pipeline's hook at a scan's end (after its last row).
    pub fn scan_ends(&mut self) {
        if let Progress::Running { target, .. } = self.progress {
            self.end_scan();
            let taken = self.scans;
            self.progress = if taken >= target {
                Progress::Done { taken }
            } else {
                Progress::Running { taken, target }
            };
        }
    }
}
