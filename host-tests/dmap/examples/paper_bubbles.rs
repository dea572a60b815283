//! The paper-sim bubbles with all three channels on (docs/experiments.md,
//! "The paper-sim bubbles with the spread channel"): thresholds by the
//! board's tail rule on defect-free parts (seeds 11-13), the defective part
//! (seed 1) and unseen defect-free parts (seeds 21, 22) through the shipped
//! engine and labeller; the power channel's defect-free floor; and a sweep
//! of the bubble radius on a band of the same lens.
//!
//! `cd host-tests && cargo run --release -p dmap --example paper_bubbles`
//! (`-- sweep` skips the full parts and takes the thresholds from the
//! command line: `-- sweep CVM POWER SPREAD`, integers as printed).

use cvm_core::Object;
use cvm_core::calibration::Rule;
use cvm_sim::{Bubble, Config, Scan, Vec3, preset};
use dmap::halos::run::{around_truth, near_truth, peak_ratios};
use dmap::halos::{Thresholds, calibrate_scans, run_scan, scorer_for, simulate};

const CALIBRATION: [u64; 3] = [11, 12, 13];
const UNSEEN: [u64; 2] = [21, 22];
/// Radii of the sweep (mm).
const RADII: [f64; 7] = [0.083, 0.100, 0.117, 0.133, 0.150, 0.167, 0.200];
const SWEEP_SEEDS: [u64; 3] = [31, 32, 33];

fn part(defect_free: bool, seed: u64) -> Config {
    let mut c = preset::paper_sim(defect_free);
    c.receiver.spot = 0.3;
    c.seed = seed;
    c
}

/// The positions whose beam axis passes within `radius + footprint * waist`
/// of the bubble's centre (the truth mask's rule, the lens's small
/// deflection neglected).
fn truth(cfg: &Config, b: &Bubble) -> Vec<(usize, usize)> {
    let reach = b.radius + cfg.footprint * cfg.raster.waist;
    let (rows, cols) = (cfg.raster.rows, cfg.raster.cols);
    (0..rows * cols)
        .map(|p| (p / cols, p % cols))
        .filter(|&(r, c)| {
            let (x, y) = cfg.raster.position(r, c);
            (x - b.center.x).hypot(y - b.center.y) < reach
        })
        .collect()
}

/// Each bubble: found, and the channels' peaks over their thresholds.
fn report(
    cfg: &Config,
    scan: &Scan,
    objects: &[Object],
    scores: &[cvm_core::PositionScore],
    thr: Thresholds,
) -> usize {
    let mut found = 0;
    for b in &cfg.part.bubbles {
        let t = truth(cfg, b);
        let hit = objects.iter().any(|o| near_truth(o, &t));
        found += usize::from(hit);
        let r = peak_ratios(
            scores,
            scan.cols,
            around_truth(&t, scan.rows, scan.cols),
            thr,
        );
        let near = (0..scan.rows * scan.cols)
            .map(|p| {
                let (x, y) = cfg.raster.position(p / scan.cols, p % scan.cols);
                (x - b.center.x).hypot(y - b.center.y)
            })
            .fold(f64::MAX, f64::min);
        println!(
            "| {:.0} | ({:.1}, {:.1}) | {:.0} | {} | {:.2} / {:.2} / {:.2} |",
            b.radius * 1000.0,
            b.center.x,
            b.center.y,
            near * 1000.0,
            if hit { "yes" } else { "no" },
            r[0],
            r[1],
            r[2]
        );
    }
    let stray = objects
        .iter()
        .filter(|o| {
            !cfg.part
                .bubbles
                .iter()
                .any(|b| near_truth(o, &truth(cfg, b)))
        })
        .count();
    println!("\nobjects away from every bubble: {stray}");
    found
}

fn header() {
    println!(
        "| radius (µm) | centre (mm) | nearest beam (µm) | found | peak / threshold: CVM / power / spread |"
    );
    println!("|---|---|---|---|---|");
}

fn full() -> Thresholds {
    let t = std::time::Instant::now();
    let refs: Vec<Scan> = CALIBRATION
        .iter()
        .map(|&s| simulate(&part(true, s)))
        .collect();
    let (scorer, thr) = calibrate_scans(&refs, &Rule::DEFAULT);
    println!("thresholds (tail rule, seeds {CALIBRATION:?}): {thr:?}");
    println!(
        "  as values: CVM {:.4}, power contrast {:.4}, spread {:.4}",
        scorer.score_to_units(thr.cvm),
        thr.power as f64 / 32768.0,
        thr.spread as f64 / 65536.0
    );
    // The power channel's floor on the references.
    let mut p: Vec<u16> = Vec::new();
    for s in &refs {
        p.extend(
            run_scan(&scorer, s.rows, s.cols, &s.data, Thresholds::MEASURE)
                .scores
                .iter()
                .map(|s| s.pmag),
        );
    }
    p.sort_unstable();
    let q = |f: f64| p[((p.len() - 1) as f64 * f).round() as usize] as f64 / 32768.0;
    println!(
        "defect-free power magnitude (contrast), {} positions: median {:.4}, 99 % {:.4}, 99.9 % {:.4}, 99.99 % {:.4}, max {:.4}",
        p.len(),
        q(0.5),
        q(0.99),
        q(0.999),
        q(0.9999),
        q(1.0)
    );
    let cfg = part(false, 1);
    let scan = simulate(&cfg);
    let out = run_scan(&scorer, scan.rows, scan.cols, &scan.data, thr);
    println!("\ndefective part (seed 1), all three channels:\n");
    header();
    let found = report(&cfg, &scan, &out.objects, &out.scores, thr);
    println!("bubbles found: {found} of {}", cfg.part.bubbles.len());
    for s in UNSEEN {
        let scan = simulate(&part(true, s));
        let out = run_scan(&scorer, scan.rows, scan.cols, &scan.data, thr);
        println!(
            "unseen defect-free part, seed {s}: {} objects",
            out.objects.len()
        );
    }
    eprintln!("full parts: {:.0} s", t.elapsed().as_secs_f64());
    thr
}

/// A band of the lens, 12 rows through its centre, with one bubble of
/// every radius between four beams (236 µm from each, as the preset's) and
/// one on a beam, 4 mm apart.
fn sweep_part(seed: u64) -> Config {
    let mut cfg = part(true, seed);
    cfg.raster.rows = 12;
    let pitch = cfg.raster.pitch;
    let z = 5.0;
    for (k, &r) in RADII.iter().enumerate() {
        // x = m * pitch lies between two columns, y = 0 between rows 5 and 6.
        let m = 24.0 * k as f64 - 72.0;
        for (dx, dy) in [(0.0, 0.0), (0.5, 0.5)] {
            cfg.part.bubbles.push(Bubble {
                center: Vec3::new((m + 12.0 * dx * 2.0 + dx) * pitch, dy * pitch, z),
                radius: r,
                index: 1.0,
            });
        }
    }
    cfg
}

fn sweep(thr: Thresholds) {
    println!("\nradius sweep (12 x 300 band through the lens centre), thresholds above:\n");
    for seed in SWEEP_SEEDS {
        let cfg = sweep_part(seed);
        let scan = simulate(&cfg);
        let scorer = scorer_for(&scan);
        let out = run_scan(&scorer, scan.rows, scan.cols, &scan.data, thr);
        println!("\nseed {seed}:\n");
        header();
        report(&cfg, &scan, &out.objects, &out.scores, thr);
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let thr = if args.first().map(String::as_str) == Some("sweep") {
        let v: Vec<u32> = args[1..]
            .iter()
            .map(|a| a.parse().expect("integer threshold"))
            .collect();
        Thresholds {
            cvm: v[0],
            power: v[1],
            spread: v[2],
        }
    } else {
        full()
    };
    sweep(thr);
}
