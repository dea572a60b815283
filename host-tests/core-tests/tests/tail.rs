//! The tail rule (`cvm_core::calibration::tail`): its integer logarithm and
//! power of two against `f64`, the fit and threshold against the `f64`
//! reference (`cvm_reference::exp_tail`) on the same bin representatives,
//! hand-computed cases, and the properties a target rate must have.

use cvm_core::calibration::histogram::{bin_of, bin_range, representative};
use cvm_core::calibration::tail::{EXP2_NEG_Q32, LN2_Q32, exp2_neg_q32, log2_q24};
use cvm_core::calibration::{Calibrator, Rule};
use cvm_core_tests::rng;
use cvm_reference::{ExpTail, exp_tail};
use proptest::prelude::*;
use rand::RngExt;

const Q24: f64 = (1u64 << 24) as f64;

fn feed(cvm: &[u32], scans: u16) -> Calibrator {
    let mut c = Box::new(Calibrator::new());
    for &m in cvm {
        c.add(m, 0, 0);
    }
    for _ in 0..scans {
        c.end_scan();
    }
    *c
}

fn tail(rate_ppm: u32, tail_ppm: u32) -> Rule {
    Rule::Tail { rate_ppm, tail_ppm }
}

/// The reference on what the calibrator sees: each value as its bin's
/// representative capped at the maximum, the start the top of the bin of
/// the nearest-rank `1 - f` quantile capped at the maximum.
fn reference(values: &[u32], tail_ppm: u32) -> (ExpTail, u32) {
    let max = *values.iter().max().unwrap();
    let mut v = values.to_vec();
    v.sort_unstable();
    let n = v.len() as u64;
    let keep = 1_000_000 - tail_ppm.min(1_000_000) as u64;
    // At most n - 10: ten values in the tail when there are more.
    let rank = ((keep * n).div_ceil(1_000_000))
        .clamp(1, n)
        .min(n.saturating_sub(10))
        .max(1) as usize;
    let start = bin_range(bin_of(v[rank - 1])).1.min(max);
    let reps: Vec<f64> = v
        .iter()
        .map(|&x| representative(bin_of(x)).min(max) as f64)
        .collect();
    (exp_tail(&reps, start as f64), max)
}

#[test]
fn log2_and_exp2_against_f64() {
    assert_eq!(log2_q24(0), 0);
    assert_eq!(log2_q24(1), 0);
    for e in 1..64 {
        assert_eq!(log2_q24(1 << e), (e as u64) << 24, "2^{e}");
    }
    let mut r = rng(7);
    for _ in 0..20_000 {
        let shift = r.random_range(0..62);
        let x: u64 = r.random_range(2..=u64::MAX >> shift);
        let got = log2_q24(x) as f64 / Q24;
        let want = (x as f64).log2();
        // Truncated: at most 2^-24 below, never above (up to f64's own
        // rounding of x and of log2).
        assert!(
            got <= want + 1e-12 && got > want - 2.0 / Q24,
            "{x}: {got} {want}"
        );
    }
    assert_eq!(
        LN2_Q32,
        (std::f64::consts::LN_2 * 2f64.powi(32)).round() as u64
    );
    for (k, &t) in EXP2_NEG_Q32.iter().enumerate() {
        let want = 2f64.powf(-(0.5f64.powi(k as i32 + 1))) * 2f64.powi(32);
        assert!((t as f64 - want).abs() <= 0.5, "table {k}");
    }
    assert_eq!(exp2_neg_q32(0), 1 << 32);
    assert_eq!(exp2_neg_q32(1 << 24), 1 << 31);
    assert_eq!(exp2_neg_q32(64 << 24), 0);
    for _ in 0..20_000 {
        let y: u64 = r.random_range(0..40u64 << 24);
        let got = exp2_neg_q32(y) as f64;
        let want = 2f64.powf(-(y as f64) / Q24) * 2f64.powi(32);
        // Rounded down at most once per factor (24) and at the shift.
        assert!(
            got <= want + 1e-6 && got >= want * (1.0 - 1e-8) - 26.0,
            "{y}: {got} {want}"
        );
    }
}

#[test]
fn hand_computed_tail_threshold_and_rate() {
    // 1..=100, one scan, top 10 %: rank 90, u = 90 (exact bins); the tail
    // is 91..=100, N_u = 10, E = 55, s = 5.5. One false position in 1000
    // parts: t = 90 + 5.5 ln(10 / 0.001) = 90 + 50.6569, thr = 141.
    let values: Vec<u32> = (1..=100).collect();
    let s = feed(&values, 1)
        .statistics(&tail(1000, 100_000))
        .unwrap()
        .cvm;
    assert_eq!((s.tail.start, s.tail.count, s.tail.excess), (90, 10, 55));
    assert_eq!((s.quantile, s.threshold, s.max), (90, 141, 100));
    // At 141: 10 exp(-51 / 5.5) = 9.395193e-4 per part.
    let ppb = s.rate_ppb.unwrap();
    assert!((939_519..=939_521).contains(&ppb), "{ppb}");
    // Median 50 (lower median of 1..=100): the smallest detected rise 91.
    assert_eq!((s.median, s.min_strength), (50, 91));
    // Ten scans of the same: a part is a tenth of the positions, the same
    // tail a tenth as frequent: t = 90 + 5.5 ln(10 / 0.01) = 127.99, 128.
    let s = feed(&values, 10)
        .statistics(&tail(1000, 100_000))
        .unwrap()
        .cvm;
    assert_eq!(s.threshold, 128);
    // A lenient target (N_u / S below it) leaves the floor, max + 1.
    let s = feed(&values, 1)
        .statistics(&tail(1_000_000_000, 100_000))
        .unwrap()
        .cvm;
    assert_eq!(s.threshold, 101);
    // No tail (every value in one bin): max + 1, no rate.
    let s = feed(&[7; 50], 1).statistics(&Rule::TAIL).unwrap().cvm;
    assert_eq!((s.threshold, s.tail.count, s.rate_ppb), (8, 0, None));
    // The spread rule reports the fit's rate at its own threshold: 1..=100
    // with k = 3: median 50, MAD 25, thr = 100 + ceil(111.195) + 1 = 213;
    // the fit of the top 1 % takes at least ten values (rank 90: the same
    // tail as above), and predicts 10 exp(-123 / 5.5) = 1.94e-9 per part
    // there: rounded up, 2 per 10^9 parts.
    let s = feed(&values, 1).statistics(&Rule::SPREAD).unwrap().cvm;
    assert_eq!((s.threshold, s.tail.start, s.tail.count), (213, 90, 10));
    assert_eq!(s.rate_ppb, Some(2));
    // A fit far past 2^-64: 0 per 10^9 parts.
    let s = feed(&values, 1)
        .statistics(&Rule::Spread {
            quantile_ppm: 1_000_000,
            k_milli: 100_000,
        })
        .unwrap()
        .cvm;
    assert_eq!(s.rate_ppb, Some(0));
}

/// Magnitudes with a tail: a bulk and an exponential-like tail of a random
/// scale, or anything.
fn magnitudes() -> impl Strategy<Value = Vec<u32>> {
    prop_oneof![
        (1u32..1_000_000, 1u32..100_000, 50usize..3000, any::<u64>()).prop_map(
            |(base, scale, n, seed)| {
                let mut r = rng(seed);
                (0..n)
                    .map(|_| {
                        let u: f64 = r.random_range(1e-12..1.0);
                        (base as f64 - scale as f64 * u.ln()).min(u32::MAX as f64) as u32
                    })
                    .collect()
            }
        ),
        prop::collection::vec(any::<u32>(), 1..500),
        prop::collection::vec(0u32..300, 1..500),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// The integer threshold and rate against the f64 formulas on the same
    /// representatives: within one unit plus the logarithm's truncation
    /// (2^-22 of a scale per unit of ln, well under 10^-6 s), and the rate
    /// within 10^-6 relative plus the rounding up.
    #[test]
    fn fit_matches_the_f64_reference(
        values in magnitudes(),
        scans in 1u16..50,
        rate_ppm in prop_oneof![Just(1000u32), 1u32..2_000_000],
        tail_ppm in prop_oneof![Just(10_000u32), 1u32..=1_000_000],
    ) {
        let s = feed(&values, scans).statistics(&tail(rate_ppm, tail_ppm)).unwrap().cvm;
        let (r, max) = reference(&values, tail_ppm);
        prop_assert_eq!(s.tail.start as f64, r.start);
        prop_assert_eq!(s.tail.count as usize, r.count);
        if r.count == 0 {
            prop_assert_eq!(s.threshold, max.saturating_add(1));
            prop_assert_eq!(s.rate_ppb, None);
            return Ok(());
        }
        let want = r.threshold(scans as usize, rate_ppm as f64 / 1e6).ceil()
            .max(max as f64 + 1.0).min(u32::MAX as f64);
        let slack = 1.0 + 1e-6 * r.scale + 1e-9 * want;
        prop_assert!((s.threshold as f64 - want).abs() <= slack,
            "thr {} want {want} (scale {})", s.threshold, r.scale);
        // Never below the maximum plus one.
        prop_assert!(s.threshold as u64 > max as u64 || s.threshold == u32::MAX);
        let rate = r.rate_at(scans as usize, s.threshold as f64) * 1e9;
        let got = s.rate_ppb.unwrap() as f64;
        prop_assert!(got >= rate * (1.0 - 1e-6) - 1e-9 && got <= rate * (1.0 + 1e-6) + 1.0,
            "rate {got} want {rate}");
        // At the target's threshold the estimate meets the target (but for
        // the threshold's rounding and the floor, which only lower it), unless
        // the threshold saturated at the largest magnitude.
        prop_assert!(s.threshold == u32::MAX || got <= rate_ppm as f64 * 1000.0 * (1.0 + 1e-5) + 1.0);
        prop_assert_eq!(s.min_strength, s.threshold.saturating_sub(s.median));
    }

    /// A lower target rate never lowers the threshold; more scans of the
    /// same magnitudes (a part is fewer of them) never raise it.
    #[test]
    fn monotone_in_the_target_and_the_scans(
        values in magnitudes(),
        a in 1u32..1_000_000,
        b in 1u32..1_000_000,
        scans in 1u16..100,
    ) {
        let c = feed(&values, scans);
        let thr = |rate| c.statistics(&tail(rate, 10_000)).unwrap().cvm.threshold;
        let (lo, hi) = (a.min(b), a.max(b));
        prop_assert!(thr(lo) >= thr(hi));
        let more = feed(&values, scans + 1).statistics(&tail(lo, 10_000)).unwrap().cvm;
        prop_assert!(more.threshold <= thr(lo));
    }
}

/// Parts of 20 000 positions drawn from `base + Exp(scale)`: the exact
/// threshold for one false position in 1000 parts is
/// `base + scale ln(20 000 / 0.001)`. With more reference parts of the
/// same distribution, the fitted scale and threshold converge on it.
#[test]
fn more_reference_scans_converge_on_the_true_threshold() {
    let (base, scale, per_part) = (50_000.0, 4000.0, 20_000usize);
    let truth = base + scale * (per_part as f64 / 1e-3).ln();
    let mut r = rng(36);
    let mut c = Box::new(Calibrator::new());
    let mut errors = Vec::new();
    for scans in 1..=64u16 {
        for _ in 0..per_part {
            let u: f64 = r.random_range(1e-12..1.0);
            c.add((base - scale * u.ln()) as u32, 0, 0);
        }
        c.end_scan();
        if [2, 8, 64].contains(&scans) {
            let s = c.statistics(&Rule::TAIL).unwrap().cvm;
            let fitted = s.tail.excess as f64 / s.tail.count as f64;
            errors.push((
                (fitted / scale - 1.0).abs(),
                (s.threshold as f64 - truth).abs() / (truth - base),
            ));
        }
    }
    // Standard error of the scale from N_u = 200 S tail values: 1/sqrt(N_u)
    // (7 % at S = 2, 0.9 % at 64); bins add under 0.4 % of the value.
    let (s2, s64) = (errors[0], errors[2]);
    assert!(s64.0 < 0.03 && s64.1 < 0.03, "{errors:?}");
    assert!(
        s64.0 < s2.0.max(0.01) && s64.1 < s2.1.max(0.01),
        "{errors:?}"
    );
}
