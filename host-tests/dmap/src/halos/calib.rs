//! The three channels' thresholds from defect-free reference scans, by the
//! board's rule: the CVM and power channels through the `Calibrator`, the
//! spread channel through a histogram of its own under the same rule
//! (`calibration::rule::channel`), until the `Calibrator` takes it too.

use cvm_core::calibration::histogram::{Histogram, bins};
use cvm_core::calibration::{Calibrator, Rule, rule};
use cvm_core::spread::SPREAD_MAX;
use cvm_core::{PositionScore, Scorer, flags};

use super::run::run_scan;
use super::thresholds::Thresholds;

/// Bins of the spread magnitudes: below `2^17` (at most [`SPREAD_MAX`]).
const SPREAD_BINS: usize = bins(17);

/// Thresholds by `rule` from `refs`, each `(rows, cols, data)`.
pub fn calibrate(scorer: &Scorer, refs: &[(usize, usize, &[u16])], rule: &Rule) -> Thresholds {
    let mut cal = Box::new(Calibrator::new());
    let mut spread = Box::new(Histogram::<SPREAD_BINS>::new());
    for &(rows, cols, data) in refs {
        let scores = run_scan(scorer, rows, cols, data, Thresholds::MEASURE).scores;
        cal.add_row(&scores);
        add_spread(&mut spread, &scores);
        cal.end_scan();
    }
    let stats = cal.statistics(rule).expect("reference positions");
    let scans = cal.scans();
    let s = rule::channel(&spread, rule, scans).expect("reference positions");
    Thresholds {
        cvm: stats.cvm.threshold,
        power: stats.power.threshold,
        // Above every magnitude: the channel measures but never fires.
        spread: s.threshold.min(SPREAD_MAX + 1),
    }
}

/// The spread magnitudes of the positions with data, as the `Calibrator`
/// takes the other channels'.
fn add_spread(h: &mut Histogram<SPREAD_BINS>, scores: &[PositionScore]) {
    for s in scores {
        if s.flags & flags::NO_DATA == 0 {
            h.add(s.smag);
        }
    }
}
