//! The spread channel: the integer share outside the core against the f64
//! reference, its invariances, and the engine's spread gradient and
//! decisions against the f64 neighbour gradient on the same values.

use cvm_core::scorer::Scratch;
use cvm_core::spread::{self, SPREAD_MAX, SPREAD_OFF};
use cvm_core::{PositionScore, Scorer, flags};
use cvm_core_tests::{
    GEOMETRIES, decide, decide_spread, random_map, random_scan, rng, run_engine_thresholds,
    scan_frames, spread_magnitude_ref, spread_q_ref, variants,
};
use cvm_reference::neighbour_gradient;
use dmap::fixed::{add_spread, score_scan};
use proptest::prelude::*;
use rand::RngExt;

/// `q` of a map through the core's function, with its power.
fn q(frame: &[u16], j1: usize, j2: usize, half: usize) -> u16 {
    let p: u32 = frame.iter().map(|&a| u32::from(a)).sum();
    spread::outside_core(frame, j1, j2, half, p)
}

/// `floor(2^16 o / p)` in 128-bit integers.
fn share_ref(o: u64, p: u64) -> u16 {
    u16::try_from((u128::from(o) << 16) / u128::from(p)).unwrap()
}

/// What the scorer's per-map pass reports as the map's spread.
fn prepared_spread(scorer: &Scorer, frame: &[u16]) -> u16 {
    let mut state = vec![0i32; scorer.state_words()];
    scorer
        .prepare_map(frame, &mut state, &mut [], &mut Scratch::new(), false)
        .unwrap()
        .spread
}

#[test]
fn hand_cases() {
    // A single lit cell: everything is in the core.
    let mut m = vec![0u16; 81];
    m[40] = 1234;
    assert_eq!(q(&m, 9, 9, 2), 0);
    m[0] = 5;
    // 5 of 1239 outside the box around (4, 4): floor(65536 * 5 / 1239).
    assert_eq!(q(&m, 9, 9, 2), 264);
    // 1 : 3 three cells apart: a quarter of the power outside.
    let mut m = vec![0u16; 81];
    m[4 * 9 + 1] = 1;
    m[4 * 9 + 4] = 3;
    assert_eq!(q(&m, 9, 9, 2), 16_384);
    // Two cells apart, the dim one is in the core.
    m[4 * 9 + 1] = 0;
    m[4 * 9 + 2] = 1;
    assert_eq!(q(&m, 9, 9, 2), 0);
    // A uniform map: the first cell is the brightest, its box is clipped
    // to 3x3 at the corner: 72 of 81 cells outside.
    assert_eq!(q(&[7; 81], 9, 9, 2), 58_254);
    assert_eq!(q(&[7; 225], 15, 15, 2), 62_914);
    // Ties: the first brightest cell in raster order, (0, 0), not (4, 4):
    // its 3x3 box holds 100 + 8, the other 100 and 71 cells are outside.
    let mut m = vec![1u16; 81];
    m[0] = 100;
    m[40] = 100;
    assert_eq!(q(&m, 9, 9, 2), share_ref(171, 279));
    // With the brightest cell in the middle the whole 5x5 box counts.
    let mut m = vec![7u16; 81];
    m[40] = 8;
    assert_eq!(q(&m, 9, 9, 2), share_ref(56 * 7, 80 * 7 + 8));
    // Full scale on the largest map: P = 256 * 65535, 247 cells outside.
    assert_eq!(q(&[u16::MAX; 256], 16, 16, 2), 63_232);
    let mut m = vec![u16::MAX - 1; 256];
    m[8 * 16 + 8] = u16::MAX;
    let p = 255 * u64::from(u16::MAX - 1) + u64::from(u16::MAX);
    assert_eq!(
        q(&m, 16, 16, 2),
        share_ref(231 * u64::from(u16::MAX - 1), p)
    );
    // The largest q: one bright cell, the rest of the light far off.
    let mut m = vec![0u16; 256];
    m[0] = 2;
    for c in [255, 254, 253, 239, 238] {
        m[c] = 1;
    }
    assert_eq!(q(&m, 16, 16, 0), share_ref(5, 7));
    // A dark map, and a 1x1 map.
    assert_eq!(q(&[0; 81], 9, 9, 2), 0);
    assert_eq!(q(&[9], 1, 1, 2), 0);
    // Half-width 0: only the brightest cell is the core.
    assert_eq!(q(&[1, 3, 0, 4], 2, 2, 0), share_ref(4, 8));
}

#[test]
fn share_is_exact_at_its_edges() {
    let p_max = 256 * 65_535u32;
    for (o, p) in [
        (0, 1),
        (1, 2),
        (p_max - 1, p_max),
        (1, p_max),
        (65_535, 65_536),
    ] {
        assert_eq!(
            spread::share(o, p),
            share_ref(o.into(), p.into()),
            "{o}/{p}"
        );
    }
    assert_eq!(spread::share(0, 0), 0);
    assert_eq!(spread::share(5, 5), u16::MAX);
}

#[test]
fn magnitude_edges() {
    assert_eq!(spread::magnitude(0, 0), 0);
    assert_eq!(spread::magnitude(3, 4), 5);
    assert_eq!(spread::magnitude(u16::MAX, 0), 65_535);
    assert_eq!(spread::magnitude(u16::MAX, u16::MAX), SPREAD_MAX);
    // Around the switch from the 32-bit root to the 64-bit one.
    for (a, b) in [
        (46_340, 46_341),
        (46_341, 46_341),
        (65_535, 1),
        (40_000, 50_000),
    ] {
        assert_eq!(
            spread::magnitude(a, b),
            spread_magnitude_ref(a, b),
            "{a} {b}"
        );
    }
}

#[test]
fn thresholds_in_units() {
    assert_eq!(spread::threshold_from_units(0.01), 656);
    assert_eq!(spread::threshold_from_units(0.0), 0);
    assert_eq!(spread::threshold_from_units(-1.0), 0);
    assert_eq!(spread::threshold_from_units(f64::NAN), SPREAD_OFF);
    assert_eq!(spread::threshold_from_units(2.0), SPREAD_OFF);
    assert_eq!(spread::to_units(32_768), 0.5);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20_000))]

    #[test]
    fn magnitude_is_the_floor_of_the_root(s0 in any::<u16>(), s1 in any::<u16>()) {
        prop_assert_eq!(spread::magnitude(s0, s1), spread_magnitude_ref(s0, s1));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// The integer `q` is `floor(2^16 outside_core)` of the f64 reference,
    /// on every geometry and half-width, and the scorer's per-map pass
    /// reports it for both kernel sets.
    #[test]
    fn q_is_the_f64_share(g in 0..GEOMETRIES.len(), half in 0usize..4, seed in any::<u64>()) {
        let (j1, j2) = GEOMETRIES[g];
        let mut r = rng(seed);
        for _ in 0..8 {
            let m = random_map(&mut r, j1 * j2, j2);
            let want = spread_q_ref(&m, j1, j2, half);
            prop_assert_eq!(q(&m, j1, j2, half), want);
        }
        let m = random_map(&mut r, j1 * j2, j2);
        for args in variants(j1, j2) {
            let scorer = args.scorer(j1, j2).unwrap();
            let scorer = scorer.with_spread_half(half as u8);
            prop_assert_eq!(prepared_spread(&scorer, &m), spread_q_ref(&m, j1, j2, half));
        }
    }

    /// Scaling the map by an integer factor (within `u16`) keeps `q`: the
    /// same fraction, the same brightest cell.
    #[test]
    fn q_is_invariant_under_scaling(g in 0..GEOMETRIES.len(), k in 2u16..50, seed in any::<u64>()) {
        let (j1, j2) = GEOMETRIES[g];
        let mut r = rng(seed);
        let m: Vec<u16> = random_map(&mut r, j1 * j2, j2)
            .iter()
            .map(|&a| a % (u16::MAX / k + 1))
            .collect();
        let scaled: Vec<u16> = m.iter().map(|&a| a * k).collect();
        prop_assert_eq!(q(&scaled, j1, j2, 2), q(&m, j1, j2, 2));
    }

    /// Moving the light across the map keeps `q` while nothing falls off
    /// and the box stays inside: light on a 6x6 patch, moved on a 16x16
    /// map.
    #[test]
    fn q_is_invariant_under_translation(
        d1 in 0usize..=10,
        d2 in 0usize..=10,
        e1 in 0usize..=10,
        e2 in 0usize..=10,
        seed in any::<u64>(),
    ) {
        let mut r = rng(seed);
        let patch: Vec<u16> = (0..36).map(|_| r.random_range(0..2000)).collect();
        let place = |o1: usize, o2: usize| {
            let mut m = vec![0u16; 256];
            for (k, &a) in patch.iter().enumerate() {
                m[(o1 + k / 6) * 16 + o2 + k % 6] = a;
            }
            m
        };
        // Only where the patch's box is inside at both places (the
        // brightest cell at least 2 cells from every edge).
        let top = patch.iter().max().copied().unwrap_or(0);
        let peak = patch.iter().position(|&a| a == top).unwrap_or(0);
        let (p1, p2) = (peak / 6, peak % 6);
        let inside = |o1: usize, o2: usize| (2..=13).contains(&(p1 + o1)) && (2..=13).contains(&(p2 + o2));
        prop_assume!(inside(d1, d2) && inside(e1, e2));
        prop_assert_eq!(q(&place(d1, d2), 16, 16, 2), q(&place(e1, e2), 16, 16, 2));
    }
}

/// The f64 neighbour gradient at one position with Eq. 1's gap rule: a
/// neighbour outside the scan or without data is replaced by the position
/// itself. The reference's border rule does the rest: its 3x3 input holds
/// the position and its four neighbours (the corners are not read).
fn gradient_ref(qs: &[Option<u16>], rows: usize, cols: usize, r: usize, c: usize) -> f64 {
    let own = qs[r * cols + c].map_or(0.0, f64::from);
    let at = |rr: isize, cc: isize| -> f64 {
        if rr < 0 || cc < 0 || rr >= rows as isize || cc >= cols as isize {
            return own;
        }
        qs[rr as usize * cols + cc as usize].map_or(own, f64::from)
    };
    let (r, c) = (r as isize, c as isize);
    let local = [
        own,
        at(r - 1, c),
        own,
        at(r, c - 1),
        own,
        at(r, c + 1),
        own,
        at(r + 1, c),
        own,
    ];
    neighbour_gradient(&local, 3, 3)[4]
}

fn flatten(rows: &[(cvm_core::RowSummary, Vec<PositionScore>)]) -> Vec<PositionScore> {
    rows.iter().flat_map(|(_, s)| s.iter().copied()).collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The engine's spread components and magnitude over scans with gaps:
    /// the components are the differences of the reference's `q`, and the
    /// magnitude is the f64 neighbour gradient of those `q` rounded down
    /// (`0 <= gradient - smag < 1`).
    #[test]
    fn engine_spread_is_the_neighbour_gradient(
        rows in 1usize..7,
        cols in 1usize..9,
        g in 0usize..4,
        gaps in 0u32..4,
        seed in any::<u64>(),
    ) {
        let (j1, j2) = [(2, 2), (3, 5), (9, 9), (15, 15)][g];
        let n = j1 * j2;
        let mut r = rng(seed);
        let data = random_scan(&mut r, rows, cols, j1, j2);
        let present: Vec<bool> = (0..rows * cols).map(|_| r.random_range(0..10) >= gaps).collect();
        let scorer = variants(j1, j2)[0].scorer(j1, j2).unwrap();
        let frames = scan_frames(&data, n, rows, cols, Some(&present));
        // Measured, never firing.
        let on = SPREAD_MAX + 1;
        let (out, _) = run_engine_thresholds(&scorer, cols, [u32::MAX, u32::MAX, on], &frames);
        let got = flatten(&out);
        prop_assert_eq!(got.len(), rows * cols);
        // Off, nothing is measured; every other value is the same.
        let (off, _) = run_engine_thresholds(&scorer, cols, [u32::MAX, u32::MAX, SPREAD_OFF], &frames);
        let unmeasured: Vec<PositionScore> = got
            .iter()
            .map(|s| PositionScore { s0: 0, s1: 0, smag: 0, ..*s })
            .collect();
        prop_assert_eq!(flatten(&off), unmeasured);
        let qs: Vec<Option<u16>> = (0..rows * cols)
            .map(|i| present[i].then(|| spread_q_ref(&data[i * n..(i + 1) * n], j1, j2, 2)))
            .collect();
        for (i, s) in got.iter().enumerate() {
            let (rr, c) = (i / cols, i % cols);
            if !present[i] {
                prop_assert_eq!(s.flags, flags::NO_DATA);
                prop_assert_eq!((s.s0, s.s1, s.smag), (0, 0, 0));
                continue;
            }
            let own = qs[i].unwrap();
            let nb = |k: Option<usize>| k.and_then(|k| qs[k]).unwrap_or(own);
            let left = nb(c.checked_sub(1).map(|cc| rr * cols + cc));
            let right = nb((c + 1 < cols).then(|| rr * cols + c + 1));
            let up = nb(rr.checked_sub(1).map(|x| x * cols + c));
            let down = nb((rr + 1 < rows).then(|| (rr + 1) * cols + c));
            prop_assert_eq!(s.s0, left.abs_diff(right), "s0 at {} {}", rr, c);
            prop_assert_eq!(s.s1, up.abs_diff(down), "s1 at {} {}", rr, c);
            let want = gradient_ref(&qs, rows, cols, rr, c);
            let m = f64::from(s.smag);
            prop_assert!(m <= want + 1e-9 && want < m + 1.0, "{} against {}", m, want);
            prop_assert_eq!(s.flags & flags::SPREAD_DEFECT, 0);
        }
    }

    /// With a spread threshold the engine decides as the batch scoring
    /// does with every channel: the same flags and strengths, positions on
    /// both sides of the threshold, the row summaries counting them.
    #[test]
    fn engine_decides_spread_as_batch(
        rows in 1usize..7,
        cols in 1usize..9,
        g in 0usize..3,
        seed in any::<u64>(),
    ) {
        let (j1, j2) = [(3, 5), (9, 9), (15, 15)][g];
        let n = j1 * j2;
        let mut r = rng(seed);
        let data = random_scan(&mut r, rows, cols, j1, j2);
        let scorer = variants(j1, j2)[0].scorer(j1, j2).unwrap();
        let mut batch = score_scan(&scorer, rows, cols, &data);
        add_spread(&scorer, rows, cols, &data, &mut batch);
        let thr = batch.iter().map(|s| s.mag).max().unwrap_or(0) / 2 + 1;
        let pthr = u32::from(batch.iter().map(|s| s.pmag).max().unwrap_or(0)) + 1;
        let sthr = batch.iter().map(|s| s.smag).max().unwrap_or(0) / 2 + 1;
        decide(&mut batch, thr, pthr);
        decide_spread(&mut batch, sthr);
        let frames = scan_frames(&data, n, rows, cols, None);
        let (out, totals) = run_engine_thresholds(&scorer, cols, [thr, pthr, sthr], &frames);
        prop_assert_eq!(&flatten(&out), &batch);
        let fired = batch.iter().filter(|s| s.flags & flags::SPREAD_DEFECT != 0).count();
        let max = batch.iter().map(|s| s.smag).max().unwrap_or(0);
        prop_assert!(max == 0 || fired > 0);
        prop_assert!(batch.iter().all(|s| (s.smag >= sthr) == (s.flags & flags::SPREAD_DEFECT != 0)));
        let defects = batch.iter().filter(|s| s.is_defect()).count() as u32;
        prop_assert_eq!(totals.defects, defects);
        let per_row: u32 = out.iter().map(|(sum, _)| sum.defects).sum();
        prop_assert_eq!(per_row, defects);
    }
}

/// A spot scan with one halo: the maps are the same spot everywhere, and at
/// one position a quarter of the light is spread over the whole map. Only
/// the spread channel is on; it fires at the halo's four neighbours (the
/// central differences skip the position itself), with the strength of
/// `smag / threshold`.
#[test]
fn a_halo_fires_the_spread_channel_at_its_neighbours() {
    let (j1, j2, rows, cols) = (9usize, 9usize, 5usize, 6usize);
    let n = j1 * j2;
    let mut spot = vec![0u16; n];
    for (k, v) in [(40, 4000), (39, 500), (41, 500), (31, 500), (49, 500)] {
        spot[k] = v;
    }
    let halo: Vec<u16> = spot.iter().map(|&a| a * 3 / 4 + 25).collect();
    let at = (2usize, 3usize);
    let mut data = Vec::new();
    for i in 0..rows * cols {
        data.extend_from_slice(if (i / cols, i % cols) == at {
            &halo
        } else {
            &spot
        });
    }
    let scorer = variants(j1, j2)[0].scorer(j1, j2).unwrap();
    let (q_spot, q_halo) = (q(&spot, j1, j2, 2), q(&halo, j1, j2, 2));
    assert_eq!(q_spot, 0);
    // 56 cells of 25 outside, of 6000 * 3/4 + 81 * 25 counts.
    assert_eq!(q_halo, share_ref(56 * 25, 4500 + 81 * 25));
    let thr = u32::from(q_halo) / 2;
    let frames = scan_frames(&data, n, rows, cols, None);
    let (out, totals) = run_engine_thresholds(&scorer, cols, [u32::MAX, u32::MAX, thr], &frames);
    let got = flatten(&out);
    let neighbours = [(1, 3), (3, 3), (2, 2), (2, 4)];
    for (i, s) in got.iter().enumerate() {
        let p = (i / cols, i % cols);
        if neighbours.contains(&p) {
            assert_eq!(s.flags, flags::SPREAD_DEFECT, "{p:?}");
            assert_eq!(s.smag, u32::from(q_halo));
            // floor(2^16 smag / threshold), at least twice 2^16 here.
            let want = (u64::from(q_halo) << 16) / u64::from(thr);
            assert_eq!(u64::from(s.strength), want);
            assert!(s.strength >= 131_072);
        } else {
            assert_eq!(s.flags & flags::DEFECT, 0, "{p:?}");
            assert_eq!(s.smag, 0, "{p:?}");
        }
    }
    assert_eq!(totals.defects, 4);
}
