//! Spread measures against hand-computed maps, their invariances, and the
//! integer forms proposed for the device (docs/spread-study.md) against the
//! f64 definition, with its overflow bound checked on the extreme maps.

mod common;

use common::*;
use cvm_reference::*;
use proptest::prelude::*;

fn map_with(g: Geometry, cells: &[((usize, usize), f64)]) -> Vec<f64> {
    let mut m = vec![0.0; g.cells()];
    for &((i1, i2), v) in cells {
        m[g.index(i1, i2)] = v;
    }
    m
}

#[test]
fn point_map_has_no_spread() {
    let g = geometry((9, 9));
    let m = map_with(g, &[((4, 7), 1234.0)]);
    assert_eq!(spread_moment(g, &m), Some(0.0));
    assert_eq!(outside_core(g, &m, 0), Some(0.0));
    assert_eq!(spread_moment(g, &vec![0.0; 81]), None);
    assert_eq!(outside_core(g, &vec![0.0; 81], 1), None);
}

#[test]
fn two_cells_give_the_two_point_variance() {
    // Weights 1/4 and 3/4 two cells apart on one axis: variance
    // p q d^2 = 1/4 * 3/4 * 4 = 0.75, whatever the power.
    let g = geometry((9, 9));
    let m = map_with(g, &[((2, 3), 10.0), ((2, 5), 30.0)]);
    assert!(close(spread_moment(g, &m).unwrap(), 0.75, 1e-15, 0.0));
    let m = map_with(g, &[((3, 2), 1.0), ((5, 2), 3.0)]);
    assert!(close(spread_moment(g, &m).unwrap(), 0.75, 1e-15, 0.0));
    // Equal cells on a diagonal: 1/4 per axis.
    let m = map_with(g, &[((0, 0), 5.0), ((1, 1), 5.0)]);
    assert!(close(spread_moment(g, &m).unwrap(), 0.5, 1e-15, 0.0));
    // The core around the brightest cell (2, 5): one cell to each side
    // leaves out column 3 (a quarter of the power), two take everything.
    let m = map_with(g, &[((2, 3), 10.0), ((2, 5), 30.0)]);
    assert!(close(outside_core(g, &m, 1).unwrap(), 0.25, 1e-15, 0.0));
    assert_eq!(outside_core(g, &m, 2), Some(0.0));
}

#[test]
fn uniform_map_has_the_discrete_uniform_variance() {
    // Variance of a uniform distribution on 0..J-1 is (J^2 - 1) / 12 per axis.
    for (j1, j2) in [(9, 9), (15, 15), (16, 16), (2, 5), (1, 7)] {
        let g = geometry((j1, j2));
        let want = ((j1 * j1 - 1) + (j2 * j2 - 1)) as f64 / 12.0;
        let got = spread_moment(g, &vec![17.0; g.cells()]).unwrap();
        assert!(close(got, want, 1e-14, 0.0), "{j1}x{j2}: {got} vs {want}");
    }
    // 9x9 uniform: 13.333...; the brightest cell is the first on ties,
    // (0, 0), whose 3x3 core clips to 2x2: 77 / 81 outside.
    let g = geometry((9, 9));
    let m = vec![1.0; 81];
    assert!(close(spread_moment(g, &m).unwrap(), 40.0 / 3.0, 1e-15, 0.0));
    assert!(close(
        outside_core(g, &m, 1).unwrap(),
        77.0 / 81.0,
        1e-15,
        0.0
    ));
}

#[test]
fn gradient_rule_by_hand() {
    // One row [1, 5, 2]: col 0 -> |5 - 1| (left border is itself), col 1 ->
    // |2 - 1|, col 2 -> |2 - 5|; no vertical part in a single row.
    assert_eq!(neighbour_gradient(&[1.0, 5.0, 2.0], 1, 3), [4.0, 1.0, 3.0]);
    // 3x3 with a spike of 10 at the centre over 1: its four edge
    // neighbours see it on one axis (9), the corners and the spike itself
    // do not (the spike's own neighbours are equal).
    let mut v = vec![1.0; 9];
    v[4] = 10.0;
    assert_eq!(
        neighbour_gradient(&v, 3, 3),
        [0.0, 9.0, 0.0, 9.0, 0.0, 9.0, 0.0, 9.0, 0.0]
    );
    // A ramp 0, 1, 2 down and across: central differences (2 at the
    // centre, 1 at a border) on both axes.
    let ramp: Vec<f64> = (0..9).map(|i| f64::from(i / 3 + i % 3)).collect();
    let g = neighbour_gradient(&ramp, 3, 3);
    assert!(close(g[4], 8f64.sqrt(), 1e-15, 0.0));
    assert!(close(g[0], 2f64.sqrt(), 1e-15, 0.0));
    assert!(close(g[1], 5f64.sqrt(), 1e-15, 0.0));
}

#[test]
fn deviation_rule_by_hand() {
    // The spike stands 9 above the median (1) of its 3x3 window; a corner's
    // window clips to 2x2 = {1, 1, 1, 10}, lower median 1, so 0 there.
    let mut v = vec![1.0; 9];
    v[4] = 10.0;
    let mut want = [0.0; 9];
    want[4] = 9.0;
    assert_eq!(local_deviation(&v, 3, 3, 1), want);
    // A 2x2 block of 10 in the middle of a 4x4 field of 1, 3x3 windows:
    // each block cell's window holds the 4 tens and 5 ones (median 1, so
    // 9); the corner (0, 0) sees {1, 1, 1, 10} and (0, 1) {1 x4, 10 x2}
    // (lower median 1, so 0 for both).
    let mut v = vec![1.0; 16];
    for i in [5, 6, 9, 10] {
        v[i] = 10.0;
    }
    let d = local_deviation(&v, 4, 4, 1);
    for i in [5, 6, 9, 10] {
        assert_eq!(d[i], 9.0);
    }
    assert_eq!(d[0], 0.0);
    assert_eq!(d[1], 0.0);
    // With 5x5 windows (the whole field for every cell) the median is
    // still 1: 4 tens among 9 to 16 values.
    assert!(
        local_deviation(&v, 4, 4, 2)
            .iter()
            .zip(&v)
            .all(|(d, x)| *d == x - 1.0)
    );
    // Half-width 0: the position is its own median.
    assert_eq!(local_deviation(&v, 4, 4, 0), vec![0.0; 16]);
}

/// The device form: `floor(2^8 m)` from integer sums of u16 samples
/// (docs/spread-study.md). Per axis, over row (column) sums `R`:
/// `S1 = Σ j R(j) <= 15 P < 2^28`, `S2 = Σ j² R(j) <= 225 P < 2^32`,
/// `P <= 256 * 65535 < 2^24`; then `N = (S2a + S2b) P - S1a² - S1b²`
/// (= P² m, >= 0, <= 112.5 P²) and `2^8 N <= 28800 P² < 2^63`. Every step
/// is checked, so an overflow fails the test.
fn q8_moment(j1: usize, j2: usize, map: &[u16]) -> Option<u16> {
    let mut rows = vec![0u32; j1];
    let mut cols = vec![0u32; j2];
    for (c, &a) in map.iter().enumerate() {
        rows[c / j2] = rows[c / j2].checked_add(u32::from(a)).unwrap();
        cols[c % j2] = cols[c % j2].checked_add(u32::from(a)).unwrap();
    }
    let p: u32 = rows
        .iter()
        .try_fold(0u32, |s, &r| s.checked_add(r))
        .unwrap();
    if p == 0 {
        return None;
    }
    let moments = |sums: &[u32]| {
        let (mut s1, mut s2) = (0u32, 0u32);
        for (j, &r) in sums.iter().enumerate() {
            let j = j as u32;
            s1 = s1.checked_add(j.checked_mul(r).unwrap()).unwrap();
            s2 = s2.checked_add((j * j).checked_mul(r).unwrap()).unwrap();
        }
        (s1, s2)
    };
    let (s1a, s2a) = moments(&rows);
    let (s1b, s2b) = moments(&cols);
    let p = u64::from(p);
    let n = (u64::from(s2a) + u64::from(s2b))
        .checked_mul(p)
        .unwrap()
        .checked_sub(u64::from(s1a) * u64::from(s1a))
        .unwrap()
        .checked_sub(u64::from(s1b) * u64::from(s1b))
        .unwrap();
    let q = n.checked_mul(256).unwrap() / (p * p);
    Some(u16::try_from(q).unwrap())
}

fn q8_agrees(j1: usize, j2: usize, map: &[u16]) {
    let g = geometry((j1, j2));
    let f: Vec<f64> = map.iter().map(|&a| f64::from(a)).collect();
    match (q8_moment(j1, j2, map), spread_moment(g, &f)) {
        (None, None) => {}
        (Some(q), Some(m)) => {
            // floor of the exact value: within one step below the f64, never above.
            let scaled = 256.0 * m;
            assert!(
                f64::from(q) <= scaled + 1e-6 && scaled < f64::from(q) + 1.0 + 1e-6,
                "{j1}x{j2}: {q} vs {scaled}"
            );
        }
        other => panic!("dark disagreement {other:?}"),
    }
}

#[test]
fn integer_form_fits_its_bounds_on_the_extreme_16x16_maps() {
    // Full scale everywhere: (255 + 255) / 12 = 42.5 cells², 10880 in Q8.
    let full = vec![65535u16; 256];
    assert_eq!(q8_moment(16, 16, &full), Some(10880));
    // All the power in two opposite corners: the largest moment, 2 * 7.5^2
    // = 112.5 cells², 28800 in Q8.
    let mut corners = vec![0u16; 256];
    corners[0] = 65535;
    corners[255] = 65535;
    assert_eq!(q8_moment(16, 16, &corners), Some(28800));
    // The four corners at full scale with everything else: the sums at
    // their largest together.
    let mut heavy = full.clone();
    heavy[1] = 0;
    q8_agrees(16, 16, &heavy);
    q8_agrees(16, 16, &corners);
    q8_agrees(9, 9, &[0; 81]);
}

/// The device form of [`outside_core`]: `floor(2^16 (P - core) / P)` by
/// long division in base 2^8, every partial remainder below
/// `P * 2^8 <= 256 * 65535 * 2^8 < 2^32`. The brightest cell is in the
/// core, so `P - core < P` and the quotient fits 16 bits.
fn q16_outside(j1: usize, j2: usize, map: &[u16], half: usize) -> Option<u16> {
    let p: u32 = map.iter().map(|&a| u32::from(a)).sum();
    if p == 0 {
        return None;
    }
    let mut peak = 0;
    for (c, &a) in map.iter().enumerate() {
        if a > map[peak] {
            peak = c;
        }
    }
    let (p1, p2) = (peak / j2, peak % j2);
    let mut core = 0u32;
    for i1 in p1.saturating_sub(half)..(p1 + half + 1).min(j1) {
        for i2 in p2.saturating_sub(half)..(p2 + half + 1).min(j2) {
            core += u32::from(map[i1 * j2 + i2]);
        }
    }
    let (mut q, mut r) = (0u32, p - core);
    for _ in 0..2 {
        r = r.checked_shl(8).filter(|_| r < 1 << 24).unwrap();
        q = (q << 8) | (r / p);
        r %= p;
    }
    Some(u16::try_from(q).unwrap())
}

fn q16_agrees(j1: usize, j2: usize, map: &[u16], half: usize) {
    let g = geometry((j1, j2));
    let f: Vec<f64> = map.iter().map(|&a| f64::from(a)).collect();
    match (q16_outside(j1, j2, map, half), outside_core(g, &f, half)) {
        (None, None) => {}
        (Some(q), Some(x)) => {
            let scaled = 65536.0 * x;
            assert!(
                f64::from(q) <= scaled + 1e-6 && scaled < f64::from(q) + 1.0 + 1e-6,
                "{j1}x{j2}: {q} vs {scaled}"
            );
        }
        other => panic!("dark disagreement {other:?}"),
    }
}

#[test]
fn outside_core_integer_form_by_hand_and_at_full_scale() {
    // Full scale everywhere on 16x16: the first cell is the brightest, its
    // 5x5 core clips to 3x3, 247 / 256 outside: 63232 in Q16.
    let full = vec![65535u16; 256];
    assert_eq!(q16_outside(16, 16, &full, 2), Some(63232));
    // A peak inside with everything else at full scale just below it:
    // the largest share outside a 5x5 core, 231 / 256 of nearly equal cells.
    let mut inner = vec![65534u16; 256];
    inner[8 * 16 + 8] = 65535;
    q16_agrees(16, 16, &inner, 2);
    // One cell lit: nothing outside. Two cells 1:3, the smaller outside.
    let mut two = vec![0u16; 81];
    two[0] = 100;
    assert_eq!(q16_outside(9, 9, &two, 2), Some(0));
    two[80] = 300;
    assert_eq!(q16_outside(9, 9, &two, 2), Some(16384));
    q16_agrees(9, 9, &[0; 81], 1);
}

fn u16_map(cells: usize) -> impl Strategy<Value = Vec<u16>> {
    prop_oneof![
        prop::collection::vec(0u16..=65535, cells),
        prop::collection::vec(prop_oneof![4 => Just(0u16), 1 => 1u16..4096], cells),
        prop::collection::vec(0u16..3, cells),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn integer_form_is_the_floor_of_the_f64_moment(
        (j, map) in prop::sample::select(GEOMETRIES).prop_flat_map(|j| (Just(j), u16_map(j.0 * j.1)))
    ) {
        q8_agrees(j.0, j.1, &map);
        for half in 0..3 {
            q16_agrees(j.0, j.1, &map, half);
        }
    }

    #[test]
    fn moment_ignores_power_and_position_and_stays_in_its_bound(
        (j, map, k, s1, s2) in prop::sample::select(&[(3usize, 3usize), (5, 4), (9, 9)][..])
            .prop_flat_map(|j| (Just(j), raw_map(j.0 * j.1), 1u32..1000, 0usize..4, 0usize..4))
    ) {
        let g = geometry(j);
        let Some(m) = spread_moment(g, &map) else {
            return Ok(());
        };
        // Largest moment on J cells per axis: half the mass at each end, ((J - 1) / 2)².
        let bound = ((j.0 - 1) as f64 / 2.0).powi(2) + ((j.1 - 1) as f64 / 2.0).powi(2);
        prop_assert!(m >= 0.0 && m <= bound * (1.0 + 1e-12), "{m} > {bound}");
        let scaled: Vec<f64> = map.iter().map(|&a| a * f64::from(k)).collect();
        prop_assert!(close(spread_moment(g, &scaled).unwrap(), m, 1e-12, 1e-12));
        // The same map moved by (s1, s2) cells on a larger detector.
        let big = geometry((j.0 + s1, j.1 + s2));
        let mut moved = vec![0.0; big.cells()];
        for (c, &a) in map.iter().enumerate() {
            let (i1, i2) = g.cell(c);
            moved[big.index(i1 + s1, i2 + s2)] = a;
        }
        prop_assert!(close(spread_moment(big, &moved).unwrap(), m, 1e-12, 1e-12));
        let core = outside_core(g, &map, 1).unwrap();
        prop_assert!((0.0..=1.0).contains(&core));
    }
}
