//! Whole-scan properties: determinism, truth mask, energy budget.

use cvm_sim::preset;

fn small(
    mut cfg: cvm_sim::Config,
    rows: usize,
    cols: usize,
    center: (f64, f64),
) -> cvm_sim::Config {
    cfg.raster.rows = rows;
    cfg.raster.cols = cols;
    cfg.raster.center = center;
    cfg.raster.rays = 64;
    cfg
}

/// [`small`] with a source of constant power, for tests that check map
/// counts against the optics.
fn steady(cfg: cvm_sim::Config, rows: usize, cols: usize, center: (f64, f64)) -> cvm_sim::Config {
    cvm_sim::Config {
        laser: cvm_sim::Laser::NONE,
        ..small(cfg, rows, cols, center)
    }
}

#[test]
fn scan_is_identical_for_one_and_two_threads() {
    let cfg = small(preset::paper_sim(false), 12, 12, (0.0, 0.0));
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| cvm_sim::simulate(&cfg, &|| {}).unwrap())
    };
    let a = run(1);
    let b = run(2);
    assert_eq!(a, b);
    let mut other = cfg.clone();
    other.seed = 2;
    assert_ne!(cvm_sim::simulate(&other, &|| {}).unwrap().data, a.data);
}

#[test]
fn truth_mask_marks_the_beams_that_touch_the_centre_bubbles() {
    // Centre group of paper-sim: bubbles of radius 0.083, 0.167, 0.334 mm at
    // x = -5, 0, 5 mm, y = 0. A 31x31 raster at 0.334 mm centred on (0, 0)
    // spans +-5.01 mm; with the 0.25 mm footprint, the bubble at x = 0
    // (r = 0.167) covers positions within 0.417 mm of it: |dx|, |dy| up to
    // one pitch and the diagonal (0.472 mm) excluded, i.e. a plus-shaped
    // 3x3 minus corners = 5 positions, up to the lens's sub-micron refraction shift.
    let cfg = small(preset::paper_sim(false), 31, 31, (0.0, 0.0));
    let mask = cvm_sim::truth_mask(&cfg);
    let at = |r: usize, c: usize| mask[r * 31 + c];
    assert!(at(15, 15) && at(14, 15) && at(16, 15) && at(15, 14) && at(15, 16));
    assert!(!at(14, 14) && !at(16, 16) && !at(15, 17) && !at(13, 15));
    let count_near_centre = (12..19)
        .flat_map(|r| (12..19).map(move |c| (r, c)))
        .filter(|&(r, c)| at(r, c))
        .count();
    assert_eq!(count_near_centre, 5);
    assert!(
        cvm_sim::truth_mask(&small(preset::paper_sim(true), 31, 31, (0.0, 0.0)))
            .iter()
            .all(|&t| !t)
    );
}

#[test]
fn prototype_truth_regions_have_the_defect_sizes() {
    // 2.8 mm patch + 2 x 0.25 mm footprint = 3.3 mm -> 9 or 10 positions of 0.334 mm;
    // 4 mm + 0.5 = 4.5 mm -> 13 or 14 positions.
    let cfg = preset::prototype(false);
    let mask = cvm_sim::truth_mask(&cfg);
    let n = 39;
    let cols_hit = |rows: std::ops::Range<usize>| {
        (0..n)
            .filter(|&c| rows.clone().any(|r| mask[r * n + c]))
            .count()
    };
    let upper = cols_hit(0..19);
    let lower = cols_hit(20..39);
    assert!((9..=10).contains(&upper), "{upper}");
    assert!((13..=14).contains(&lower), "{lower}");
}

#[test]
fn defect_free_lens_scan_is_one_bright_cell_per_beam() {
    // Away from cell boundaries, the whole beam lands on one detector cell:
    // (1 - 0.04)^2 of the photons, i.e. 1e5 * 0.9216 / 32 = 2880 counts, +- shot noise.
    let mut cfg = steady(preset::paper_sim(true), 3, 3, (0.0, 0.0));
    cfg.raster.rays = 256;
    let scan = cvm_sim::simulate(&cfg, &|| {}).unwrap();
    for pos in scan.data.chunks(225) {
        let peak = *pos.iter().max().unwrap();
        assert!((f64::from(peak) - 2880.0).abs() < 40.0, "{peak}");
        assert_eq!(pos[7 * 15 + 7], peak);
        let rest: u32 = pos.iter().map(|&v| u32::from(v)).sum::<u32>() - u32::from(peak);
        // Read noise of 20 e- = 0.625 counts, rounded and clipped at 0: about
        // P(N > 0.8 sigma) = 21 % of the 224 dark cells read 1, so ~47 in all.
        assert!(rest < 100, "{rest}");
    }
    let b = scan.budget;
    assert!((b.total() - 9.0).abs() < 1e-6, "{b:?}");
}

#[test]
fn large_bubble_scatters_the_beam_off_the_detector() {
    // r = 0.334 mm > waist 0.25 mm: almost every ray meets the bubble, which
    // acts as a strong diverging ball lens, so little light stays on the array.
    let mut cfg = small(preset::paper_sim(false), 1, 1, (5.0, 0.0));
    cfg.raster.rays = 512;
    let hit = cvm_sim::simulate(&cfg, &|| {}).unwrap();
    cfg.part.bubbles.clear();
    let clean = cvm_sim::simulate(&cfg, &|| {}).unwrap();
    let sum = |d: &[u16]| d.iter().map(|&v| u64::from(v)).sum::<u64>();
    assert!(
        sum(&hit.data) * 5 < sum(&clean.data),
        "{} vs {}",
        sum(&hit.data),
        sum(&clean.data)
    );
    let b = hit.budget;
    assert!(
        b.aperture + b.off_detector + b.backward + b.edge > 0.8,
        "{b:?}"
    );
    assert!((b.total() - 1.0).abs() < 1e-6);
    assert!(hit.truth[0] && !clean.truth[0]);
}

#[test]
fn small_bubble_removes_the_power_falling_on_its_disc() {
    // r = 0.083 mm at x = -5 mm: the fraction of a Gaussian beam (waist
    // w = 0.25 mm) on the bubble's disc is 1 - exp(-2 r^2 / w^2) = 0.198,
    // and all of it is scattered far off the centre cell (the bubble is a
    // diverging ball lens of focal length about -r). The centre cell keeps
    // 2880 * (1 - 0.198) = 2310 counts.
    let mut cfg = steady(preset::paper_sim(false), 1, 1, (-5.0, 0.0));
    cfg.raster.rays = 4096;
    let hit = cvm_sim::simulate(&cfg, &|| {}).unwrap();
    let lost = 1.0 - (-2.0 * 0.083f64.powi(2) / 0.25f64.powi(2)).exp();
    let expect = 1e5 * 0.96 * 0.96 / 32.0 * (1.0 - lost);
    let got = f64::from(hit.data[7 * 15 + 7]);
    assert!((got - expect).abs() < 0.02 * expect, "{got} vs {expect}");
}

/// Per position: total counts and the count-weighted centroid (cells).
fn sums_and_centroids(scan: &cvm_sim::Scan) -> Vec<(f64, f64, f64)> {
    let n = scan.j1 * scan.j2;
    scan.data
        .chunks(n)
        .map(|m| {
            let (mut s, mut a, mut b) = (0.0, 0.0, 0.0);
            for (k, &v) in m.iter().enumerate() {
                let v = f64::from(v);
                s += v;
                a += v * (k / scan.j2) as f64;
                b += v * (k % scan.j2) as f64;
            }
            (s, a / s.max(1.0), b / s.max(1.0))
        })
        .collect()
}

#[test]
fn defect_free_part_differs_only_by_defects_and_noise() {
    // 18x18 positions over the upper-left rough patch of the prototype.
    let cfg = small(preset::prototype(false), 18, 18, (-3.0, 3.0));
    let defective = cvm_sim::simulate(&cfg, &|| {}).unwrap();
    let free_cfg = small(preset::prototype(true), 18, 18, (-3.0, 3.0));
    let free = cvm_sim::simulate(&free_cfg, &|| {}).unwrap();
    assert!(free.truth.iter().all(|&t| !t));
    // Same seed: a beam that reaches no defect reads the same counts,
    // laser noise included. Away from the truth mask (two positions: the
    // rays extend to two waists, 1.5 pitches) most maps are bit-identical;
    // the rest got light that an internal reflection carried onto the
    // patch, which changes a few counts (and the order of later draws).
    let (rows, cols) = (18usize, 18usize);
    let (a, b) = (sums_and_centroids(&defective), sums_and_centroids(&free));
    let (mut far, mut same) = (0, 0);
    for r in 0..rows {
        for c in 0..cols {
            let near = (r.saturating_sub(2)..=(r + 2).min(rows - 1)).any(|rr| {
                (c.saturating_sub(2)..=(c + 2).min(cols - 1))
                    .any(|cc| defective.truth[rr * cols + cc])
            });
            if !near {
                let i = r * cols + c;
                far += 1;
                same += usize::from(
                    defective.data[i * 81..(i + 1) * 81] == free.data[i * 81..(i + 1) * 81],
                );
                assert!((a[i].0 / b[i].0 - 1.0).abs() < 0.01, "({r},{c})");
                assert!((a[i].1 - b[i].1).abs() < 0.02 && (a[i].2 - b[i].2).abs() < 0.02);
            }
        }
    }
    assert!(far > 40 && same * 4 > far * 3, "{same} of {far}");
    // Another seed: the same part, other noise. Totals agree to the laser's
    // 1 % rms, 2 % drift and shot noise; spots land at the same place.
    let other = cvm_sim::simulate(
        &cvm_sim::Config {
            seed: 7,
            ..free_cfg.clone()
        },
        &|| {},
    )
    .unwrap();
    assert_ne!(other.data, free.data);
    for (a, b) in sums_and_centroids(&free)
        .iter()
        .zip(sums_and_centroids(&other))
    {
        assert!((a.0 / b.0 - 1.0).abs() < 0.1, "{a:?} {b:?}");
        assert!(
            (a.1 - b.1).abs() < 0.05 && (a.2 - b.2).abs() < 0.05,
            "{a:?} {b:?}"
        );
    }
}

#[test]
fn laser_power_scales_each_map() {
    // A defect-free 6x6 patch of paper-sim with 5 % fluctuation against a
    // steady source: each map's total follows the beam's power factor (to
    // its shot noise, about 0.35 % of the total).
    let steady_cfg = steady(preset::paper_sim(true), 6, 6, (10.0, 10.0));
    let laser = cvm_sim::Laser {
        rms: 0.05,
        drift: 0.02,
    };
    let noisy_cfg = cvm_sim::Config {
        laser,
        ..steady_cfg.clone()
    };
    let a = sums_and_centroids(&cvm_sim::simulate(&steady_cfg, &|| {}).unwrap());
    let b = sums_and_centroids(&cvm_sim::simulate(&noisy_cfg, &|| {}).unwrap());
    let mut spread = 0.0;
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        let f = laser.factor(noisy_cfg.seed, 6, 6, i / 6, i % 6);
        assert!(
            (y.0 / x.0 / f - 1.0).abs() < 0.015,
            "{i}: {} vs {f}",
            y.0 / x.0
        );
        spread += (f - 1.0).powi(2);
    }
    // The factors do vary (at 5 % rms) and default presets have laser noise.
    assert!((spread / 36.0).sqrt() > 0.02);
    assert_eq!(preset::prototype(false).laser, preset::default_laser());
    assert_eq!(preset::paper_sim(true).laser, preset::default_laser());
}
