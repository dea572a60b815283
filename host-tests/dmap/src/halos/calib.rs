//! The three channels' thresholds from defect-free reference scans, by the
//! board's rule and with the board's code: the `Calibrator` takes every
//! position's three magnitudes, as `calibrate N` does on live scans.

use cvm_core::calibration::{Calibrator, Rule};
use cvm_core::spread::{SPREAD_MAX, SPREAD_OFF};
use cvm_core::{Config, Geometry, Scorer};
use cvm_sim::Scan;

use super::run::run_scan;
use super::thresholds::Thresholds;

/// The scan of a part the simulator accepts (every part drawn here is).
pub fn simulate(cfg: &cvm_sim::Config) -> Scan {
    cvm_sim::simulate(cfg, &|| {}).expect("valid part")
}

/// The firmware's default scorer (paper kernels) for `scan`'s detector.
pub fn scorer_for(scan: &Scan) -> Scorer {
    let g =
        Geometry::new(scan.j1 as u8, scan.j2 as u8).expect("a detector of 1 to 16 cells a side");
    Scorer::new(&Config::paper(g)).expect("paper kernels score every geometry")
}

/// The scorer of the reference scans `refs` (all of one detector) and the
/// thresholds `rule` sets on them.
pub fn calibrate_scans(refs: &[Scan], rule: &Rule) -> (Scorer, Thresholds) {
    let scorer = scorer_for(&refs[0]);
    let views: Vec<_> = refs.iter().map(|s| (s.rows, s.cols, &s.data[..])).collect();
    let thr = calibrate(&scorer, &views, rule);
    (scorer, thr)
}

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
