//! The pieces of `dmap::halos` against independent references: a halo's
//! truth region against the simulator's own truth mask, a halo's strength
//! in a beam's power against every beam of the raster, and the "found"
//! rule on hand-made objects.

use cvm_core::Object;
use dmap::halos::run::near_truth;
use dmap::halos::{Geo, Thresholds, halo_part, halo_part_of_beam_power, strongest_beam};

#[test]
fn halo_truth_regions_are_the_simulators_truth_mask() {
    for geo in Geo::BOTH {
        for size in [1.0, 2.0, 3.0] {
            let at = [(9, 9), (9, 29), (29, 9), (29, 29)];
            let (cfg, halos) = halo_part(geo, 7, 39, size, &[0.05, 0.1, 0.2, 0.3], &at);
            let mask = cvm_sim::truth_mask(&cfg);
            let mut ours = vec![false; 39 * 39];
            for h in &halos {
                assert!(!h.truth.is_empty(), "{geo:?} {size}: an empty truth");
                for &(r, c) in &h.truth {
                    ours[r * 39 + c] = true;
                }
            }
            assert_eq!(ours, mask, "{geo:?}, discs of {size} positions");
        }
    }
}

#[test]
fn a_halo_of_a_beams_power_takes_that_power_from_its_strongest_beam() {
    let at = [(9, 9), (9, 29), (29, 19)];
    for geo in Geo::BOTH {
        for size in [1.0, 3.0] {
            let powers = [0.10, 0.20, 0.30];
            let (cfg, halos) = halo_part_of_beam_power(geo, 11, 39, size, &powers, &at).unwrap();
            let r = &cfg.raster;
            for (h, &p) in halos.iter().zip(&powers) {
                // The beam nearest the disc's centre takes the most: the
                // overlap of a Gaussian beam with a disc falls with the
                // distance between their centres.
                let nearest = (0..39 * 39)
                    .map(|q| r.position(q / 39, q % 39))
                    .min_by(|a, b| {
                        let d = |(x, y): (f64, f64)| (x - h.disc.x).hypot(y - h.disc.y);
                        d(*a).total_cmp(&d(*b))
                    })
                    .unwrap();
                let most = h.disc.beam_share(nearest.0, nearest.1, r.waist);
                assert!((most - p).abs() < 1e-12, "{geo:?} {size}: {most} for {p}");
                assert!(h.disc.share >= p && h.disc.share <= 1.0, "{}", h.disc.share);
                assert_eq!(strongest_beam(&cfg, &h.disc), most);
            }
            let discs: Vec<_> = halos.iter().map(|h| h.disc).collect();
            assert_eq!(cfg.part.scatterers, discs);
        }
        // No beam loses 90 % of its power to a disc of one position: at
        // most the 59 % of a centred beam that crosses it.
        let err = halo_part_of_beam_power(geo, 11, 39, 1.0, &[0.9], &at).unwrap_err();
        assert!(err.contains("not 90.0 %"), "{err}");
    }
}

fn object(row0: u32, row1: u32, col0: u32, col1: u32) -> Object {
    Object {
        row0,
        row1,
        col0,
        col1,
        ..Object::default()
    }
}

#[test]
fn an_object_is_near_a_truth_within_one_position_diagonals_included() {
    let o = object(5, 6, 10, 12);
    // Inside, on each side one position out, and the corners diagonally.
    for t in [(5, 10), (4, 11), (7, 11), (6, 9), (6, 13), (4, 9), (7, 13)] {
        assert!(near_truth(&o, &[t]), "{t:?}");
    }
    // Two positions out, each way.
    for t in [(3, 11), (8, 11), (5, 8), (5, 14), (3, 8)] {
        assert!(!near_truth(&o, &[t]), "{t:?}");
    }
    // At row and column 0 nothing wraps.
    assert!(near_truth(&object(0, 0, 0, 0), &[(1, 1)]));
    assert!(!near_truth(&object(0, 0, 0, 0), &[(2, 0)]));
}

#[test]
fn channel_subsets_leave_the_others_measuring_but_silent() {
    let t = Thresholds {
        cvm: 10,
        power: 20,
        spread: 30,
    };
    let m = Thresholds::MEASURE;
    assert_eq!(t.cvm_only(), Thresholds { cvm: 10, ..m });
    assert_eq!(t.power_only(), Thresholds { power: 20, ..m });
    assert_eq!(t.spread_only(), Thresholds { spread: 30, ..m });
    // The spread channel measures (not SPREAD_OFF) but no magnitude reaches it.
    assert!(m.spread > cvm_core::spread::SPREAD_MAX && m.spread != cvm_core::spread::SPREAD_OFF);
    assert_eq!(t.without_spread().spread, cvm_core::spread::SPREAD_OFF);
}
