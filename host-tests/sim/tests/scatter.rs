//! Scattering discs: the halo's share and profile against hand-computed
//! Gaussian cell integrals, and the truth mask.

use cvm_sim::scan::beam_map;
use cvm_sim::*;
use rand::SeedableRng;

/// A flat plate seen by a 9x9 detector of 1 mm pixels behind a 50 mm lens,
/// the beam along the axis: every ray leaves parallel to the axis and lands
/// on the centre of the array, so the map is exact arithmetic.
fn plate(scatterers: Vec<Scatterer>) -> Config {
    let mut cfg = preset::prototype(true);
    cfg.part = Part {
        shape: Shape::Plate {
            thickness: 5.0,
            side: 50.0,
        },
        index: 1.5,
        bubbles: vec![],
        defects: vec![],
        scatterers,
    };
    cfg.receiver.aperture = 1e6;
    cfg.receiver.spot = 0.0;
    cfg.raster.rays = 4096;
    cfg.laser = Laser::NONE;
    cfg
}

fn noise_free_map(cfg: &Config, x: f64, y: f64) -> (Vec<f64>, Budget) {
    let body = cfg.part.body();
    let mut tracer = Tracer::new(&body, &cfg.receiver, cfg.trace);
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(4);
    let mut map = vec![0.0; 81];
    let budget = beam_map(cfg, &mut tracer, x, y, &mut rng, &mut Vec::new(), &mut map);
    (map, budget)
}

#[test]
fn halo_is_a_gaussian_of_the_scattered_share_around_the_spot() {
    // Plate, normal incidence: forward transmission with all internal
    // reflections (1 - R) / (1 + R) = 0.96 / 1.04 = 0.923077. A share
    // s = 0.2 of it goes into a halo of 0.06 rad rms, i.e. 3 mm = 3 pixels
    // in the focal plane; per axis, cell k (from -4 to 4) receives
    // Phi((k + 0.5) / 3) - Phi((k - 0.5) / 3): 0.132368 at k = 0, 0.054865
    // at k = 4, 0.866386 over the array. Hence centre cell
    // 0.923077 (0.8 + 0.2 * 0.132368^2) = 0.741696, corner
    // 0.923077 * 0.2 * 0.054865^2 = 0.000556, middle of an edge
    // 0.923077 * 0.2 * 0.054865 * 0.132368 = 0.001341, and
    // 0.923077 * 0.2 * (1 - 0.866386^2) = 0.046039 lost beside the array.
    let disc = Scatterer {
        x: 0.0,
        y: 0.0,
        radius: 2.0,
        share: 0.2,
        width: 0.06,
    };
    let (map, b) = noise_free_map(&plate(vec![disc]), 0.0, 0.0);
    let close = |got: f64, want: f64| (got - want).abs() < 2e-6;
    assert!(close(map[40], 0.741_696), "{}", map[40]);
    for corner in [0, 8, 72, 80] {
        assert!(close(map[corner], 0.000_556), "{}", map[corner]);
    }
    for edge in [4, 36, 44, 76] {
        assert!(close(map[edge], 0.001_341), "{}", map[edge]);
    }
    assert!(close(b.off_detector, 0.046_039), "{b:?}");
    assert!((b.total() - 1.0).abs() < 1e-9);

    // Without the disc all of it is on the centre cell.
    let (clean, b) = noise_free_map(&plate(vec![]), 0.0, 0.0);
    assert!(close(clean[40], 0.923_077), "{}", clean[40]);
    assert_eq!(clean.iter().filter(|&&v| v > 0.0).count(), 1);
    assert_eq!(b.off_detector, 0.0);
}

#[test]
fn a_disc_smaller_than_the_beam_scatters_the_share_of_its_light() {
    // Disc radius w / sqrt(2) with the beam centred on it: 1 - exp(-1) =
    // 0.632121 of the beam crosses it (the beam, cut at 2 w, misses
    // exp(-8) = 3.4e-4 of its tail), so the halo carries 0.3 * 0.632121 of
    // the transmitted power, and 1 - 0.866386^2 of that misses the array.
    let disc = Scatterer {
        x: 1.0,
        y: -1.0,
        radius: 0.25 / 2f64.sqrt(),
        share: 0.3,
        width: 0.06,
    };
    assert!((disc.centred_beam_share(0.25) - 0.3 * 0.632_121).abs() < 1e-6);
    let (_, b) = noise_free_map(&plate(vec![disc]), 1.0, -1.0);
    let halo = b.off_detector / (0.923_077 * (1.0 - 0.866_386f64.powi(2)));
    assert!(
        (halo / (0.3 * 0.632_121) - 1.0).abs() < 0.01,
        "halo share {halo}"
    );
    // A beam 1 mm away (four waists) does not touch it.
    let (_, b) = noise_free_map(&plate(vec![disc]), 2.0, -1.0);
    assert_eq!(b.off_detector, 0.0);
}

#[test]
fn a_disc_changes_only_the_positions_it_touches_and_the_truth_marks_them() {
    // Prototype lens, 9x9 positions at 0.334 mm centred on (0, 0), a disc
    // three pitches across (radius 0.501 mm) centred there. The truth marks
    // positions within 0.501 + 0.25 = 0.751 mm: |(dr, dc)| <= sqrt(5)
    // pitches (0.747 mm), 21 positions, and each of their maps changes. The
    // beam, cut at 2 w = 0.5 mm, cannot reach the disc from 1.001 mm or
    // more: from three pitches straight (1.002 mm) or further, those maps
    // are the same, draw for draw, as without the disc, since the halo
    // takes no random numbers. (The four diagonal positions at 0.945 mm
    // may catch a ray's tail.)
    let mut cfg = preset::prototype(false);
    cfg.part.defects.clear();
    cfg.raster.rows = 9;
    cfg.raster.cols = 9;
    cfg.raster.rays = 64;
    let clean = simulate(&cfg, &|| {}).unwrap();
    cfg.part.scatterers = vec![Scatterer::across(0.0, 0.0, 3.0, 0.334, 0.3, 0.06)];
    let hit = simulate(&cfg, &|| {}).unwrap();
    let (mut marked, mut same) = (0, 0);
    for r in 0..9 {
        for c in 0..9 {
            let p = r * 9 + c;
            let (dr, dc) = (r as i64 - 4, c as i64 - 4);
            let d2 = dr * dr + dc * dc;
            let (a, b) = (&clean.data[p * 81..][..81], &hit.data[p * 81..][..81]);
            assert_eq!(hit.truth[p], d2 <= 5, "truth at ({r}, {c})");
            assert!(!clean.truth[p]);
            if d2 <= 5 {
                marked += 1;
                assert_ne!(a, b, "({r}, {c})");
            } else if d2 >= 9 {
                same += 1;
                assert_eq!(a, b, "({r}, {c})");
            }
        }
    }
    assert_eq!((marked, same), (21, 81 - 25));
    // The centre beam lies wholly on the disc: its peak cell loses about
    // 30 % and more than half of that reappears elsewhere on the array.
    let centre = &hit.data[40 * 81..][..81];
    let before = &clean.data[40 * 81..][..81];
    let peak = (0..81).max_by_key(|&j| before[j]).unwrap();
    let ratio = f64::from(centre[peak]) / f64::from(before[peak]);
    assert!((ratio - 0.72).abs() < 0.04, "{ratio}");
    let sum = |m: &[u16]| m.iter().map(|&v| f64::from(v)).sum::<f64>();
    let kept = sum(centre) / sum(before);
    assert!(kept > 0.85 && kept < 0.97, "{kept}");

    // A disc that scatters nothing leaves the scan as it was.
    cfg.part.scatterers[0].share = 0.0;
    assert_eq!(simulate(&cfg, &|| {}).unwrap().data, clean.data);
}

#[test]
fn halo_is_centred_where_the_deflected_spot_lands() {
    // Prototype lens, beam 3 mm off its axis, so the spot lands off the
    // array's centre. The rays leaving the clean part give each ray's
    // focal-plane point (u, v) = f (dx, dy) / dz and weight w; a disc
    // covering the whole beam sends s = 0.25 of every ray into a halo of
    // 0.04 rad, 2 mm at f = 50 mm, combined with the 0.5 mm spot. So the
    // map is the clean map times 1 - s plus, for every ray,
    // w s gy(a) gx(b): Gaussian cell integrals around (u, -v).
    let mut cfg = preset::prototype(true);
    cfg.raster.rays = 1024;
    cfg.laser = Laser::NONE;
    let (x, y) = (3.0, 0.5);
    let body = cfg.part.body();
    let mut tracer = Tracer::new(&body, &cfg.receiver, cfg.trace);
    tracer.exits = Some(Vec::new());
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(4);
    let mut unused = vec![0.0; 81];
    beam_map(
        &cfg,
        &mut tracer,
        x,
        y,
        &mut rng,
        &mut Vec::new(),
        &mut unused,
    );
    let exits = tracer.exits.take().unwrap();
    let f = cfg.receiver.focal;
    let landing: Vec<(f64, f64, f64)> = exits
        .iter()
        .map(|e| (f * e.1.x / e.1.z, f * e.1.y / e.1.z, e.2))
        .collect();
    let w: f64 = landing.iter().map(|l| l.2).sum();
    let u0 = landing.iter().map(|l| l.2 * l.0).sum::<f64>() / w;
    assert!(u0.abs() > 1.0, "the spot should land off centre, u0 = {u0}");

    let (clean, _) = noise_free_map(&cfg, x, y);
    cfg.part.scatterers = vec![Scatterer {
        x,
        y,
        radius: 2.0,
        share: 0.25,
        width: 0.04,
    }];
    let (hit, _) = noise_free_map(&cfg, x, y);
    let sigma = (f * 0.04f64).hypot(cfg.receiver.spot);
    let phi = |t: f64| 0.5 * (1.0 + cvm_sim::trace::erf(t / sigma / 2f64.sqrt()));
    let cell = |k: usize, centre: f64| {
        let lo = (k as f64 - 4.5) * cfg.receiver.pixel;
        phi(lo + cfg.receiver.pixel - centre) - phi(lo - centre)
    };
    let mut worst = 0.0f64;
    for a in 0..9 {
        for b in 0..9 {
            let halo = hit[a * 9 + b] - 0.75 * clean[a * 9 + b];
            let want: f64 = landing
                .iter()
                .map(|&(u, v, w)| w * 0.25 * cell(a, -v) * cell(b, u))
                .sum();
            worst = worst.max((halo - want).abs());
        }
    }
    assert!(worst < 1e-12, "largest difference {worst}");
}
