//! What a calibration hands on: the thresholds it set and the statistics
//! behind them, as the board's `calibrated` reply and `dmap calibrate` carry
//! them.

/// What a finished calibration found: the three channels' thresholds and
/// the statistics behind them, in the units of the header's `thr`
/// (magnitudes), `pthr` (power magnitudes, `Q15`) and of the `sthr`
/// setting (spread magnitudes, `Q16`). [`super::Calibrator::finish`]
/// makes it, on the board and in `dmap calibrate` alike.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Calibration {
    /// Scans it took.
    pub scans: u16,
    /// Positions with data it took them from.
    pub positions: u32,
    /// The CVM threshold the board's rule set (`Rule::DEFAULT`, the tail
    /// rule: [`super`]).
    pub threshold: u32,
    /// The same on the power magnitudes, or `POWER_OFF` when above every
    /// power magnitude.
    pub power_threshold: u32,
    /// The same on the spread magnitudes, or `SPREAD_OFF` when above
    /// every spread magnitude.
    pub spread_threshold: u32,
    /// Median and median absolute deviation of the magnitudes, each the
    /// lower median of the magnitudes' histogram bins (exact below 256,
    /// else the middle of a bin under 0.8 % wide; see
    /// [`super`]).
    pub median: u32,
    pub mad: u32,
    /// The same of the power magnitudes.
    pub power_median: u32,
    pub power_mad: u32,
    /// The same of the spread magnitudes.
    pub spread_median: u32,
    pub spread_mad: u32,
    /// The target the tail rule set the thresholds for, in false positions
    /// per million parts (the `calibrate` request's, 1000 by default); 0
    /// when another rule set them (only `dmap calibrate --rule spread`).
    pub rate_ppm: u32,
}
