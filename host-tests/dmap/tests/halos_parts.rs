//! The pieces of `dmap::halos` against independent references: a halo's
//! truth region against the simulator's own truth mask, and the "found"
//! rule on hand-made objects.

use cvm_core::Object;
use dmap::halos::run::near_truth;
use dmap::halos::{Geo, Thresholds, halo_part};

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
