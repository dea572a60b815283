//! The pooled statistics of `dmap::halos::pooled` against values worked
//! out by hand on small made-up rasters, and its defects against the
//! simulator's beam shares.

use dmap::halos::Geo;
use dmap::halos::pooled::{
    Channel, Defect, Footprints, Kind, Place, Quantities, defect_part, matched, pooled,
};

/// A 5x5 raster, every power 100 and every `q` 0.01 but for `changed`.
fn raster(changed: &[((usize, usize), f64, f64)]) -> Quantities {
    let mut qs = Quantities {
        rows: 5,
        cols: 5,
        power: vec![100.0; 25],
        q: vec![0.01; 25],
    };
    for &((r, c), p, q) in changed {
        qs.power[r * 5 + c] = p;
        qs.q[r * 5 + c] = q;
    }
    qs
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-12
}

#[test]
fn one_weak_position_against_its_eight_neighbours() {
    let qs = raster(&[((2, 2), 90.0, 0.01)]);
    let v = pooled(&qs, Channel::Power, Footprints::Single);
    // (1 - 90 / 100) / sqrt(1 + 1/8).
    assert!(close(v[12], 0.1 / 1.125f64.sqrt()), "{}", v[12]);
    // A neighbour: its 3x3 box holds the weak one among its 8, mean 98.75;
    // (1 - 100 / 98.75) / sqrt(1 + 1/8), below 0.
    assert!(
        close(v[7], (1.0 - 100.0 / 98.75) / 1.125f64.sqrt()),
        "{}",
        v[7]
    );
    // A corner: 3 neighbours, (2x2 box), all 100.
    assert!(close(v[0], 0.0));
    // The pairs and quads do not beat the position alone here: a pair
    // with a neighbour of 100 in rows 1-3 and columns 1-3 (or 2-4) has
    // mean 95 against 10 of mean 100: 0.05 / sqrt(1/2 + 1/10) = 0.0645.
    let all = pooled(&qs, Channel::Power, Footprints::All);
    assert!(close(all[12], v[12]));
    // But the neighbour's value is now its pair with the weak position.
    assert!(close(all[13], 0.05 / 0.6f64.sqrt()), "{}", all[13]);
    // The ideal detector with the position's own pattern is the same
    // statistic: surroundings the 8 neighbours, sqrt(1 + 1/8).
    let m = matched(&qs, Channel::Power, &[((0, 0), 0.3)], (2, 2)).unwrap();
    assert!(close(m, v[12]), "{m}");
}

#[test]
fn a_halo_split_over_two_positions_pools_into_their_pair() {
    let qs = raster(&[((2, 1), 100.0, 0.03), ((2, 2), 100.0, 0.03)]);
    let single = pooled(&qs, Channel::Spread, Footprints::Single);
    // Alone: 0.03 against 7 x 0.01 and 0.03, (0.03 - 0.0125) / sqrt(1 + 1/8).
    assert!(
        close(single[12], 0.0175 / 1.125f64.sqrt()),
        "{}",
        single[12]
    );
    let all = pooled(&qs, Channel::Spread, Footprints::All);
    // The pair (2,1)-(2,2) in rows 1-3, columns 0-3: 0.02 over 10
    // surroundings, 0.02 / sqrt(1/2 + 1/10).
    let pair = 0.02 / 0.6f64.sqrt();
    assert!(close(all[11], pair) && close(all[12], pair), "{all:?}");
    // The quad (1..=2, 1..=2): mean 0.02 against 8 of 0.01 in rows 1-3,
    // columns 0-3: 0.01 / sqrt(1/4 + 1/8) = 0.0163, less than the pair.
    assert!(all[11] > 0.01 / 0.375f64.sqrt());
    // The power channel is one-sided: the raised q does not show there,
    // and a raised power is not a loss.
    let up = raster(&[((2, 2), 110.0, 0.01)]);
    assert!(pooled(&up, Channel::Power, Footprints::All)[12] < 0.0);
    // Known pattern: both beams at weight 1, surroundings the 10 others
    // of the 3x4 box: sum w (q - R) / sqrt(2 + 4 / 10).
    let m = matched(
        &qs,
        Channel::Spread,
        &[((0, 0), 1.0), ((0, 1), 1.0)],
        (2, 1),
    )
    .unwrap();
    assert!(close(m, 0.04 / 2.4f64.sqrt()), "{m}");
}

#[test]
fn the_window_holds_three_rows() {
    // Two rows below a position, a change is outside every footprint's box.
    let qs = raster(&[((4, 2), 50.0, 0.51)]);
    for (ch, excess) in [
        (Channel::Power, 1.0 - 75.0 / 100.0),
        (Channel::Spread, 0.25),
    ] {
        let v = pooled(&qs, ch, Footprints::All);
        assert!(close(v[2 * 5 + 2], 0.0), "{ch:?}: {}", v[12]);
        // One row below, its vertical pair with (4, 2) is the largest:
        // mean 75 (q 0.26) against 7 of 100 (0.01), sqrt(1/2 + 1/7).
        let want = excess / (0.5f64 + 1.0 / 7.0).sqrt();
        assert!(close(v[3 * 5 + 2], want), "{ch:?}: {} {want}", v[17]);
    }
}

#[test]
fn defects_take_their_power_from_their_strongest_beams() {
    for geo in Geo::BOTH {
        for (kind, power) in [(Kind::Absorber, 0.25), (Kind::Halo, 0.02)] {
            let at = (19, 19);
            let defects: Vec<Defect> = [Place::Centred, Place::BetweenColumns, Place::BetweenRows]
                .into_iter()
                .enumerate()
                .map(|(i, place)| Defect {
                    kind,
                    power,
                    at: (at.0, at.1 - 13 + 13 * i),
                    place,
                })
                .collect();
            let (cfg, placed) = defect_part(geo, 3, 39, 0.02, &defects).unwrap();
            assert_eq!(cfg.laser.rms, 0.02);
            let r = cfg.raster;
            for p in &placed {
                let (row, col) = p.defect.at;
                let d = p.halo.disc;
                // Against the simulator's own share of the named beams.
                let share = |rr: usize, cc: usize| {
                    let (x, y) = r.position(rr, cc);
                    d.beam_share(x, y, r.waist)
                };
                assert!((p.beams[0].1 - power).abs() < 1e-12, "{p:?}");
                match p.defect.place {
                    Place::Centred => {
                        assert_eq!(p.beams[0].0, (row, col));
                        // Each of the four neighbours, 334 µm off a disc of
                        // radius 167 µm: far less.
                        assert!(share(row, col + 1) < power / 5.0);
                    }
                    Place::BetweenColumns => {
                        assert!((share(row, col) - power).abs() < 1e-9);
                        assert!((share(row, col + 1) - power).abs() < 1e-9);
                    }
                    Place::BetweenRows => {
                        assert!((share(row, col) - power).abs() < 1e-9);
                        assert!((share(row + 1, col) - power).abs() < 1e-9);
                    }
                }
                let want = match kind {
                    Kind::Absorber => 0.45,
                    Kind::Halo => 0.06,
                };
                assert_eq!(d.width, want);
            }
        }
    }
}
