//! `dmap calibrate --rule tail`: thresholds from a target rate of false
//! positions per part, recomputed here from the references' integer
//! magnitudes with the f64 formulas (`cvm_reference::exp_tail`); the
//! estimate and the smallest detected rise it prints; the options of the
//! two rules kept apart; and calibration files of version 3 (before the
//! rule had a name) still applied.

use std::path::{Path, PathBuf};

use dmap::npy;

use crate::common;
use common::{dmap, ok, one_line_error, s, spot_scan};

fn tmp(name: &str) -> PathBuf {
    common::tmp_in("caltail", name)
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The documented bins (docs/experiments.md): itself below 256, else bins
/// `w = 2^(floor(log2 v) - 7)` wide from multiples of `w`: (top, middle).
fn bin(v: u64) -> (u64, u64) {
    if v < 256 {
        return (v, v);
    }
    let w = 1u64 << (v.ilog2() - 7);
    (v / w * w + w - 1, v / w * w + w / 2)
}

/// The integer CVM magnitudes of `refs` (`dmap score --distance cvm-fixed`
/// in units, times `2^q`).
fn magnitudes(refs: &[&Path], q: i32) -> Vec<u64> {
    let mut m = Vec::new();
    for (i, r) in refs.iter().enumerate() {
        let g = tmp(&format!("g{i}.npy"));
        ok(&dmap(&[
            "score",
            s(r),
            "--distance",
            "cvm-fixed",
            "-o",
            s(&g),
        ]));
        let img = npy::read_gradient(&g).unwrap();
        m.extend(
            img.data
                .chunks(3)
                .map(|p| (p[2] * 2f64.powi(q)).round() as u64),
        );
    }
    m
}

/// The spread magnitudes (`Q16`) of `refs` in the firmware's arithmetic
/// (`dmap::fixed`, the batch the engine is checked against).
fn spread_magnitudes(refs: &[&Path]) -> Vec<u64> {
    let mut m = Vec::new();
    for r in refs {
        let scan = dmap::npy::ScanFile::open(r).unwrap();
        let g = &scan.geometry;
        let (j1, j2) = (g.j1(), g.j2());
        let scorer = dmap::options::ScoringArgs::default()
            .scorer(j1, j2)
            .unwrap();
        let n = j1 * j2;
        let mut data = vec![0u16; scan.maps() * n];
        let mut scratch = Vec::new();
        scan.maps_u16(0, &mut data, &mut scratch).unwrap();
        let mut scores = dmap::fixed::score_scan(&scorer, scan.rows, scan.cols, &data);
        dmap::fixed::add_spread(&scorer, scan.rows, scan.cols, &data, &mut scores);
        m.extend(scores.iter().map(|x| u64::from(x.smag)));
    }
    m
}

/// The tail rule's threshold in f64 on integer magnitudes `m` of `scans`
/// scans, the top `f` fitted, one false position in 1000 parts; and the
/// fit's scale.
fn tail_threshold(m: &[u64], scans: usize, f: f64) -> (f64, f64) {
    let n = m.len();
    let max = *m.iter().max().unwrap();
    let mut sorted = m.to_vec();
    sorted.sort_unstable();
    let rank = ((1.0 - f) * n as f64).ceil() as usize;
    let rank = rank.min(n - 10).max(1);
    let start = bin(sorted[rank - 1]).0.min(max);
    let reps: Vec<f64> = m.iter().map(|&x| bin(x).1.min(max) as f64).collect();
    let fit = cvm_reference::exp_tail(&reps, start as f64);
    (
        fit.threshold(scans, 1e-3).ceil().max(max as f64 + 1.0),
        fit.scale,
    )
}

#[test]
fn tail_rule_meets_its_target_by_the_f64_formulas() {
    let (r1, r2) = (tmp("r1.npy"), tmp("r2.npy"));
    spot_scan(&r1, 14, 16, 5, 1);
    spot_scan(&r2, 13, 16, 5, 2);
    let cal = tmp("tail.json");
    let out = dmap(&[
        "calibrate",
        s(&r1),
        s(&r2),
        "--rule",
        "tail",
        "--tail-fraction",
        "0.05",
        "-o",
        s(&cal),
    ]);
    ok(&out);
    let v = json(&cal);
    assert_eq!(v["version"], 5);
    assert_eq!(v["rule"]["name"], "tail");
    assert_eq!(
        (
            v["rule"]["rate_ppm"].as_u64(),
            v["rule"]["tail_ppm"].as_u64()
        ),
        (Some(1000), Some(50_000))
    );
    let ch = &v["channels"]["cvm"];
    let q = ch["q"].as_i64().unwrap() as i32;
    let m = magnitudes(&[&r1, &r2], q);
    let n = m.len();
    assert_eq!(n, (14 + 13) * 16);
    let max = *m.iter().max().unwrap();
    // The tail's start: the top of the bin of rank ceil(0.95 n) (at most
    // n - 10), at most the maximum; its values: the representatives above it, at most the
    // maximum.
    let mut sorted = m.clone();
    sorted.sort_unstable();
    let rank = (95 * n).div_ceil(100).min(n - 10);
    let start = bin(sorted[rank - 1]).0.min(max);
    let reps: Vec<f64> = m.iter().map(|&x| bin(x).1.min(max) as f64).collect();
    let fit = cvm_reference::exp_tail(&reps, start as f64);
    let ints = &ch["tail"]["integers"];
    assert_eq!(ints["start"].as_u64(), Some(start));
    assert_eq!(ints["positions"].as_u64(), Some(fit.count as u64));
    assert!(fit.count > 0);
    // Two scans, one false position in 1000 parts.
    let want = fit.threshold(2, 1e-3).ceil().max(max as f64 + 1.0);
    let thr = ch["thr"].as_f64().unwrap();
    assert!(
        (thr - want).abs() <= 1.0 + 1e-6 * fit.scale,
        "{thr} vs {want}"
    );
    let rate = fit.rate_at(2, thr);
    let got = ch["false_positions_per_part"].as_f64().unwrap();
    assert!(
        got >= rate * (1.0 - 1e-6) && got <= rate * (1.0 + 1e-6) + 1e-9,
        "{got} {rate}"
    );
    assert!(got <= 1e-3 * (1.0 + 1e-5), "{got}");
    let unit = 2f64.powi(-q);
    let median = ch["integers"]["median"].as_f64().unwrap();
    assert_eq!(ch["min_strength"].as_f64(), Some((thr - median) * unit));
    // Printed per channel.
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("CVM: estimated false positions per part"),
        "{err}"
    );
    assert!(err.contains("power: "), "{err}");
    assert!(err.contains("spread: "), "{err}");
    // The spread channel: the same rule on the Q16 spread magnitudes.
    let sm = spread_magnitudes(&[&r1, &r2]);
    let sch = &v["channels"]["spread"];
    assert_eq!(sch["q"], 16);
    let (want, scale) = tail_threshold(&sm, 2, 0.05);
    let sthr = sch["thr"].as_f64().unwrap();
    if want > 92680.0 {
        assert_eq!(sthr, u32::MAX as f64);
    } else {
        assert!(
            (sthr - want).abs() <= 1.0 + 1e-6 * scale,
            "{sthr} vs {want}"
        );
        let median = sch["integers"]["median"].as_f64().unwrap();
        assert_eq!(
            sch["min_strength"].as_f64(),
            Some((sthr - median) / 65536.0)
        );
        assert!(
            err.contains("spread: estimated false positions per part"),
            "{err}"
        );
    }
    // No reference position reaches it, and a stricter target never
    // lowers it.
    assert!(thr > max as f64);
    let strict = tmp("strict.json");
    ok(&dmap(&[
        "calibrate",
        s(&r1),
        s(&r2),
        "--rule",
        "tail",
        "--tail-fraction",
        "0.05",
        "--rate",
        "0.000001",
        "-o",
        s(&strict),
    ]));
    let t2 = json(&strict)["channels"]["cvm"]["thr"].as_f64().unwrap();
    let want2 = fit.threshold(2, 1e-6).ceil().max(max as f64 + 1.0);
    assert!(
        t2 >= thr && (t2 - want2).abs() <= 1.0 + 1e-6 * fit.scale,
        "{t2} {want2}"
    );
}

#[test]
fn spread_rule_reports_the_fit_too_and_the_options_stay_apart() {
    let r = tmp("o.npy");
    spot_scan(&r, 10, 12, 5, 3);
    let cal = tmp("spread.json");
    ok(&dmap(&[
        "calibrate",
        s(&r),
        "--rule",
        "spread",
        "--k",
        "2",
        "-o",
        s(&cal),
    ]));
    let v = json(&cal);
    assert_eq!(v["rule"]["name"], "spread");
    assert_eq!(v["rule"]["k_milli"], 2000);
    for c in ["cvm", "power", "spread"] {
        assert!(
            v["channels"][c]["tail"]["integers"]["positions"].is_u64(),
            "{c}"
        );
        assert!(
            v["channels"][c].get("false_positions_per_part").is_some(),
            "{c}"
        );
    }
    let x = tmp("x.json");
    for (args, needle) in [
        (
            vec!["--rule", "tail", "--k", "2"],
            "--k-mad is not a parameter of the tail rule",
        ),
        (
            vec!["--rule", "tail", "--quantile", "0.9"],
            "--quantile is not a parameter",
        ),
        (
            vec!["--rule", "spread", "--rate", "0.01"],
            "--rate is not a parameter of the spread rule",
        ),
        (
            vec!["--rule", "tail", "--rate", "0"],
            "--rate must be in (0, 1]",
        ),
        (
            vec!["--rule", "tail", "--tail-fraction", "1.5"],
            "--tail-fraction must be in (0, 1]",
        ),
        (
            vec!["--rule", "tail", "--scores"],
            "--from-scores applies the spread rule only",
        ),
    ] {
        one_line_error(
            &dmap(&[&["calibrate", s(&r)][..], &args, &["-o", s(&x)]].concat()),
            needle,
        );
    }
    assert!(!x.exists());
}

/// A version 3 file (the layout before the rule's name and the tail fit)
/// is applied as before; a version past this dmap's is refused.
#[test]
fn version_3_files_are_still_applied() {
    let r = tmp("v.npy");
    spot_scan(&r, 8, 9, 5, 4);
    let cal = tmp("v4.json");
    ok(&dmap(&[
        "calibrate",
        s(&r),
        "--rule",
        "tail",
        "-o",
        s(&cal),
    ]));
    let mut v = json(&cal);
    let (thr, pthr) = (
        v["channels"]["cvm"]["thr"].clone(),
        v["channels"]["power"]["thr"].clone(),
    );
    v["version"] = serde_json::json!(3);
    v["rule"].as_object_mut().unwrap().remove("name");
    for c in ["cvm", "power"] {
        let o = v["channels"][c].as_object_mut().unwrap();
        for k in [
            "tail",
            "false_positions_per_part",
            "rate_ppb",
            "min_strength",
            "threshold_over_max",
        ] {
            assert!(o.remove(k).is_some(), "{c} {k}");
        }
    }
    let v3 = tmp("v3.json");
    std::fs::write(&v3, v.to_string()).unwrap();
    let out = dmap(&["stream", s(&r), "--calibration", s(&v3)]);
    ok(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    let header = text.lines().next().unwrap();
    assert!(header.contains(&format!(",thr={thr},")), "{header}");
    assert!(header.contains(&format!(",pthr={pthr},")), "{header}");
    v["version"] = serde_json::json!(6);
    let v6 = tmp("v6.json");
    std::fs::write(&v6, v.to_string()).unwrap();
    one_line_error(
        &dmap(&["stream", s(&r), "--calibration", s(&v6)]),
        "this dmap reads 2 to 5",
    );
}
