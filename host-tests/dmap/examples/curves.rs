//! Detection curves for scattering defects (docs/experiments.md, "Detection
//! curves for scattering defects"): the fraction of halos found against
//! the scattered share (5-30 %) and the disc size (1-3 positions), at both
//! geometries of docs/spread-study.md, for each channel of the shipped
//! engine alone, CVM + power, all three, and EMD, every threshold set by
//! the board's tail rule (0.001 false positions per part) on eight
//! reference parts; false objects on twenty unseen defect-free parts.
//! Writes `docs/img/halo_curves_9x9.png` and `docs/img/halo_curves_15x15.png`.
//!
//! With `beam`, a halo's strength is the share of its strongest beam's
//! power that it takes (5, 7.5, 10 and 15 %; a disc of one position up
//! to half a pitch off the beams can take no more than 18 %), not the
//! share of the light crossing the disc, and the plots are
//! `halo_curves_beam_*.png`.
//!
//! `cd host-tests && cargo run --release -p dmap --example curves [-- beam]`

use std::path::Path;

use cvm_core::Scorer;
use cvm_core::calibration::histogram::{Histogram, bins};
use cvm_core::calibration::{Rule, rule};
use cvm_reference::{Emd, Ground, gradient_image};
use cvm_sim::Scan;
use dmap::halos::plot::{Chart, Series, draw};
use dmap::halos::{
    Geo, Halo, Thresholds, around, calibrate_scans, found, halo_part, halo_part_of_beam_power,
    near, peak_ratios, run_scan, simulate,
};
use dmap::objects::components;
use rayon::prelude::*;

const REFERENCE: [u64; 8] = [500, 501, 502, 503, 504, 505, 506, 507];
const FREE_PARTS: u64 = 20;
const DEFECT_PARTS: u64 = 5;
const RASTER: usize = 39;
/// Shares of the light crossing a disc that it scatters.
const SHARES: [f64; 4] = [0.05, 0.10, 0.20, 0.30];
/// Shares of its strongest beam's power that a halo takes (`beam`).
const POWERS: [f64; 4] = [0.05, 0.075, 0.10, 0.15];
const SIZES: [f64; 3] = [1.0, 2.0, 3.0];
/// One halo per quadrant.
const AT: [(usize, usize); 4] = [(9, 9), (9, 29), (29, 9), (29, 29)];
/// EMD magnitudes (cell units) in integers for the tail rule's histogram.
const EMD_SCALE: f64 = 65536.0;

const METHODS: [&str; 6] = ["CVM", "power", "spread", "CVM + power", "all three", "EMD"];
const COLOURS: [[u8; 3]; 6] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [148, 103, 189],
    [214, 39, 40],
    [127, 127, 127],
];

/// EMD gradient magnitudes of a scan, scaled to integers.
fn emd(scan: &Scan) -> Vec<u32> {
    let g = cvm_reference::Geometry::new(scan.j1, scan.j2).unwrap();
    let d = Emd::new(g, Ground::Euclid);
    let maps: Vec<f64> = scan.data.iter().map(|&v| f64::from(v)).collect();
    gradient_image(&maps, scan.rows, scan.cols, g, &d)
        .chunks_exact(3)
        .map(|v| (v[2] * EMD_SCALE).round().min(u32::MAX as f64) as u32)
        .collect()
}

/// The objects (8-connected components) of the positions at or above `thr`,
/// as boxes in the engine's object form.
fn emd_objects(mags: &[u32], thr: u32) -> Vec<cvm_core::Object> {
    let mask: Vec<bool> = mags.iter().map(|&m| m >= thr).collect();
    components(&mask, RASTER, RASTER)
        .into_iter()
        .map(|px| {
            let (rs, cs): (Vec<usize>, Vec<usize>) = px.iter().cloned().unzip();
            cvm_core::Object {
                row0: *rs.iter().min().unwrap() as u32,
                row1: *rs.iter().max().unwrap() as u32,
                col0: *cs.iter().min().unwrap() as u32,
                col1: *cs.iter().max().unwrap() as u32,
                area: px.len() as u32,
                ..cvm_core::Object::default()
            }
        })
        .collect()
}

/// Every method's objects on one scan, and the scores with all three on.
fn objects_of(
    scorer: &Scorer,
    scan: &Scan,
    thr: Thresholds,
    emd_thr: u32,
) -> (Vec<Vec<cvm_core::Object>>, Vec<cvm_core::PositionScore>) {
    let engine = [
        thr.cvm_only(),
        thr.power_only(),
        thr.spread_only(),
        thr.without_spread(),
        thr,
    ];
    let mut scores = Vec::new();
    let mut v: Vec<Vec<cvm_core::Object>> = engine
        .iter()
        .map(|&t| {
            let out = run_scan(scorer, scan.rows, scan.cols, &scan.data, t);
            if t == thr {
                scores = out.scores;
            }
            out.objects
        })
        .collect();
    v.push(emd_objects(&emd(scan), emd_thr));
    (v, scores)
}

struct Result {
    /// found[method][size][share]
    found: Vec<Vec<Vec<usize>>>,
    /// Objects on the unseen defect-free parts, and parts with any.
    false_objects: Vec<(usize, usize)>,
    /// Objects on the halo parts away from every halo.
    stray: Vec<usize>,
    /// worst[size][share]: with all three channels, the smallest over the
    /// instances of the largest channel's peak over its threshold.
    worst: Vec<Vec<f64>>,
}

/// How the strengths of a run are given.
#[derive(Clone, Copy, PartialEq)]
enum Strength {
    /// [`SHARES`] of the light crossing each disc.
    Crossing,
    /// [`POWERS`] of the strongest beam's power.
    Beam,
}

impl Strength {
    fn levels(self) -> [f64; 4] {
        match self {
            Strength::Crossing => SHARES,
            Strength::Beam => POWERS,
        }
    }
}

fn measure(geo: Geo, strength: Strength) -> Result {
    let levels = strength.levels();
    let t = std::time::Instant::now();
    let refs: Vec<Scan> = REFERENCE
        .iter()
        .map(|&k| simulate(&geo.part(k, RASTER)))
        .collect();
    let (scorer, thr) = calibrate_scans(&refs, &Rule::DEFAULT);
    let mut h = Box::new(Histogram::<{ bins(32) }>::new());
    for m in refs.par_iter().map(emd).collect::<Vec<_>>() {
        m.iter().for_each(|&v| h.add(v));
    }
    let emd_channel = rule::channel(&h, &Rule::DEFAULT, REFERENCE.len() as u16).unwrap();
    let emd_thr = emd_channel.threshold;
    println!(
        "\n## {}\n\nthresholds (tail rule, {} reference parts): CVM {:.4}, power contrast {:.4}, spread {:.4}, EMD {:.4} (integers {thr:?}, EMD {emd_thr})\n",
        geo.name(),
        REFERENCE.len(),
        scorer.score_to_units(thr.cvm),
        thr.power as f64 / 32768.0,
        thr.spread as f64 / 65536.0,
        emd_thr as f64 / EMD_SCALE,
    );
    let free: Vec<Vec<usize>> = (0..FREE_PARTS)
        .into_par_iter()
        .map(|k| {
            let scan = simulate(&geo.part(k, RASTER));
            objects_of(&scorer, &scan, thr, emd_thr)
                .0
                .iter()
                .map(Vec::len)
                .collect()
        })
        .collect();
    let false_objects = (0..METHODS.len())
        .map(|m| {
            let n: usize = free.iter().map(|f| f[m]).sum();
            (n, free.iter().filter(|f| f[m] > 0).count())
        })
        .collect();
    let jobs: Vec<(usize, u64)> = (0..SIZES.len())
        .flat_map(|si| (0..DEFECT_PARTS).map(move |k| (si, k)))
        .collect();
    // Per part: its size, its halos with their strength's index.
    type Run = (
        usize,
        Vec<(Halo, usize)>,
        (Vec<Vec<cvm_core::Object>>, Vec<cvm_core::PositionScore>),
    );
    let runs: Vec<Run> = jobs
        .par_iter()
        .map(|&(si, k)| {
            let id = FREE_PARTS + 100 * (si as u64 + 1) + k;
            let index: Vec<usize> = (0..AT.len()).map(|i| (i + k as usize) % 4).collect();
            let at: Vec<f64> = index.iter().map(|&i| levels[i]).collect();
            let (cfg, halos) = match strength {
                Strength::Crossing => halo_part(geo, id, RASTER, SIZES[si], &at, &AT),
                Strength::Beam => halo_part_of_beam_power(geo, id, RASTER, SIZES[si], &at, &AT)
                    .unwrap_or_else(|e| panic!("{}: {e}", geo.name())),
            };
            let scan = simulate(&cfg);
            let halos = halos.into_iter().zip(index).collect();
            (si, halos, objects_of(&scorer, &scan, thr, emd_thr))
        })
        .collect();
    let mut res = Result {
        found: vec![vec![vec![0; levels.len()]; SIZES.len()]; METHODS.len()],
        false_objects,
        stray: vec![0; METHODS.len()],
        worst: vec![vec![f64::MAX; levels.len()]; SIZES.len()],
    };
    for (si, halos, (objs, scores)) in &runs {
        for &(ref h, ai) in halos {
            let r = peak_ratios(scores, RASTER, around(h, RASTER, RASTER), thr);
            let best = r.iter().cloned().fold(0.0, f64::max);
            let w = &mut res.worst[*si][ai];
            *w = w.min(best);
        }
        for (m, o) in objs.iter().enumerate() {
            for &(ref h, ai) in halos {
                res.found[m][*si][ai] += usize::from(found(o, h));
            }
            res.stray[m] += o
                .iter()
                .filter(|o| !halos.iter().any(|(h, _)| near(o, h)))
                .count();
        }
    }
    eprintln!("{}: {:.0} s", geo.name(), t.elapsed().as_secs_f64());
    res
}

/// The strengths as column heads, in percent.
fn heads(strength: Strength) -> String {
    let v: Vec<String> = strength
        .levels()
        .iter()
        .map(|l| format!("{} %", l * 100.0))
        .collect();
    v.join(" | ")
}

fn table(geo: Geo, strength: Strength, r: &Result) {
    println!(
        "halos found of {DEFECT_PARTS} per cell, sizes 1 / 2 / 3 positions; false objects on {FREE_PARTS} unseen defect-free parts (parts with any); objects away from the halos on the {} halo parts\n",
        DEFECT_PARTS as usize * SIZES.len()
    );
    println!(
        "| {} | {} | false objects (parts) | stray |",
        geo.name(),
        heads(strength)
    );
    println!("|---|---|---|---|---|---|---|");
    for (m, name) in METHODS.iter().enumerate() {
        let cells: Vec<String> = (0..strength.levels().len())
            .map(|ai| {
                let v: Vec<String> = (0..SIZES.len())
                    .map(|si| r.found[m][si][ai].to_string())
                    .collect();
                v.join(" / ")
            })
            .collect();
        println!(
            "| {name} | {} | {} ({}) | {} |",
            cells.join(" | "),
            r.false_objects[m].0,
            r.false_objects[m].1,
            r.stray[m]
        );
    }
}

fn margins(geo: Geo, strength: Strength, r: &Result) {
    println!(
        "\nall three channels, the weakest halo of {DEFECT_PARTS}: its strongest channel's peak over that channel's threshold\n"
    );
    println!("| {} | {} |", geo.name(), heads(strength));
    println!("|---|---|---|---|---|");
    for (si, size) in SIZES.iter().enumerate() {
        let cells: Vec<String> = r.worst[si].iter().map(|w| format!("{w:.2}")).collect();
        println!("| {size} position(s) | {} |", cells.join(" | "));
    }
}

/// Each method's curve moved sideways by up to `reach` percentage points,
/// so that curves that coincide stay visible.
fn nudge(m: usize, reach: f64) -> f64 {
    (m as f64 - (METHODS.len() - 1) as f64 / 2.0) * reach / ((METHODS.len() - 1) as f64 / 2.0)
}

fn plot(geo: Geo, strength: Strength, r: &Result) {
    let levels = strength.levels();
    // Small beside the narrowest gap between two strengths (5 and 2.5 points).
    let reach = match strength {
        Strength::Crossing => 1.0,
        Strength::Beam => 0.25,
    };
    let charts: Vec<Chart> = SIZES
        .iter()
        .enumerate()
        .map(|(si, &size)| Chart {
            title: format!(
                "{} DISC OF {size} POSITION{}",
                geo.name().to_uppercase(),
                if si == 0 { "" } else { "S" }
            ),
            series: METHODS
                .iter()
                .enumerate()
                .map(|(m, name)| Series {
                    name: name.to_uppercase(),
                    colour: COLOURS[m],
                    points: levels
                        .iter()
                        .enumerate()
                        .map(|(ai, &s)| {
                            (
                                s * 100.0 + nudge(m, reach),
                                r.found[m][si][ai] as f64 / DEFECT_PARTS as f64,
                            )
                        })
                        .collect(),
                })
                .collect(),
        })
        .collect();
    let ticks: Vec<f64> = levels.iter().map(|l| l * 100.0).collect();
    let (range, label, file) = match strength {
        Strength::Crossing => ((2.0, 33.0), "SCATTERED SHARE %", "halo_curves"),
        Strength::Beam => ((3.0, 17.0), "SHARE OF THE BEAM POWER %", "halo_curves_beam"),
    };
    let im = draw(&charts, range, &ticks, label);
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../docs/img")
        .join(format!("{file}_{}.png", geo.name()));
    dmap::render::write_png(&path, &im).expect("write the plot");
    println!("\nwrote {}", path.display());
}

fn main() {
    let strength = match std::env::args().nth(1).as_deref() {
        None => Strength::Crossing,
        Some("beam") => Strength::Beam,
        Some(other) => {
            eprintln!("curves: unknown argument {other:?} (none, or `beam`)");
            std::process::exit(2);
        }
    };
    for geo in Geo::BOTH {
        let r = measure(geo, strength);
        table(geo, strength, &r);
        margins(geo, strength, &r);
        plot(geo, strength, &r);
    }
}
