//! The measurements of docs/spread-study.md: the spread of defect-free maps
//! on parts the project's presets never scan, its response to scattering
//! halos, and how two decision rules separate the two.
//!
//! `cd host-tests && cargo run --release -p cvm-reference --example spread_study`
//!
//! Both geometries come from the simulator's presets with the part, the
//! raster's place on it and every seed changed: 9x9 from `prototype` (a
//! cylindrical lens, Gaussian detector spot of half a pixel), 15x15 from
//! `paper-sim` (a weak double-convex lens) with a spot of half a pixel, as
//! the experiments' main runs. Both keep the presets' 12-bit ADC, shot and
//! read noise and 1 % laser power noise with drift.

use cvm_reference::*;
use cvm_sim::rng::mix;
use cvm_sim::{Config, Scan, Scatterer, preset};

const RASTER: usize = 39;
const FREE_PARTS: u64 = 20;
const DEFECT_PARTS: u64 = 5;
/// Reference parts for today's calibration rule, apart from the others.
const CALIBRATION: [u64; 2] = [500, 501];
const SHARES: [f64; 4] = [0.05, 0.10, 0.20, 0.30];
const SIZES: [f64; 3] = [1.0, 2.0, 3.0];
/// Halo rms angle: the forward lobe of inclusions of about ten wavelengths.
const HALO: f64 = 0.06;

/// A number in [0, 1) from a hash.
fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64
}

#[derive(Clone, Copy)]
enum Geo {
    Nine,
    Fifteen,
}

impl Geo {
    fn name(self) -> &'static str {
        match self {
            Geo::Nine => "9x9",
            Geo::Fifteen => "15x15",
        }
    }

    /// Part `k` of this geometry, defect-free: its own lens and raster place.
    fn part(self, k: u64) -> Config {
        let h = mix(k ^ 0x5350_5245_4144); // "SPREAD"
        let (a, b) = (unit(h), unit(mix(h)));
        let mut cfg = match self {
            Geo::Nine => {
                let mut c = preset::prototype(true);
                // Radii 55-75 mm keep the spot on the array across the raster.
                if let cvm_sim::Shape::Cylindrical { radius, .. } = &mut c.part.shape {
                    *radius = 55.0 + 20.0 * a;
                }
                c.raster.center = (2.0 * b - 1.0, 6.0 * a - 3.0);
                c
            }
            Geo::Fifteen => {
                let mut c = preset::paper_sim(true);
                c.receiver.spot = 0.3;
                c.raster.center = (80.0 * a - 40.0, 80.0 * b - 40.0);
                c
            }
        };
        cfg.raster.rows = RASTER;
        cfg.raster.cols = RASTER;
        cfg.seed = 1000 + k;
        cfg
    }
}

/// One scan's per-position values.
struct Scores {
    spread: Vec<f64>,
    core: Vec<f64>,
    core5: Vec<f64>,
    cvm: Vec<f64>,
    power: Vec<f64>,
}

fn score(scan: &Scan) -> Scores {
    let g = Geometry::new(scan.j1, scan.j2).unwrap();
    let n = g.cells();
    let maps: Vec<f64> = scan.data.iter().map(|&v| f64::from(v)).collect();
    let spread = maps
        .chunks_exact(n)
        .map(|m| spread_moment(g, m).unwrap_or(0.0))
        .collect();
    let core = maps
        .chunks_exact(n)
        .map(|m| outside_core(g, m, 1).unwrap_or(0.0))
        .collect();
    let core5 = maps
        .chunks_exact(n)
        .map(|m| outside_core(g, m, 2).unwrap_or(0.0))
        .collect();
    let emb = CvmEmbedding::new(&CvmConfig::paper(g, PaperWeights::Uniform, None).unwrap());
    let cvm = gradient_image(&maps, scan.rows, scan.cols, g, &emb)
        .chunks_exact(3)
        .map(|v| v[2])
        .collect();
    let p: Vec<f64> = maps.chunks_exact(n).map(|m| m.iter().sum()).collect();
    let contrast = |a: f64, b: f64| {
        if a + b > 0.0 {
            (a - b).abs() / (a + b)
        } else {
            0.0
        }
    };
    let (rows, cols) = (scan.rows, scan.cols);
    let at = |r: usize, c: usize| p[r * cols + c];
    let mut power = Vec::with_capacity(rows * cols);
    for r in 0..rows {
        for c in 0..cols {
            let c0 = contrast(at(r, (c + 1).min(cols - 1)), at(r, c.saturating_sub(1)));
            let c1 = contrast(at((r + 1).min(rows - 1), c), at(r.saturating_sub(1), c));
            power.push(c0.hypot(c1));
        }
    }
    Scores {
        spread,
        core,
        core5,
        cvm,
        power,
    }
}

const RULES: [&str; 12] = [
    "spread, gradient",
    "spread, dev. 3x3",
    "spread, dev. 5x5",
    "spread, dev. 7x7",
    "outside 3x3 core, gradient",
    "outside 3x3 core, dev. 3x3",
    "outside 3x3 core, dev. 5x5",
    "outside 3x3 core, dev. 7x7",
    "outside 5x5 core, gradient",
    "outside 5x5 core, dev. 5x5",
    "CVM",
    "power",
];

fn rules(s: &Scores) -> Vec<Vec<f64>> {
    let (r, c) = (RASTER, RASTER);
    vec![
        neighbour_gradient(&s.spread, r, c),
        local_deviation(&s.spread, r, c, 1),
        local_deviation(&s.spread, r, c, 2),
        local_deviation(&s.spread, r, c, 3),
        neighbour_gradient(&s.core, r, c),
        local_deviation(&s.core, r, c, 1),
        local_deviation(&s.core, r, c, 2),
        local_deviation(&s.core, r, c, 3),
        neighbour_gradient(&s.core5, r, c),
        local_deviation(&s.core5, r, c, 2),
        s.cvm.clone(),
        s.power.clone(),
    ]
}

fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// The halos of defective part `k` (size `size` positions across): four,
/// one per quadrant, the shares rotated from part to part, each centre
/// moved off the beam positions by up to half a pitch.
fn halos(cfg: &Config, k: u64, size: f64) -> Vec<(Scatterer, f64)> {
    let pitch = cfg.raster.pitch;
    [(9, 9), (9, 29), (29, 9), (29, 29)]
        .iter()
        .enumerate()
        .map(|(i, &(row, col))| {
            let (x, y) = cfg.raster.position(row, col);
            let h = mix(k.wrapping_mul(31) ^ i as u64 ^ 0x4841_4C4F); // "HALO"
            let (dx, dy) = ((unit(h) - 0.5) * pitch, (unit(mix(h)) - 0.5) * pitch);
            let share = SHARES[(i + k as usize) % 4];
            (
                Scatterer::across(x + dx, y + dy, size, pitch, share, HALO),
                share,
            )
        })
        .collect()
}

fn main() {
    for geo in [Geo::Nine, Geo::Fifteen] {
        study(geo);
    }
    bubbles();
}

fn study(geo: Geo) {
    let t = std::time::Instant::now();
    // Defect-free parts: the distribution of the measure and of every rule.
    let mut spread_all = Vec::new();
    // Thresholds as `dmap calibrate` sets them today, on two reference
    // parts of their own: the maximum plus three robust standard
    // deviations (1.4826 MAD) of the reference scores.
    let mut thr = vec![0.0f64; RULES.len()];
    let mut reference = vec![Vec::new(); RULES.len()];
    for k in CALIBRATION {
        let scan = cvm_sim::simulate(&geo.part(k), &|| {}).unwrap();
        for (i, v) in rules(&score(&scan)).into_iter().enumerate() {
            reference[i].extend(v);
        }
    }
    for (i, v) in reference.iter_mut().enumerate() {
        let med = quantile(v, 0.5);
        let mut dev: Vec<f64> = v.iter().map(|x| (x - med).abs()).collect();
        thr[i] = quantile(v, 1.0) + 3.0 * 1.4826 * quantile(&mut dev, 0.5);
    }
    let mut false_positions = vec![0usize; RULES.len()];
    let mut false_parts = vec![0usize; RULES.len()];
    let mut free_max = vec![0.0f64; RULES.len()];
    let mut free_q999 = vec![Vec::new(); RULES.len()];
    let mut part_max = vec![Vec::new(); RULES.len()];
    for k in 0..FREE_PARTS {
        let scan = cvm_sim::simulate(&geo.part(k), &|| {}).unwrap();
        let s = score(&scan);
        spread_all.extend_from_slice(&s.spread);
        for (i, v) in rules(&s).into_iter().enumerate() {
            let m = v.iter().cloned().fold(0.0, f64::max);
            free_max[i] = free_max[i].max(m);
            let over = v.iter().filter(|&&x| x >= thr[i]).count();
            false_positions[i] += over;
            false_parts[i] += usize::from(over > 0);
            part_max[i].push(m);
            free_q999[i].extend(v);
        }
    }
    let n = spread_all.len() as f64;
    let mean = spread_all.iter().sum::<f64>() / n;
    let sd = (spread_all.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
    println!(
        "\n## {} ({} defect-free parts, {} positions)\n",
        geo.name(),
        FREE_PARTS,
        spread_all.len()
    );
    println!(
        "spread moment (cells²): mean {:.4}, sd {:.4}, min {:.4}, 1 % {:.4}, median {:.4}, 99 % {:.4}, max {:.4}\n",
        mean,
        sd,
        quantile(&mut spread_all, 0.0),
        quantile(&mut spread_all, 0.01),
        quantile(&mut spread_all, 0.5),
        quantile(&mut spread_all, 0.99),
        quantile(&mut spread_all, 1.0)
    );
    println!("| rule | 99.9 % | max | max per part, median / min |");
    println!("|---|---|---|---|");
    for (i, name) in RULES.iter().enumerate() {
        println!(
            "| {name} | {:.4} | {:.4} | {:.4} / {:.4} |",
            quantile(&mut free_q999[i], 0.999),
            free_max[i],
            quantile(&mut part_max[i], 0.5),
            quantile(&mut part_max[i], 0.0)
        );
    }

    // Defective parts: each halo's peak score (over the positions within
    // one pitch of its truth region) over the defect-free maximum.
    // sep[rule][size][share] = separations of the instances.
    let mut sep = vec![vec![vec![Vec::new(); SHARES.len()]; SIZES.len()]; RULES.len()];
    let mut found = vec![vec![vec![0usize; SHARES.len()]; SIZES.len()]; RULES.len()];
    let mut beam_share = vec![0.0; SIZES.len()];
    let mut spread_peak = vec![vec![Vec::new(); SHARES.len()]; SIZES.len()];
    for (si, &size) in SIZES.iter().enumerate() {
        for k in 0..DEFECT_PARTS {
            let id = FREE_PARTS + 100 * (si as u64 + 1) + k;
            let mut cfg = geo.part(id);
            let hs = halos(&cfg, id, size);
            beam_share[si] = hs[0].0.centred_beam_share(cfg.raster.waist) / hs[0].0.share;
            cfg.part.scatterers = hs.iter().map(|h| h.0).collect();
            let scan = cvm_sim::simulate(&cfg, &|| {}).unwrap();
            let s = score(&scan);
            let rv = rules(&s);
            for (h, share) in &hs {
                let reach = h.radius + cfg.footprint * cfg.raster.waist + cfg.raster.pitch;
                let region: Vec<usize> = (0..RASTER * RASTER)
                    .filter(|&p| {
                        let (x, y) = cfg.raster.position(p / RASTER, p % RASTER);
                        (x - h.x).hypot(y - h.y) < reach
                    })
                    .collect();
                let ai = SHARES.iter().position(|s| s == share).unwrap();
                for (ri, v) in rv.iter().enumerate() {
                    let peak = region.iter().map(|&p| v[p]).fold(0.0, f64::max);
                    sep[ri][si][ai].push(peak / free_max[ri]);
                    found[ri][si][ai] += usize::from(peak >= thr[ri]);
                }
                let sp = region.iter().map(|&p| s.spread[p]).fold(0.0, f64::max);
                spread_peak[si][ai].push(sp);
            }
        }
    }
    println!(
        "\nlargest spread moment on a halo (median of {DEFECT_PARTS}; defect-free median {:.4}):\n",
        quantile(&mut spread_all, 0.5)
    );
    println!("| size (positions) | centred beam's share of s | 5 % | 10 % | 20 % | 30 % |");
    println!("|---|---|---|---|---|---|");
    for (si, &size) in SIZES.iter().enumerate() {
        let cells: Vec<String> = (0..SHARES.len())
            .map(|ai| format!("{:.3}", quantile(&mut spread_peak[si][ai], 0.5)))
            .collect();
        println!("| {size} | {:.2} | {} |", beam_share[si], cells.join(" | "));
    }
    println!(
        "\nseparation: halo peak / defect-free maximum, worst (median) of {DEFECT_PARTS} halos; found = worst > 1\n"
    );
    println!("| rule | size | 5 % | 10 % | 20 % | 30 % |");
    println!("|---|---|---|---|---|---|");
    for (ri, name) in RULES.iter().enumerate() {
        for (si, &size) in SIZES.iter().enumerate() {
            let cells: Vec<String> = (0..SHARES.len())
                .map(|ai| {
                    let v = &mut sep[ri][si][ai];
                    let med = quantile(v, 0.5);
                    format!("{:.2} ({:.2})", v[0], med)
                })
                .collect();
            println!("| {name} | {size} | {} |", cells.join(" | "));
        }
    }
    println!(
        "\nthreshold of today's rule (max + 3 robust sd on two reference parts): false positions on the {FREE_PARTS} unseen parts (parts with any), halos found of {DEFECT_PARTS} per share, sizes 1 / 2 / 3\n"
    );
    println!(
        "| rule | threshold / unseen max | false positions (parts) | 5 % | 10 % | 20 % | 30 % |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (ri, name) in RULES.iter().enumerate() {
        let cells: Vec<String> = (0..SHARES.len())
            .map(|ai| {
                let f: Vec<String> = (0..SIZES.len())
                    .map(|si| found[ri][si][ai].to_string())
                    .collect();
                f.join(" / ")
            })
            .collect();
        println!(
            "| {name} | {:.2} | {} ({}) | {} |",
            thr[ri] / free_max[ri],
            false_positions[ri],
            false_parts[ri],
            cells.join(" | ")
        );
    }
    eprintln!("{}: {:.0} s", geo.name(), t.elapsed().as_secs_f64());
}

/// Do the paper-sim bubbles make a halo? One beam centred on a bubble of
/// each radius, noise-free, against the same beam without it.
fn bubbles() {
    use cvm_sim::scan::beam_map;
    use rand::SeedableRng;
    println!("\n## paper-sim bubbles, beam centred on the bubble, 300 µm spot, noise-free\n");
    println!(
        "| radius (µm) | power kept | spread (cells²) | outside the 3x3 core | defect-free: spread / outside core |"
    );
    println!("|---|---|---|---|---|");
    let mut cfg = preset::paper_sim(false);
    cfg.receiver.spot = 0.3;
    cfg.raster.rays = 16_384;
    let g = Geometry::new(15, 15).unwrap();
    let run = |cfg: &Config, x: f64, y: f64| {
        let body = cfg.part.body();
        let mut tracer = cvm_sim::Tracer::new(&body, &cfg.receiver, cfg.trace);
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(1);
        let mut map = vec![0.0; 225];
        beam_map(cfg, &mut tracer, x, y, &mut rng, &mut Vec::new(), &mut map);
        map
    };
    let clean_cfg = preset::paper_sim(true);
    let clean_cfg = Config {
        receiver: cfg.receiver,
        raster: cfg.raster,
        ..clean_cfg
    };
    for b in cfg.part.bubbles.iter().take(3) {
        let hit = run(&cfg, b.center.x, b.center.y);
        let clean = run(&clean_cfg, b.center.x, b.center.y);
        let (ph, pc): (f64, f64) = (hit.iter().sum(), clean.iter().sum());
        println!(
            "| {:.0} | {:.3} | {:.4} | {:.4} | {:.4} / {:.4} |",
            b.radius * 1000.0,
            ph / pc,
            spread_moment(g, &hit).unwrap(),
            outside_core(g, &hit, 1).unwrap(),
            spread_moment(g, &clean).unwrap(),
            outside_core(g, &clean, 1).unwrap()
        );
    }
}
