//! The ray model against hand-computed optics.

use cvm_sim::preset;
use cvm_sim::*;
use rand::SeedableRng;

fn receiver() -> Receiver {
    Receiver {
        focal: 50.0,
        distance: 100.0,
        aperture: 1e6,
        j1: 15,
        j2: 15,
        pixel: 0.5,
        spot: 0.0,
    }
}

fn part(shape: Shape, bubbles: Vec<Bubble>) -> Part {
    Part {
        shape,
        index: 1.5,
        bubbles,
        defects: vec![],
        scatterers: vec![],
    }
}

/// Trace one ray from z = -1 and return the rays leaving the part forward
/// plus the power budget.
fn exits(
    part: &Part,
    p: Vec3,
    d: Vec3,
    interaction: Interaction,
) -> (Vec<(Vec3, Vec3, f64)>, Budget) {
    let body = part.body();
    let rx = receiver();
    let mut t = Tracer::new(
        &body,
        &rx,
        TraceOptions {
            interaction,
            ..TraceOptions::default()
        },
    );
    t.exits = Some(Vec::new());
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(7);
    let mut map = vec![0.0; 225];
    let mut budget = Budget::default();
    t.trace(p, d, 1.0, &mut rng, &mut map, &mut budget);
    let e = t.exits.take().unwrap();
    budget.detected += e.iter().map(|x| x.2).sum::<f64>();
    (e, budget)
}

fn strongest(e: &[(Vec3, Vec3, f64)]) -> (Vec3, Vec3, f64) {
    *e.iter().max_by(|a, b| a.2.total_cmp(&b.2)).unwrap()
}

#[test]
fn flat_plate_gives_zero_net_deflection_and_the_textbook_shift() {
    let plate = part(
        Shape::Plate {
            thickness: 5.0,
            side: 50.0,
        },
        vec![],
    );
    let th = 20f64.to_radians();
    let d = Vec3::new(th.sin(), 0.0, th.cos());
    let (e, budget) = exits(&plate, Vec3::new(0.0, 0.0, -1.0), d, Interaction::Split);
    // Every forward ray (main one and ghosts) leaves parallel to the input.
    for (_, o, _) in &e {
        assert!((o.x - d.x).abs() < 1e-12 && o.y.abs() < 1e-12 && (o.z - d.z).abs() < 1e-12);
    }
    // Lateral displacement t sin(th - th') / cos(th') of the main ray.
    let thp = (th.sin() / 1.5).asin();
    let shift = 5.0 * (th - thp).sin() / thp.cos();
    let (p, _, w) = strongest(&e);
    let straight_x = (p.z + 1.0) * th.tan();
    let lateral = (straight_x - p.x) * th.cos();
    assert!((lateral - shift).abs() < 1e-9, "{lateral} vs {shift}");
    // Main ray carries (1 - R_in)(1 - R_out) with the Fresnel reflectances at 20 deg.
    let r = optics::fresnel_reflectance(th.cos(), 1.0, 1.5);
    assert!((w - (1.0 - r) * (1.0 - r)).abs() < 1e-12);
    // Energy is conserved: everything is accounted for.
    assert!((budget.total() - 1.0).abs() < 1e-9, "{budget:?}");
}

#[test]
fn thick_lens_focuses_paraxial_rays_at_its_back_focal_distance() {
    // R1 = R2 = 100, t = 2, n = 1.5: 1/F = (n-1)(2/R - (n-1) t / (n R^2)),
    // back focal distance BFD = F (1 - (n-1) t / (n R1)).
    let (r, t, n) = (100.0, 2.0, 1.5);
    let f = 1.0 / ((n - 1.0) * (2.0 / r - (n - 1.0) * t / (n * r * r)));
    let bfd = f * (1.0 - (n - 1.0) * t / (n * r));
    let lens = part(
        Shape::DoubleConvex {
            r1: r,
            r2: r,
            thickness: t,
            diameter: 20.0,
        },
        vec![],
    );
    let mut lsa = Vec::new();
    for h in [0.1, 0.3] {
        let (e, _) = exits(
            &lens,
            Vec3::new(h, 0.0, -1.0),
            Vec3::new(0.0, 0.0, 1.0),
            Interaction::Split,
        );
        let (p, d, _) = strongest(&e);
        let z_cross = p.z - p.x * d.z / d.x;
        assert!(
            (z_cross - (t + bfd)).abs() < 5e-3,
            "h={h}: {z_cross} vs {}",
            t + bfd
        );
        lsa.push(t + bfd - z_cross);
    }
    // The small remainder is spherical aberration: marginal rays focus
    // short, by an amount growing as h^2 (third order).
    assert!(lsa[0] > 0.0 && lsa[1] > 0.0);
    assert!((lsa[1] / lsa[0] - 9.0).abs() < 0.2, "{lsa:?}");
}

#[test]
fn ray_through_bubble_centre_is_undeflected() {
    let b = Bubble {
        center: Vec3::new(1.0, -2.0, 2.5),
        radius: 0.3,
        index: 1.0,
    };
    let plate = part(
        Shape::Plate {
            thickness: 5.0,
            side: 50.0,
        },
        vec![b],
    );
    let (e, budget) = exits(
        &plate,
        Vec3::new(1.0, -2.0, -1.0),
        Vec3::new(0.0, 0.0, 1.0),
        Interaction::Split,
    );
    assert!(!e.is_empty());
    for (p, d, _) in &e {
        assert!(d.x.abs() < 1e-12 && d.y.abs() < 1e-12 && (d.z - 1.0).abs() < 1e-12);
        assert!((p.x - 1.0).abs() < 1e-9 && (p.y + 2.0).abs() < 1e-9);
    }
    // Four interfaces at normal incidence, each R = 0.04: the direct ray keeps 0.96^4.
    assert!((strongest(&e).2 - 0.96f64.powi(4)).abs() < 1e-12);
    assert!((budget.total() - 1.0).abs() < 1e-9);
}

#[test]
fn grazing_ray_is_totally_reflected_by_a_bubble() {
    // Impact parameter 0.95 r: incidence asin(0.95) = 71.8 deg > 41.8 deg critical,
    // so nothing enters the bubble; the ray turns by pi - 2 i = 36.38 deg in the
    // glass and leaves the plate at asin(1.5 sin(36.38 deg)) = 62.87 deg.
    let b = Bubble {
        center: Vec3::new(0.0, 0.0, 2.5),
        radius: 0.2,
        index: 1.0,
    };
    let plate = part(
        Shape::Plate {
            thickness: 5.0,
            side: 50.0,
        },
        vec![b],
    );
    let (e, _) = exits(
        &plate,
        Vec3::new(0.95 * 0.2, 0.0, -1.0),
        Vec3::new(0.0, 0.0, 1.0),
        Interaction::Split,
    );
    let (_, d, w) = strongest(&e);
    let i = 0.95f64.asin();
    let inside = std::f64::consts::PI - 2.0 * i;
    let out = (1.5 * inside.sin()).asin();
    assert!(
        (d.x.atan2(d.z) - out).abs() < 1e-9,
        "{} vs {}",
        d.x.atan2(d.z).to_degrees(),
        out.to_degrees()
    );
    assert!((out.to_degrees() - 62.87).abs() < 0.01);
    // No Fresnel loss at the bubble (total reflection), only at the two plate faces.
    let r_in = optics::fresnel_reflectance(1.0, 1.0, 1.5);
    let r_out = optics::fresnel_reflectance(inside.cos(), 1.5, 1.0);
    assert!((w - (1.0 - r_in) * (1.0 - r_out)).abs() < 1e-12);
}

#[test]
fn receiving_lens_maps_angle_to_f_tan_alpha() {
    let rx = receiver();
    for (alpha, phi) in [(0.1f64, 0.0f64), (0.05, 1.0), (0.2, -2.0)] {
        let d = Vec3::new(
            alpha.sin() * phi.cos(),
            alpha.sin() * phi.sin(),
            alpha.cos(),
        );
        let (u, v) = rx.focal_plane(d);
        assert!((u.hypot(v) - 50.0 * alpha.tan()).abs() < 1e-12);
        assert!((v.atan2(u) - phi).abs() < 1e-12);
    }
    // 15 cells of 0.5 mm: the axis hits the centre cell (7, 7); a ray at
    // f tan(alpha) = +1.0 mm in x lands two cells right, +1.0 mm in y two rows up.
    assert_eq!(rx.cell(0.0, 0.0), Some((7, 7)));
    assert_eq!(rx.cell(1.0, 0.0), Some((7, 9)));
    assert_eq!(rx.cell(0.0, 1.0), Some((5, 7)));
    assert_eq!(rx.cell(3.8, 0.0), None);
}

#[test]
fn beam_through_plate_lands_on_the_cell_of_its_angle() {
    // No part in the way (plate far off to the side): a beam tilted by
    // alpha with 50 tan(alpha) = 1.0 mm hits cell (7, 9) with all its power
    // (no Fresnel losses in air).
    let plate = part(
        Shape::Plate {
            thickness: 5.0,
            side: 10.0,
        },
        vec![],
    );
    let body = plate.body();
    let rx = receiver();
    let mut t = Tracer::new(&body, &rx, TraceOptions::default());
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(1);
    let mut map = vec![0.0; 225];
    let mut budget = Budget::default();
    let a = (1.0f64 / 50.0).atan();
    t.trace(
        Vec3::new(100.0, 0.0, -1.0),
        Vec3::new(a.sin(), 0.0, a.cos()),
        1.0,
        &mut rng,
        &mut map,
        &mut budget,
    );
    assert!((map[7 * 15 + 9] - 1.0).abs() < 1e-15);
    assert_eq!(budget.detected, 1.0);
}

#[test]
fn stochastic_and_split_agree_on_average() {
    // Power reaching each cell through a bubble-hit beam: the stochastic
    // choice is an unbiased estimate of the Fresnel split.
    let mut cfg = preset::prototype(true);
    cfg.part = part(
        Shape::Plate {
            thickness: 5.0,
            side: 50.0,
        },
        vec![Bubble {
            center: Vec3::new(0.0, 0.0, 2.5),
            radius: 0.2,
            index: 1.0,
        }],
    );
    cfg.receiver = Receiver {
        focal: 50.0,
        distance: 20.0,
        aperture: 1e6,
        j1: 9,
        j2: 9,
        pixel: 5.0,
        spot: 0.0,
    };
    cfg.raster.rays = 2000;
    let body = cfg.part.body();
    let mut maps = Vec::new();
    for interaction in [Interaction::Split, Interaction::Stochastic] {
        let mut t = Tracer::new(
            &body,
            &cfg.receiver,
            TraceOptions {
                interaction,
                ..TraceOptions::default()
            },
        );
        let mut acc = vec![0.0; 81];
        let mut map = vec![0.0; 81];
        let mut rays = Vec::new();
        let reps = if interaction == Interaction::Split {
            1
        } else {
            40
        };
        for k in 0..reps {
            let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(k);
            scan::beam_map(&cfg, &mut t, 0.0, 0.0, &mut rng, &mut rays, &mut map);
            acc.iter_mut()
                .zip(&map)
                .for_each(|(a, m)| *a += m / reps as f64);
        }
        maps.push(acc);
    }
    let centre = 4 * 9 + 4;
    assert!(
        (maps[0][centre] - maps[1][centre]).abs() < 0.01,
        "{} vs {}",
        maps[0][centre],
        maps[1][centre]
    );
    let off0: f64 = maps[0].iter().sum::<f64>() - maps[0][centre];
    let off1: f64 = maps[1].iter().sum::<f64>() - maps[1][centre];
    assert!(
        off0 > 0.02,
        "bubble must scatter light off the centre cell: {off0}"
    );
    assert!((off0 - off1).abs() < 0.01 + 0.1 * off0, "{off0} vs {off1}");
}

#[test]
fn point_spread_shares_power_by_gaussian_cell_integrals() {
    // Spot centred on the middle cell, sigma = half a pixel: each axis keeps
    // Phi(1) - Phi(-1) = 0.682689 in the centre cell, so 0.466064 in 2-D;
    // the next cell on one axis gets Phi(3) - Phi(1) = 0.157305 of that axis.
    let rx = Receiver {
        spot: 0.25,
        ..receiver()
    };
    let mut map = vec![0.0; 225];
    let mut scratch = Vec::new();
    let on = rx.spread(0.0, 0.0, 1.0, &mut map, &mut scratch);
    assert!((map[7 * 15 + 7] - 0.682_689_49f64.powi(2)).abs() < 1e-6);
    assert!((map[7 * 15 + 8] - 0.682_689_49 * 0.157_305_46).abs() < 1e-6);
    assert!((map[6 * 15 + 7] - map[7 * 15 + 8]).abs() < 1e-12);
    assert!((on - 1.0).abs() < 1e-6);
    assert!((map.iter().sum::<f64>() - on).abs() < 1e-12);
    // A spot at the array's right edge loses half its power beside it.
    let mut map = vec![0.0; 225];
    let on = rx.spread(7.5 * 0.5, 0.0, 1.0, &mut map, &mut scratch);
    assert!((on - 0.5).abs() < 1e-6, "{on}");
}

#[test]
fn erf_matches_tabulated_values() {
    // erf(0.5) = 0.5204998778, erf(1) = 0.8427007929, erf(2) = 0.9953222650.
    for (x, e) in [
        (0.5, 0.520_499_877_8),
        (1.0, 0.842_700_792_9),
        (2.0, 0.995_322_265_0),
    ] {
        assert!((trace::erf(x) - e).abs() < 2e-7);
        assert!((trace::erf(-x) + e).abs() < 2e-7);
    }
}
