//! The three channels' thresholds from defect-free reference scans, by the
//! board's rule and with the board's code: the `Calibrator` takes every
//! position's three magnitudes, as `calibrate N` does on live scans.

use cvm_core::Scorer;
use cvm_core::calibration::{Calibrator, Rule};
use cvm_core::spread::{SPREAD_MAX, SPREAD_OFF};

use super::run::run_scan;
use super::thresholds::Thresholds;

/// Thresholds by `rule` from `refs`, each `(rows, cols, data)`.
pub fn calibrate(scorer: &Scorer, refs: &[(usize, usize, &[u16])], rule: &Rule) -> Thresholds {
    let mut cal = Box::new(Calibrator::new());
    for &(rows, cols, data) in refs {
        let scores = run_scan(scorer, rows, cols, data, Thresholds::MEASURE).scores;
        cal.add_row(&scores);
        cal.end_scan();
    }
    let stats = cal.statistics(rule).expect("reference positions");
    Thresholds {
        cvm: stats.cvm.threshold,
        power: stats.power.threshold,
        // Off (above every magnitude) becomes a threshold nothing reaches
        // but that keeps the channel measuring, for the curves' ratios.
        spread: match stats.spread.threshold {
            SPREAD_OFF => SPREAD_MAX + 1,
            t => t,
        },
    }
}
