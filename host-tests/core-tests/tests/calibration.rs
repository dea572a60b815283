//! The streaming calibration (`cvm_core::calibration`) against a
//! brute-force reference of the rule as docs/experiments.md and the
//! module's documentation state it: every magnitude replaced by its bin's
//! representative, sorted, lower medians picked by rank, the margin
//! computed as an exact rational in `u128`. Then the pipeline's hook
//! against feeding the same positions directly.

use cvm_core::Position;
use cvm_core::calibration::histogram::{MANTISSA_BITS, bin_of, bin_range, bins};
use cvm_core::calibration::{
    CALIBRATOR_BYTES, CVM_BINS, CalibrationError, Calibrator, Channel, POWER_BINS, Progress, Rule,
    SPREAD_BINS,
};
use cvm_core::pipeline::{Pipeline, Settings};
use cvm_core::power::{POWER_MAX, POWER_OFF};
use cvm_core::protocol::{LineSink, Priority};
use cvm_core::spread::{SPREAD_MAX, SPREAD_OFF};
use cvm_core_tests::{random_scan, rng, run_engine_thresholds};
use proptest::prelude::*;

/// The documented quantisation, written from the definition: below
/// `2^(M+1)` a value is its own bin; above, with `e = floor(log2 v)`, the
/// bins are `w = 2^(e - M)` wide and start at multiples of `w`.
/// Returns (lowest, highest, representative) of `v`'s bin.
fn bin_ref(v: u32) -> (u64, u64, u64) {
    let v = v as u64;
    if v < 1 << (MANTISSA_BITS + 1) {
        return (v, v, v);
    }
    let e = 63 - v.leading_zeros() as u64;
    let w = 1u64 << (e - MANTISSA_BITS as u64);
    let lo = v / w * w;
    (lo, lo + w - 1, lo + w / 2)
}

/// `ceil(k * 1.4826 * mad)` with `k = k_milli / 1000`, exactly.
fn margin_ref(k_milli: u32, mad: u64) -> u128 {
    (k_milli as u128 * 14826 * mad as u128).div_ceil(10_000_000)
}

/// A channel's spread-rule fields: positions, max, quantile, median, MAD,
/// threshold and the minimum strength.
fn spread(c: &Channel) -> [u32; 7] {
    [
        c.positions,
        c.max,
        c.quantile,
        c.median,
        c.mad,
        c.threshold,
        c.min_strength,
    ]
}

/// The spread rule on one channel's values, brute force.
fn channel_ref(values: &[u32], rule: &Rule) -> Channel {
    let &Rule::Spread {
        quantile_ppm,
        k_milli,
    } = rule
    else {
        unreachable!("the spread rule")
    };
    let n = values.len();
    let mut v = values.to_vec();
    v.sort_unstable();
    let reps: Vec<u64> = v.iter().map(|&x| bin_ref(x).2).collect();
    // Lower median: rank ceil(n / 2), 1-based.
    let mid = n.div_ceil(2) - 1;
    let median = reps[mid];
    let mut dev: Vec<u64> = reps.iter().map(|&r| r.abs_diff(median)).collect();
    dev.sort_unstable();
    let mad = dev[mid];
    let rank = ((quantile_ppm as u128 * n as u128).div_ceil(1_000_000) as usize).clamp(1, n);
    let max = *v.last().unwrap();
    let quantile = bin_ref(v[rank - 1]).1.min(max as u64);
    let thr = (quantile as u128 + margin_ref(k_milli, mad) + 1).min(u32::MAX as u128);
    Channel {
        positions: n as u32,
        max,
        quantile: quantile as u32,
        median: median as u32,
        mad: mad as u32,
        threshold: thr as u32,
        min_strength: (thr as u32).saturating_sub(median as u32),
        ..Channel::default()
    }
}

fn feed(cvm: &[u32], power: &[u16]) -> Calibrator {
    feed3(cvm, power, &vec![0; cvm.len()])
}

fn feed3(cvm: &[u32], power: &[u16], spread: &[u32]) -> Calibrator {
    let mut c = Box::new(Calibrator::new());
    for ((&m, &p), &s) in cvm.iter().zip(power).zip(spread) {
        c.add(m, p, s);
    }
    *c
}

#[test]
fn bins_tile_the_values_as_documented() {
    let mut next = 0u64;
    for b in 0..bins(32) {
        let (lo, hi) = bin_range(b);
        assert_eq!(lo as u64, next, "bin {b}");
        assert_eq!(bin_ref(lo), bin_ref(hi), "bin {b}");
        assert_eq!((bin_ref(lo).0, bin_ref(lo).1), (lo as u64, hi as u64));
        assert_eq!((bin_of(lo), bin_of(hi)), (b, b));
        next = hi as u64 + 1;
    }
    assert_eq!(next, 1 << 32);
    assert_eq!(bins(32), CVM_BINS);
    assert_eq!(bin_of(u32::MAX), CVM_BINS - 1);
    assert_eq!(bin_of(u16::MAX as u32), POWER_BINS - 1);
    // Exact below 2^(M+1); relative width under 2^-M above.
    assert_eq!(bin_range(bin_of(255)), (255, 255));
    assert_eq!(bin_range(bin_of(256)), (256, 257));
    for v in [256u32, 1000, 5_668_864, 1 << 31, u32::MAX] {
        let (lo, hi) = bin_range(bin_of(v));
        assert!((hi - lo + 1) as f64 / lo as f64 <= 1.0 / 128.0, "{v}");
    }
}

#[test]
fn hand_computed_rule() {
    // 1..=9 and 100, all exact: lower median 5; deviations 4 3 2 1 0 1 2 3
    // 4 95, sorted 0 1 1 2 2 ..., lower median 2; k = 2: margin
    // ceil(2 * 1.4826 * 2) = ceil(5.9304) = 6, thr = 100 + 6 + 1.
    let cvm = [1, 2, 3, 4, 5, 6, 7, 8, 9, 100];
    let rule = Rule::Spread {
        quantile_ppm: 1_000_000,
        k_milli: 2000,
    };
    let c = feed(&cvm, &[0; 10]);
    let s = c.statistics(&rule).unwrap();
    assert_eq!(
        (s.cvm.max, s.cvm.median, s.cvm.mad, s.cvm.threshold),
        (100, 5, 2, 107)
    );
    // p = 0.9: rank 9, the value 9; k = 0: thr 10.
    let p9 = Rule::Spread {
        quantile_ppm: 900_000,
        k_milli: 0,
    };
    assert_eq!(c.statistics(&p9).unwrap().cvm.threshold, 10);
    // Above 256: 1000 is in [1000, 1003] (width 4, representative 1002),
    // 70000 in [69632, 70143] (width 512, representative 69888).
    assert_eq!(bin_range(bin_of(1000)), (1000, 1003));
    assert_eq!(bin_range(bin_of(70000)), (69632, 70143));
    let c = feed(&[1000, 1001, 70000], &[0; 3]);
    let s = c.statistics(&Rule::SPREAD).unwrap().cvm;
    // Representatives 1002 1002 69888: median 1002, deviations 0 0 68886,
    // MAD 0; thr = max + 0 + 1.
    assert_eq!((s.median, s.mad, s.threshold), (1002, 0, 70001));
    // The spread rule's defaults: margin ceil(3 * 1.4826 * MAD).
    let c = feed(&[10, 20, 30], &[0; 3]);
    let s = c.statistics(&Rule::SPREAD).unwrap().cvm;
    // median 20, deviations 10 0 10, MAD 10: ceil(44.478) = 45.
    assert_eq!((s.median, s.mad, s.threshold), (20, 10, 30 + 45 + 1));
}

#[test]
fn power_threshold_above_every_magnitude_is_off() {
    // Power magnitudes 0 and 40000 (a dark neighbour): median 0, MAD 0;
    // thr 40001 stays.
    let c = feed(&[5, 5], &[0, 40000]);
    assert_eq!(c.finish(&Rule::SPREAD).unwrap().power_threshold, 40001);
    let c = feed(&[5, 5], &[POWER_MAX as u16, 0]);
    let s = c.statistics(&Rule::SPREAD).unwrap();
    assert_eq!(s.power.threshold, POWER_OFF);
    assert_eq!(s.cvm.threshold, 6);
    // A margin past the largest magnitude turns the power channel off and
    // saturates the CVM one.
    let c = feed(&[0, 1000, 100_000], &[0, 100, 2000]);
    let big = Rule::Spread {
        quantile_ppm: 1_000_000,
        k_milli: u32::MAX,
    };
    let s = c.finish(&big).unwrap();
    assert_eq!((s.threshold, s.power_threshold), (u32::MAX, POWER_OFF));
}

#[test]
fn spread_threshold_above_every_magnitude_is_off() {
    // Spread magnitudes 0 and 90000: median 0, MAD 0; thr 90001 stays
    // (at most SPREAD_MAX = 92680).
    let c = feed3(&[5, 5], &[0, 0], &[0, 90000]);
    let r = c.finish(&Rule::SPREAD).unwrap();
    assert_eq!(
        (r.spread_threshold, r.spread_median, r.spread_mad),
        (90001, 0, 0)
    );
    // The largest magnitude itself: thr SPREAD_MAX + 1 is off.
    let c = feed3(&[5, 5], &[0, 0], &[SPREAD_MAX, 0]);
    let s = c.statistics(&Rule::SPREAD).unwrap();
    assert_eq!(s.spread.threshold, SPREAD_OFF);
    assert_eq!(s.spread.min_strength, u32::MAX);
    assert_eq!(s.cvm.threshold, 6);
    // A value past SPREAD_MAX (the engine never gives one) counts as
    // SPREAD_MAX, never as a lost position.
    let c = feed3(&[5], &[0], &[u32::MAX]);
    let s = c.statistics(&Rule::SPREAD).unwrap();
    assert_eq!((s.spread.max, s.spread.threshold), (SPREAD_MAX, SPREAD_OFF));
}

#[test]
fn nothing_taken_and_too_many_positions_are_errors() {
    let mut c = Box::new(Calibrator::new());
    assert_eq!(c.finish(&Rule::DEFAULT), Err(CalibrationError::NoPositions));
    c.add(7, 1, 3);
    // Doubling by merging a copy: 2^31 positions after 31 merges, the 32nd
    // would make 2^32.
    for _ in 0..31 {
        let copy = c.clone();
        c.merge(&copy);
    }
    assert_eq!(c.positions(), 1 << 31);
    assert!(c.finish(&Rule::DEFAULT).is_ok());
    let copy = c.clone();
    c.merge(&copy);
    assert_eq!(c.positions(), 1 << 31, "an overflowing merge adds nothing");
    assert_eq!(
        c.finish(&Rule::DEFAULT),
        Err(CalibrationError::TooManyPositions)
    );
}

#[test]
fn memory_is_bounded() {
    let counts = 4 * (CVM_BINS + POWER_BINS + SPREAD_BINS);
    assert_eq!(CALIBRATOR_BYTES, core::mem::size_of::<Calibrator>());
    assert!(
        // Besides the counts: each histogram's few counters, the scans and
        // the progress.
        CALIBRATOR_BYTES >= counts && CALIBRATOR_BYTES <= counts + 48,
        "{CALIBRATOR_BYTES}"
    );
    // 26, 10 and 11 octaves of 128 bins above the 256 exact values:
    // 32-, 16- and 17-bit magnitudes (SPREAD_MAX = 92680 < 2^17).
    assert_eq!((CVM_BINS, POWER_BINS, SPREAD_BINS), (3328, 1280, 1408));
    const { assert!(SPREAD_MAX < 1 << 17) };
}

/// Magnitudes with many ties, tiny and huge ones.
fn values() -> impl Strategy<Value = u32> {
    prop_oneof![
        0u32..4,
        0u32..300,
        any::<u32>(),
        (u32::MAX - 1000)..=u32::MAX,
        1_000_000u32..2_000_000,
        prop::sample::select(vec![0u32, 255, 256, 257, 1 << 20, u32::MAX]),
    ]
}

fn rules() -> impl Strategy<Value = Rule> {
    (
        prop_oneof![Just(1_000_000u32), 0u32..=1_000_000],
        prop_oneof![Just(3000u32), 0u32..20_000, Just(u32::MAX)],
    )
        .prop_map(|(quantile_ppm, k_milli)| Rule::Spread {
            quantile_ppm,
            k_milli,
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn calibrator_follows_the_rule(
        triples in prop::collection::vec(
            (values(), 0u16..=POWER_MAX as u16, prop_oneof![0u32..300, 0u32..=SPREAD_MAX]),
            1..400,
        ),
        rule in rules(),
        split in 0usize..400,
    ) {
        let cvm: Vec<u32> = triples.iter().map(|t| t.0).collect();
        let power: Vec<u16> = triples.iter().map(|t| t.1).collect();
        let spr: Vec<u32> = triples.iter().map(|t| t.2).collect();
        let s = feed3(&cvm, &power, &spr).statistics(&rule).unwrap();
        prop_assert_eq!(spread(&s.cvm), spread(&channel_ref(&cvm, &rule)));
        let p32: Vec<u32> = power.iter().map(|&p| p as u32).collect();
        let mut pref = channel_ref(&p32, &rule);
        if pref.threshold > POWER_MAX {
            pref.threshold = POWER_OFF;
            pref.min_strength = u32::MAX;
        }
        prop_assert_eq!(spread(&s.power), spread(&pref));
        let mut sref = channel_ref(&spr, &rule);
        if sref.threshold > SPREAD_MAX {
            sref.threshold = SPREAD_OFF;
            sref.min_strength = u32::MAX;
        }
        prop_assert_eq!(spread(&s.spread), spread(&sref));
        // Taken in two parts and merged, or in another order: the same.
        let k = split.min(cvm.len());
        let mut a = feed3(&cvm[..k], &power[..k], &spr[..k]);
        a.merge(&feed3(&cvm[k..], &power[k..], &spr[k..]));
        prop_assert_eq!(a.statistics(&rule).unwrap(), s);
        let rev = |v: &[u32]| v.iter().rev().copied().collect::<Vec<u32>>();
        let rp: Vec<u16> = power.iter().rev().copied().collect();
        prop_assert_eq!(feed3(&rev(&cvm), &rp, &rev(&spr)).statistics(&rule).unwrap(), s);
    }

    #[test]
    fn one_position(v in values(), p in 0u16..=POWER_MAX as u16) {
        let s = feed(&[v], &[p]).statistics(&Rule::SPREAD).unwrap();
        let rep = bin_ref(v).2 as u32;
        prop_assert_eq!((s.cvm.max, s.cvm.quantile, s.cvm.median, s.cvm.mad), (v, v, rep, 0));
        prop_assert_eq!(s.cvm.threshold, v.saturating_add(1));
        prop_assert_eq!(s.power.threshold, if p as u32 == POWER_MAX { POWER_OFF } else { p as u32 + 1 });
    }
}

#[derive(Default)]
struct Discard;

impl LineSink for Discard {
    fn line(&mut self, _line: &[u8], _priority: Priority) {}
}

/// The beams of a `rows x cols` scan in raster order, `lost` marked missing.
fn beams(data: &[u16], cols: usize, n: usize, lost: &[usize]) -> Vec<(Position, Option<Vec<u16>>)> {
    data.chunks_exact(n)
        .enumerate()
        .map(|(i, f)| {
            let pos = Position {
                row: (i / cols) as u32,
                col: (i % cols) as u32,
            };
            (pos, (!lost.contains(&i)).then(|| f.to_vec()))
        })
        .collect()
}

#[test]
fn the_pipeline_hook_takes_the_armed_scans_positions() {
    let mut r = rng(32);
    let (rows, cols, j) = (5usize, 7usize, 4usize);
    let scorer = dmap::options::ScoringArgs::default().scorer(j, j).unwrap();
    let settings = Settings {
        cols: cols as u32,
        threshold: scorer.threshold_from_units(0.02),
        power_threshold: 3000,
        spread_threshold: cvm_core::spread::SPREAD_OFF,
        scores: false,
        max_defect_lines_per_row: 3,
        rows: rows as u32,
        outputs: cvm_core::settings::Outputs::DEFAULT,
        sources: [cvm_core::settings::Source::Default; cvm_core::settings::KEYS],
    };
    // Four scans: one before arming, two calibrated (the second with two
    // lost beams), one after.
    let scans: Vec<Vec<(Position, Option<Vec<u16>>)>> = (0..4)
        .map(|i| {
            let lost: &[usize] = if i == 2 { &[3, cols + 1] } else { &[] };
            beams(&random_scan(&mut r, rows, cols, j, j), cols, j * j, lost)
        })
        .collect();
    let words = cvm_core::stream::row_words_for(cols, scorer.config());
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let mut cal = Box::new(Calibrator::new());
    let mut p = Box::new(Pipeline::<64>::new(&scorer, settings, &mut a, &mut b).unwrap());
    p.attach_calibrator(&mut cal);
    let mut sink = Discard;
    let mut run = |p: &mut Pipeline<64>, frames: &[(Position, Option<Vec<u16>>)]| {
        p.begin(&mut sink);
        for (pos, f) in frames {
            match f {
                Some(f) => p.push(*pos, f, &mut sink),
                None => p.mark_missing(*pos, &mut sink),
            };
        }
        p.finish(0, &mut sink);
    };
    run(&mut p, &scans[0]);
    assert_eq!(p.calibrator().unwrap().progress(), Progress::Idle);
    assert_eq!(p.calibrator().unwrap().positions(), 0);
    p.calibrator_mut().unwrap().arm(2);
    assert_eq!(
        p.calibrator().unwrap().progress(),
        Progress::Armed { target: 2 }
    );
    run(&mut p, &scans[1]);
    assert_eq!(
        p.calibrator().unwrap().progress(),
        Progress::Running {
            taken: 1,
            target: 2
        }
    );
    run(&mut p, &scans[2]);
    assert_eq!(
        p.calibrator().unwrap().progress(),
        Progress::Done { taken: 2 }
    );
    run(&mut p, &scans[3]);
    let got = p.calibrator().unwrap().finish(&Rule::DEFAULT).unwrap();

    // The same positions fed directly: the engine's rows of scans 1 and 2
    // (positions without data left out), the spread measured (a threshold
    // above SPREAD_MAX, not SPREAD_OFF) though the settings have it off.
    let mut direct = Box::new(Calibrator::new());
    for frames in &scans[1..3] {
        let (rows_out, _) =
            run_engine_thresholds(&scorer, cols, [1, POWER_OFF, SPREAD_MAX + 1], frames);
        for (_, scores) in &rows_out {
            direct.add_row(scores);
        }
        direct.end_scan();
    }
    assert_eq!(direct.finish(&Rule::DEFAULT).unwrap(), got);
    assert_eq!(
        (got.scans, got.positions),
        (2, (2 * rows * cols - 2) as u32)
    );
    // A complete scan: the batch scorer `dmap calibrate` takes magnitudes
    // from gives the same calibration as the pipeline's hook.
    let mut hooked = Box::new(Calibrator::new());
    p.attach_calibrator(&mut hooked);
    p.calibrator_mut().unwrap().arm(1);
    run(&mut p, &scans[3]);
    let data: Vec<u16> = scans[3]
        .iter()
        .flat_map(|(_, f)| f.clone().unwrap())
        .collect();
    let mut batch = Box::new(Calibrator::new());
    let mut scores = dmap::fixed::score_scan(&scorer, rows, cols, &data);
    dmap::fixed::add_spread(&scorer, rows, cols, &data, &mut scores);
    batch.add_row(&scores);
    batch.end_scan();
    assert_eq!(
        p.calibrator().unwrap().finish(&Rule::DEFAULT),
        batch.finish(&Rule::DEFAULT)
    );
}

/// The documented bins (docs/experiments.md), 2^7 per octave above 255:
/// (top, middle) of `v`'s bin.
fn bin_top_mid(v: u32) -> (u64, u64) {
    let (_, hi, mid) = bin_ref(v);
    (hi, mid)
}

/// The tail rule's threshold on `values` from `scans` scans, in f64
/// (`cvm_reference::exp_tail`), for a rate of 1e-3 per part and the top
/// 1 % fitted (`Rule::DEFAULT`), and the fit's scale.
fn tail_threshold_f64(values: &[u32], scans: usize) -> (f64, f64) {
    let n = values.len();
    let mut sorted = values.to_vec();
    sorted.sort_unstable();
    let max = *sorted.last().unwrap() as u64;
    let rank = (99 * n).div_ceil(100).min(n.saturating_sub(10)).max(1);
    let start = bin_top_mid(sorted[rank - 1]).0.min(max);
    let reps: Vec<f64> = values
        .iter()
        .map(|&x| bin_top_mid(x).1.min(max) as f64)
        .collect();
    let fit = cvm_reference::exp_tail(&reps, start as f64);
    (
        fit.threshold(scans, 1e-3).ceil().max(max as f64 + 1.0),
        fit.scale,
    )
}

/// Live scans through the pipeline: a calibration with the spread channel
/// off measures the spread all the same and sets the same spread threshold
/// as one with the channel on; the tail rule's threshold recomputed in f64
/// from the magnitudes agrees; and the calibrated scans decide as with the
/// channel off (the spread is measured, not applied).
#[test]
fn a_calibration_with_the_spread_channel_off_still_sets_its_threshold() {
    let mut r = rng(77);
    let (rows, cols, j) = (12usize, 20usize, 5usize);
    let scorer = dmap::options::ScoringArgs::default().scorer(j, j).unwrap();
    let settings = |spread_threshold| Settings {
        cols: cols as u32,
        threshold: scorer.threshold_from_units(0.5),
        power_threshold: 3277,
        spread_threshold,
        scores: false,
        max_defect_lines_per_row: 0,
        rows: rows as u32,
        outputs: cvm_core::settings::Outputs::DEFAULT,
        sources: [cvm_core::settings::Source::Default; cvm_core::settings::KEYS],
    };
    let data: Vec<Vec<u16>> = (0..3)
        .map(|_| random_scan(&mut r, rows, cols, j, j))
        .collect();
    let words = cvm_core::stream::row_words_for(cols, scorer.config());
    let calibrate = |sthr: u32| {
        let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
        let mut cal = Box::new(Calibrator::new());
        let mut p = Box::new(Pipeline::<64>::new(&scorer, settings(sthr), &mut a, &mut b).unwrap());
        p.attach_calibrator(&mut cal);
        p.calibrator_mut().unwrap().arm(data.len() as u16);
        let mut defects = Vec::new();
        for scan in &data {
            p.begin(&mut Discard);
            for (pos, f) in beams(scan, cols, j * j, &[]) {
                p.push(pos, &f.unwrap(), &mut Discard);
            }
            defects.push(p.finish(0, &mut Discard).defects);
        }
        assert_eq!(
            p.calibrator().unwrap().progress(),
            Progress::Done { taken: 3 }
        );
        // After the calibration the setting is back: with the channel off,
        // nothing is measured.
        let back = p.settings().spread_threshold;
        (
            p.calibrator().unwrap().finish(&Rule::DEFAULT).unwrap(),
            defects,
            back,
        )
    };
    let (off, off_defects, back) = calibrate(SPREAD_OFF);
    assert_eq!(back, SPREAD_OFF);
    let (on, _, _) = calibrate(6554);
    assert_eq!(off, on, "the channel off or on, the same calibration");
    assert!(off.spread_median > 0 || off.spread_mad > 0, "{off:?}");
    assert!(off.spread_threshold <= SPREAD_MAX, "{off:?}");
    // Not calibrating, the same scans with the channel off: the same defects.
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let mut p =
        Box::new(Pipeline::<64>::new(&scorer, settings(SPREAD_OFF), &mut a, &mut b).unwrap());
    let plain: Vec<u32> = data
        .iter()
        .map(|scan| {
            p.begin(&mut Discard);
            for (pos, f) in beams(scan, cols, j * j, &[]) {
                p.push(pos, &f.unwrap(), &mut Discard);
            }
            p.finish(0, &mut Discard).defects
        })
        .collect();
    assert_eq!(plain, off_defects);
    // The tail rule in f64 on the spread magnitudes (the batch scorer's).
    let mut smag = Vec::new();
    for scan in &data {
        let mut s = dmap::fixed::score_scan(&scorer, rows, cols, scan);
        dmap::fixed::add_spread(&scorer, rows, cols, scan, &mut s);
        smag.extend(s.iter().map(|x| x.smag));
    }
    let (want, scale) = tail_threshold_f64(&smag, data.len());
    let want = if want > SPREAD_MAX as f64 {
        SPREAD_OFF as f64
    } else {
        want
    };
    let got = off.spread_threshold as f64;
    assert!((got - want).abs() <= 1.0 + 1e-6 * scale, "{got} vs {want}");
}
