//! Pooled decisions for one-position defects (docs/experiments.md, "Pooled
//! decisions for one-position defects"): absorbers taking 5-25 % and halos
//! taking 2-10 % of their strongest beam's power, on a beam and half-way
//! between two, on the halo parts of both geometries with 2 % per-beam
//! laser power jitter. Found or not by
//!
//! - the shipped decisions (`cvm_core::Engine` + `Objects`, all three
//!   channels, thresholds by the board's tail rule on eight reference parts);
//! - an ideal detector that knows the defect's footprint (the share each
//!   beam loses): the matched statistic of the power lost (absorbers) or of
//!   `q` gained (halos) against the surroundings, thresholded by the same
//!   rule on the same statistic over every position of the reference parts;
//! - the pooled candidates in the three-row window (`dmap::halos::pooled`):
//!   the position alone against its 8 neighbours, and the largest over
//!   that, the pairs and the 2x2 quads holding it, on `P` and on `q`;
//!
//! with false objects on twenty unseen defect-free parts per geometry.
//!
//! `cd host-tests && cargo run --release -p dmap --example pooled`

use cvm_core::calibration::Rule;
use cvm_sim::Scan;
use cvm_sim::scan::beam_map;
use dmap::halos::pooled::{
    Channel, Footprints, Kind, Place, Placed, Quantities, defect_part, layout, matched,
    matched_all, pattern, pooled, quantities, tail_threshold,
};
use dmap::halos::run::{around_truth, near_truth};
use dmap::halos::{Geo, calibrate_scans, found, run_scan, simulate};
use dmap::objects::components;
use rayon::prelude::*;

const REFERENCE: [u64; 8] = [500, 501, 502, 503, 504, 505, 506, 507];
const FREE_PARTS: u64 = 20;
const RASTER: usize = 39;
/// Per-beam laser power jitter, relative rms.
const RMS: f64 = 0.02;
/// Defects per cell (kind, strength, on a beam or between two).
const N: usize = 20;
const ABSORBERS: [f64; 6] = [0.05, 0.10, 0.125, 0.15, 0.20, 0.25];
const HALOS: [f64; 6] = [0.02, 0.04, 0.05, 0.06, 0.08, 0.10];

const METHODS: [&str; 5] = [
    "shipped (all three)",
    "ideal (known footprint)",
    "pooled: position alone",
    "pooled: + pairs, quads",
    "shipped + pooled",
];

fn good(geo: Geo, k: u64) -> Scan {
    let mut cfg = geo.part(k, RASTER);
    cfg.laser.rms = RMS;
    simulate(&cfg)
}

/// The pooled thresholds of one footprint set: power, spread.
type Pair = [f64; 2];

/// Positions where either pooled channel fires.
fn fires(qs: &Quantities, set: Footprints, thr: Pair) -> Vec<bool> {
    let p = pooled(qs, Channel::Power, set);
    let s = pooled(qs, Channel::Spread, set);
    p.iter()
        .zip(&s)
        .map(|(&a, &b)| a >= thr[0] || b >= thr[1])
        .collect()
}

/// Each pooled channel's largest value over its threshold among `at`.
fn ratio(qs: &Quantities, set: Footprints, thr: Pair, at: &[(usize, usize)]) -> f64 {
    let mut best = 0.0f64;
    for (i, ch) in Channel::BOTH.into_iter().enumerate() {
        let v = pooled(qs, ch, set);
        for &(r, c) in at {
            best = best.max(v[r * qs.cols + c] / thr[i]);
        }
    }
    best
}

fn channel_of(kind: Kind) -> Channel {
    match kind {
        Kind::Absorber => Channel::Power,
        Kind::Halo => Channel::Spread,
    }
}

struct Cell {
    found: [usize; 5],
    /// The weakest instance's peak over its threshold: ideal, pooled (all).
    worst: [f64; 2],
}

fn measure(geo: Geo) {
    let t0 = std::time::Instant::now();
    let refs: Vec<Scan> = REFERENCE.par_iter().map(|&k| good(geo, k)).collect();
    let (scorer, thr) = calibrate_scans(&refs, &Rule::DEFAULT);
    let ref_qs: Vec<Quantities> = refs.iter().map(quantities).collect();
    let sets = [Footprints::Single, Footprints::All];
    let pooled_thr: Vec<Pair> = sets
        .iter()
        .map(|&set| {
            Channel::BOTH.map(|ch| {
                let v: Vec<Vec<f64>> = ref_qs.iter().map(|q| pooled(q, ch, set)).collect();
                tail_threshold(&v)
            })
        })
        .collect();
    println!(
        "\n## {}\n\nshipped thresholds (tail rule, {} reference parts, 2 % jitter): CVM {:.4}, power contrast {:.4}, spread {:.4}",
        geo.name(),
        REFERENCE.len(),
        scorer.score_to_units(thr.cvm),
        thr.power as f64 / 32768.0,
        thr.spread as f64 / 65536.0
    );
    for (set, t) in sets.iter().zip(&pooled_thr) {
        println!(
            "pooled thresholds, {set:?}: power {:.4}, spread {:.5}",
            t[0], t[1]
        );
    }
    // Noise of the quantities on the references (what the thresholds stand on).
    let rel: Vec<f64> = ref_qs
        .iter()
        .flat_map(|q| {
            let p = pooled(q, Channel::Power, Footprints::Single);
            p.into_iter().collect::<Vec<_>>()
        })
        .collect();
    let sd = (rel.iter().map(|v| v * v).sum::<f64>() / rel.len() as f64).sqrt();
    println!(
        "rms of the single-position power statistic on the references (about the relative noise of P): {sd:.4}"
    );

    // Unseen defect-free parts.
    let free: Vec<[usize; 4]> = (0..FREE_PARTS)
        .into_par_iter()
        .map(|k| {
            let scan = good(geo, k);
            let objs = run_scan(&scorer, scan.rows, scan.cols, &scan.data, thr).objects;
            let qs = quantities(&scan);
            let c: Vec<usize> = sets
                .iter()
                .zip(&pooled_thr)
                .map(|(&set, &t)| components(&fires(&qs, set, t), RASTER, RASTER).len())
                .collect();
            [objs.len(), c[0], c[1], objs.len() + c[1]]
        })
        .collect();
    let false_count = |i: usize| {
        (
            free.iter().map(|f| f[i]).sum::<usize>(),
            free.iter().filter(|f| f[i] > 0).count(),
        )
    };

    // Defect parts.
    let kinds: [(Kind, &[f64]); 2] = [(Kind::Absorber, &ABSORBERS), (Kind::Halo, &HALOS)];
    let parts = layout(&kinds, true, N);
    type Hit = (Placed, [bool; 5], [f64; 2]);
    let per_part: Vec<(Vec<Hit>, [usize; 3])> = parts
        .par_iter()
        .enumerate()
        .map(|(j, defects)| {
            let (cfg, placed) = defect_part(geo, 100 + j as u64, RASTER, RMS, defects)
                .unwrap_or_else(|e| panic!("{}: {e}", geo.name()));
            let scan = simulate(&cfg);
            let objs = run_scan(&scorer, scan.rows, scan.cols, &scan.data, thr).objects;
            let qs = quantities(&scan);
            let masks: Vec<Vec<bool>> = sets
                .iter()
                .zip(&pooled_thr)
                .map(|(&set, &t)| fires(&qs, set, t))
                .collect();
            let comps: Vec<Vec<Vec<(usize, usize)>>> = masks
                .iter()
                .map(|m| components(m, RASTER, RASTER))
                .collect();
            let truths: Vec<&[(usize, usize)]> = placed.iter().map(|p| &p.halo.truth[..]).collect();
            let stray_objects = objs
                .iter()
                .filter(|o| !truths.iter().any(|t| near_truth(o, t)))
                .count();
            let stray_pooled = |s: usize| {
                comps[s]
                    .iter()
                    .filter(|c| {
                        let near = |&(r, cc): &(usize, usize)| {
                            truths.iter().any(|t| {
                                t.iter()
                                    .any(|&(tr, tc)| tr.abs_diff(r) <= 1 && tc.abs_diff(cc) <= 1)
                            })
                        };
                        !c.iter().any(near)
                    })
                    .count()
            };
            let stray = [stray_objects, stray_pooled(0), stray_pooled(1)];
            let hits = placed
                .into_iter()
                .map(|p| {
                    let before = found(&objs, &p.halo);
                    let at = around_truth(&p.halo.truth, RASTER, RASTER);
                    let pooled_found: Vec<bool> = masks
                        .iter()
                        .map(|m| at.iter().any(|&(r, c)| m[r * RASTER + c]))
                        .collect();
                    let ch = channel_of(p.defect.kind);
                    let pat = pattern(&p);
                    let null: Vec<Vec<f64>> =
                        ref_qs.iter().map(|q| matched_all(q, ch, &pat)).collect();
                    let t_ideal = tail_threshold(&null);
                    let v = matched(&qs, ch, &pat, p.beams[0].0).unwrap_or(0.0);
                    let ideal = v >= t_ideal;
                    let r_pooled = ratio(&qs, Footprints::All, pooled_thr[1], &at);
                    (
                        p,
                        [
                            before,
                            ideal,
                            pooled_found[0],
                            pooled_found[1],
                            before || pooled_found[1],
                        ],
                        [v / t_ideal, r_pooled],
                    )
                })
                .collect();
            (hits, stray)
        })
        .collect();
    let mut stray = [0usize; 3];
    for (_, s) in &per_part {
        for (a, b) in stray.iter_mut().zip(s) {
            *a += b;
        }
    }

    for (kind, levels) in kinds {
        let name = match kind {
            Kind::Absorber => "absorbers",
            Kind::Halo => "halos",
        };
        let heads: Vec<String> = levels.iter().map(|l| format!("{} %", l * 100.0)).collect();
        println!(
            "\n{} {name}, found of {N} per strength (share of the strongest beam's power): on a beam / half-way between two\n",
            geo.name()
        );
        println!("| {} {name} | {} |", geo.name(), heads.join(" | "));
        println!("|---|{}", "---|".repeat(levels.len()));
        let mut cells: Vec<Vec<Cell>> = Vec::new();
        for between in [false, true] {
            cells.push(
                levels
                    .iter()
                    .map(|&l| {
                        let mut c = Cell {
                            found: [0; 5],
                            worst: [f64::MAX; 2],
                        };
                        for (p, f, w) in per_part.iter().flat_map(|x| &x.0) {
                            let d = p.defect;
                            if d.kind == kind
                                && d.power == l
                                && (d.place != Place::Centred) == between
                            {
                                for (n, &hit) in c.found.iter_mut().zip(f) {
                                    *n += usize::from(hit);
                                }
                                for (low, &v) in c.worst.iter_mut().zip(w) {
                                    *low = low.min(v);
                                }
                            }
                        }
                        c
                    })
                    .collect(),
            );
        }
        for (m, method) in METHODS.iter().enumerate() {
            let row: Vec<String> = (0..levels.len())
                .map(|i| format!("{} / {}", cells[0][i].found[m], cells[1][i].found[m]))
                .collect();
            println!("| {method} | {} |", row.join(" | "));
        }
        println!(
            "\nthe weakest instance's peak over its threshold, on a beam / between: ideal; pooled (+ pairs, quads)\n"
        );
        for m in 0..2 {
            let row: Vec<String> = (0..levels.len())
                .map(|i| format!("{:.2} / {:.2}", cells[0][i].worst[m], cells[1][i].worst[m]))
                .collect();
            println!("| {} | {} |", ["ideal", "pooled"][m], row.join(" | "));
        }
    }
    let labels = [
        "shipped",
        "pooled: position alone",
        "pooled: + pairs, quads",
        "shipped + pooled",
    ];
    println!("\nfalse objects on {FREE_PARTS} unseen defect-free parts (parts with any):");
    for (i, l) in labels.iter().enumerate() {
        let (n, p) = false_count(i);
        println!("- {l}: {n} ({p})");
    }
    println!(
        "objects away from every defect on the {} defect parts: shipped {}, pooled alone {}, pooled + pairs, quads {}",
        parts.len(),
        stray[0],
        stray[1],
        stray[2]
    );
    eprintln!("{}: {:.0} s", geo.name(), t0.elapsed().as_secs_f64());
}

/// How much of the light the absorbers take still reaches the detector:
/// each beam an absorber takes from, traced with and without it (the same
/// rays), its detected power lost against the share of its rays that
/// cross the disc times what it puts on the detector without the absorber.
fn absorbed_light(geo: Geo) {
    let kinds: [(Kind, &[f64]); 1] = [(Kind::Absorber, &[0.25])];
    let defects = &layout(&kinds, true, 9)[0];
    let (cfg, placed) = defect_part(geo, 99, RASTER, RMS, defects).expect("absorbers");
    let mut clean = cfg.clone();
    clean.part.scatterers.clear();
    let (body, clean_body) = (cfg.part.body(), clean.part.body());
    let cells = cfg.receiver.j1 * cfg.receiver.j2;
    let detected = |c: &cvm_sim::Config, body: &cvm_sim::part::Body, (r, col): (usize, usize)| {
        let mut tracer = cvm_sim::Tracer::new(body, &c.receiver, c.trace);
        let mut rng = cvm_sim::rng::position_rng(c.seed, r, col);
        let (x, y) = c.raster.position(r, col);
        let mut map = vec![0.0; cells];
        beam_map(c, &mut tracer, x, y, &mut rng, &mut Vec::new(), &mut map).detected
    };
    // The share of a beam's rays that cross a disc: the rays `beam_map`
    // draws first from the position's generator, parallel to the axis.
    let crossing = |d: &cvm_sim::Scatterer, (r, col): (usize, usize)| {
        let mut rays = Vec::new();
        let mut rng = cvm_sim::rng::position_rng(cfg.seed, r, col);
        cvm_sim::beam::sample(cfg.raster.waist, cfg.raster.rays, &mut rng, &mut rays);
        let (x, y) = cfg.raster.position(r, col);
        d.share
            * rays
                .iter()
                .filter(|s| d.contains(x + s.0, y + s.1))
                .map(|s| s.2)
                .sum::<f64>()
    };
    let (mut lost, mut taken) = (0.0, 0.0);
    for p in &placed {
        for &(at, _) in &p.beams {
            let d0 = detected(&clean, &clean_body, at);
            lost += d0 - detected(&cfg, &body, at);
            taken += crossing(&p.halo.disc, at) * d0;
        }
    }
    println!(
        "\n{}: the beams the absorbers cross would put {taken:.3} beams of power on the detector through them; it receives {lost:.3} less: {:.1} % of the light they take reaches it",
        geo.name(),
        100.0 * (1.0 - lost / taken)
    );
}

fn main() {
    for geo in Geo::BOTH {
        absorbed_light(geo);
        measure(geo);
    }
}
