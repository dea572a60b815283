//! The pooled decisions' fixed point (`cvm_core::channels::pooled`)
//! against their definitions in f64: the gain table, the loss and the
//! raise for any sums the engine can hold, hand-computed cases, and the
//! gain's purpose checked by simulation: every footprint's value has the
//! noise of one position against its eight neighbours.

use cvm_core::channels::pooled::{GAIN_FRAC, MAX_POSITIONS, gain, loss, raise};
use cvm_core_tests::rng;
use proptest::prelude::*;
use rand::RngExt;

/// Largest map power: 256 cells at full scale.
const P_MAX: u32 = 256 * 65_535;

fn gain_f64(k: u32, m: u32) -> f64 {
    let (k, m) = (k as f64, m as f64);
    (1.125 / (1.0 / k + 1.0 / m)).sqrt()
}

/// The loss by its definition: integer means, the `Q15` ratio, the gain.
fn loss_ref(sum_f: u64, k: u32, sum_r: u64, m: u32) -> u32 {
    let (mf, mr) = (sum_f / k as u64, sum_r / m as u64);
    if mr <= mf {
        return 0;
    }
    let ratio = ((mr - mf) << 15) / mr;
    ((ratio * gain(k, m) as u64) >> GAIN_FRAC) as u32
}

#[test]
fn gains_are_the_floor_of_their_definition() {
    for k in 1..=MAX_POSITIONS {
        for m in 1..=MAX_POSITIONS {
            let want = (gain_f64(k, m) * (1u32 << GAIN_FRAC) as f64).floor() as u32;
            assert_eq!(gain(k, m), want, "gain({k}, {m})");
        }
    }
    // One position against its eight neighbours is the unit.
    assert_eq!(gain(1, 8), 1 << GAIN_FRAC);
    // Nothing to pool, or too much.
    assert_eq!(gain(0, 8), 0);
    assert_eq!(gain(1, 0), 0);
    assert_eq!(gain(MAX_POSITIONS + 1, 8), 0);
    assert_eq!(gain(4, MAX_POSITIONS + 1), 0);
}

#[test]
fn hand_computed_cases() {
    // A position that lost 10 % against eight neighbours at 10^6:
    // floor(0.1 2^15) = 3276, gain 1.
    assert_eq!(loss(900_000, 1, 8_000_000, 8), 3276);
    // Brighter than its ring, or equal: no loss.
    assert_eq!(loss(1_100_000, 1, 8_000_000, 8), 0);
    assert_eq!(loss(1_000_000, 1, 8_000_000, 8), 0);
    // Two positions that lost 10 % each against ten: the same ratio, and
    // the gain sqrt(1.125 / (1/2 + 1/10)) = 1.3693 (Q14 22434).
    assert_eq!(gain(2, 10), 22_434);
    assert_eq!(loss(1_800_000, 2, 10_000_000, 10), (3276 * 22_434) >> 14);
    // A dark ring, an empty footprint or ring.
    assert_eq!(loss(0, 1, 0, 8), 0);
    assert_eq!(loss(5, 0, 8_000_000, 8), 0);
    assert_eq!(loss(5, 1, 8_000_000, 0), 0);
    // A footprint whose spread is 300 (Q16) above a ring at 200.
    assert_eq!(raise(500, 1, 1600, 8), 300);
    assert_eq!(raise(800, 2, 2000, 10), (200 * 22_434) >> 14);
    assert_eq!(raise(200, 1, 1600, 8), 0);
    assert_eq!(raise(100, 1, 1600, 8), 0);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20_000))]

    /// Any sums the engine can hold: the definition exactly, no overflow,
    /// and within one `Q15` step (scaled) of the real-valued loss.
    #[test]
    fn loss_is_its_definition(
        k in 1..=4u32, m in 1..=MAX_POSITIONS,
        pf in 0..=P_MAX, pr in 0..=P_MAX, df in 0..=P_MAX, dr in 0..=P_MAX,
    ) {
        // Sums of k and m powers: the extremes and a spread between them.
        let sum_f = (pf as u64 * k as u64 - (df as u64 % (k as u64))).min(k as u64 * P_MAX as u64);
        let sum_r = (pr as u64 * m as u64 - (dr as u64 % (m as u64))).min(m as u64 * P_MAX as u64);
        let got = loss(sum_f as u32, k, sum_r as u32, m);
        prop_assert_eq!(got, loss_ref(sum_f, k, sum_r, m));
        let (mf, mr) = (sum_f as f64 / k as f64, sum_r as f64 / m as f64);
        let real = if mr > mf { (mr - mf) / mr * gain_f64(k, m) * 32768.0 } else { 0.0 };
        // Flooring the means moves the ratio by at most 2/mean_R; the
        // ratio's floor by one step (times the gain), the gain's floor by
        // one part in its Q14 value, the product's floor by one.
        let g = gain_f64(k, m);
        let slack = 1.0 + g + real / gain(k, m) as f64 + 32768.0 * 2.0 * g / mr.max(1.0);
        prop_assert!((got as f64 - real).abs() <= slack, "{} vs {} slack {} k {} m {} mf {} mr {}", got, real, slack, k, m, mf, mr);
    }

    /// The raise: the definition, within two `Q16` steps (scaled) of the
    /// real-valued difference of means.
    #[test]
    fn raise_is_its_definition(
        k in 1..=4u32, m in 1..=MAX_POSITIONS, qf in 0..=65_535u32, qr in 0..=65_535u32,
    ) {
        let (sum_f, sum_r) = (qf * k, qr * m);
        let got = raise(sum_f, k, sum_r, m);
        let want = if qf > qr { ((qf - qr) * gain(k, m)) >> GAIN_FRAC } else { 0 };
        prop_assert_eq!(got, want);
        let real = (qf as f64 - qr as f64).max(0.0) * gain_f64(k, m);
        prop_assert!((got as f64 - real).abs() <= 2.0 + qf as f64 / 16384.0);
    }
}

/// The largest sums do not overflow and give the largest values.
#[test]
fn extremes() {
    for k in 1..=MAX_POSITIONS {
        for m in 1..=MAX_POSITIONS {
            assert_eq!(loss(0, k, m * P_MAX, m), (32_768 * gain(k, m)) >> GAIN_FRAC);
            assert_eq!(loss(k * P_MAX, k, m * P_MAX, m), 0);
            assert_eq!(
                raise(k * 65_535, k, 0, m),
                (65_535 * gain(k, m)) >> GAIN_FRAC
            );
        }
    }
}

/// What the gain is for: with independent Gaussian noise of 2 % on every
/// power, each footprint's scaled loss (taken signed, from the same
/// formula) has the standard deviation of one position against its eight
/// neighbours, 2 % sqrt(1 + 1/8) = 2.12 %, within 3 %.
#[test]
fn every_footprint_has_the_noise_of_one_position_against_eight() {
    let mut r = rng(50);
    let nominal = 4_000_000.0f64;
    let sigma = 0.02;
    for (k, m) in [(1, 8), (2, 10), (2, 7), (4, 8), (1, 5), (3, 12)] {
        let n = 60_000;
        let mut sum2 = 0.0;
        for _ in 0..n {
            let mut draw = || {
                // Box-Muller from two uniforms.
                let (u, v): (f64, f64) = (r.random(), r.random());
                let z = (-2.0 * (1.0 - u).ln()).sqrt() * (std::f64::consts::TAU * v).cos();
                (nominal * (1.0 + sigma * z)) as u32
            };
            let sum_f: u32 = (0..k).map(|_| draw()).sum();
            let sum_r: u32 = (0..m).map(|_| draw()).sum();
            // Signed: the loss when darker, minus the loss of the mirror
            // image (ring and footprint swapped by their means) when not.
            let (mf, mr) = (sum_f / k, sum_r / m);
            let v = if mr > mf {
                loss(sum_f, k, sum_r, m) as f64
            } else {
                -(((mf - mr) as f64 / mr as f64) * 32768.0 * gain(k, m) as f64 / 16384.0)
            };
            sum2 += v * v;
        }
        let sd = (sum2 / n as f64).sqrt() / 32768.0;
        let want = sigma * 1.125f64.sqrt();
        assert!(
            (sd / want - 1.0).abs() < 0.03,
            "footprint {k} against {m}: sd {sd:.5}, want {want:.5}"
        );
    }
}
