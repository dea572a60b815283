//! `dmap calibrate` and `--calibration` on stream, emulate and twin, run
//! as a user would: real files, the real binary.

use std::path::{Path, PathBuf};
use std::process::Output;

use dmap::npy;

mod common;
use common::{dmap, ok, s};

fn tmp(name: &str) -> PathBuf {
    common::tmp_in("cal", name)
}

fn one_line_error(out: &Output, needle: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "expected failure: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
    assert!(err.contains(needle), "{err:?} lacks {needle:?}");
    assert!(!err.contains("panicked"));
}

/// A small synthetic reference: a spot drifting across a `j x j` detector
/// with pseudo-random noise (a 64-bit LCG, so the test needs no RNG crate).
fn reference(path: &Path, rows: usize, cols: usize, j: usize, seed: u64) {
    part(path, rows, cols, j, seed, false)
}

/// [`reference`], with a defect (the spot thrown two cells aside) at the
/// centre position if `defect`.
fn part(path: &Path, rows: usize, cols: usize, j: usize, seed: u64, defect: bool) {
    let mut x = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
    let mut data = Vec::with_capacity(rows * cols * j * j);
    for r in 0..rows {
        for c in 0..cols {
            let (mut cy, cx) = (
                1.0 + r as f64 * (j as f64 - 3.0) / rows as f64,
                1.0 + c as f64 * (j as f64 - 3.0) / cols as f64,
            );
            if defect && (r, c) == (rows / 2, cols / 2) {
                cy += 2.0;
            }
            for a in 0..j {
                for b in 0..j {
                    x = x
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    let noise = (x >> 54) as f64; // 0..1023
                    let d2 = (a as f64 - cy).powi(2) + (b as f64 - cx).powi(2);
                    data.push((3000.0 * (-d2).exp() + noise / 16.0).round() as u16);
                }
            }
        }
    }
    let g = cvm_reference::Geometry::new(j, j).unwrap();
    npy::write_scan_u16(path, rows, cols, g, &data).unwrap();
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn threshold_follows_the_documented_rule() {
    let (r1, r2) = (tmp("rule-r1.npy"), tmp("rule-r2.npy"));
    reference(&r1, 7, 9, 5, 1);
    reference(&r2, 6, 9, 5, 2);
    let cal = tmp("rule.json");
    ok(&dmap(&[
        "calibrate",
        s(&r1),
        s(&r2),
        "--k",
        "2.5",
        "-o",
        s(&cal),
    ]));
    let v = json(&cal);
    // Recomputed from the fixed-point scores `dmap score` writes (distance
    // units, exact multiples of 2^-q), with the rule of docs/experiments.md.
    let mut m = Vec::new();
    for (i, r) in [&r1, &r2].into_iter().enumerate() {
        let g = tmp(&format!("rule-g{i}.npy"));
        ok(&dmap(&[
            "score",
            s(r),
            "--distance",
            "cvm-fixed",
            "-o",
            s(&g),
        ]));
        let img = npy::read_gradient(&g).unwrap();
        m.extend(img.data.chunks(3).map(|p| p[2]));
    }
    assert_eq!(m.len(), 7 * 9 + 6 * 9);
    let q = v["channels"]["cvm"]["q"].as_i64().unwrap() as i32;
    let unit = 2f64.powi(-q);
    m.sort_by(f64::total_cmp);
    let med = |v: &[f64]| {
        let n = v.len();
        if n % 2 == 1 {
            v[n / 2]
        } else {
            (v[n / 2 - 1] + v[n / 2]) / 2.0
        }
    };
    let median = med(&m);
    let mut dev: Vec<f64> = m.iter().map(|x| (x - median).abs()).collect();
    dev.sort_by(f64::total_cmp);
    let mad = med(&dev);
    let max = *m.last().unwrap();
    // In integer scores (exact in f64 at these sizes), then in units.
    let want_thr = max / unit + (2.5 * 1.4826 * (mad / unit)).ceil() + 1.0;
    let ch = &v["channels"]["cvm"];
    assert_eq!(ch["thr"].as_f64().unwrap(), want_thr);
    // JSON's decimal reads back within an ulp; the integer is the calibration.
    let t = ch["threshold"].as_f64().unwrap();
    assert!((t - want_thr * unit).abs() <= 1e-15 * t, "{t}");
    let close = |k: &str, want: f64| {
        let got = ch[k].as_f64().unwrap();
        assert!(
            (got - want).abs() <= 1e-15 * want.abs(),
            "{k}: {got} vs {want}"
        );
    };
    close("max", max);
    close("mad", mad);
    close("median", median);
    assert_eq!(v["references"].as_array().unwrap().len(), 2);
    assert_eq!(
        v["config"],
        serde_json::json!({"j1": 5, "j2": 5, "kernels": "paper", "b": 0,
            "weights": "uniform", "normalise": true, "full_scale": 65535})
    );
    // No reference position reaches it: nothing flagged on the references.
    let out = dmap(&["stream", s(&r1), "--calibration", s(&cal)]);
    ok(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(!text.lines().any(|l| l.starts_with('D')), "{text}");
}

#[test]
fn calibration_streams_the_same_bytes_as_its_threshold() {
    let (r, scan) = (tmp("same-r.npy"), tmp("same-scan.npy"));
    reference(&r, 6, 8, 4, 3);
    part(&scan, 9, 8, 4, 4, true);
    for (name, extra) in [
        ("norm", vec![]),
        ("raw", vec!["--raw"]),
        ("square", vec!["--kernels", "square"]),
    ] {
        let cal = tmp(&format!("same-{name}.json"));
        let mut args = vec!["calibrate", s(&r), "--k", "0", "-o", s(&cal)];
        args.extend(&extra);
        ok(&dmap(&args));
        // The threshold as the scorer's integer in distance units, exactly.
        let ch = &json(&cal)["channels"]["cvm"];
        let t = ch["thr"].as_f64().unwrap() * 2f64.powi(-(ch["q"].as_i64().unwrap() as i32));
        let t = format!("{t:?}");
        let run = |how: &[&str]| {
            let mut a = vec!["stream", s(&scan), "--scores"];
            a.extend(&extra);
            a.extend(how);
            let out = dmap(&a);
            ok(&out);
            out.stdout
        };
        let by_file = run(&["--calibration", s(&cal)]);
        let by_value = run(&["--threshold", &t]);
        assert_eq!(by_file, by_value, "{name}");
        // The scan differs from the reference: some positions reach it.
        assert!(by_file.windows(2).any(|w| w == b"\nD"), "{name}");
    }
}

#[test]
fn calibration_refuses_other_configurations_and_bad_input() {
    let (r, r3) = (tmp("bad-r.npy"), tmp("bad-r3.npy"));
    reference(&r, 5, 6, 5, 5);
    reference(&r3, 5, 6, 3, 6);
    let cal = tmp("bad.json");
    ok(&dmap(&["calibrate", s(&r), "-o", s(&cal)]));
    for (extra, needle) in [
        (vec!["--raw"], "normalise: calibrated true, this run false"),
        (vec!["--kernels", "square"], "kernels"),
        (vec!["--bmax", "2"], "b: calibrated 0, this run 2"),
        (vec!["--weights", "unit"], "weights"),
        (
            vec!["--full-scale", "4095"],
            "full_scale: calibrated 65535, this run 4095",
        ),
    ] {
        let mut a = vec!["stream", s(&r), "--calibration", s(&cal)];
        a.extend(&extra);
        one_line_error(&dmap(&a), needle);
    }
    // Another detector geometry.
    one_line_error(
        &dmap(&["stream", s(&r3), "--calibration", s(&cal)]),
        "j1: calibrated 5, this run 3",
    );
    // Both a threshold and a calibration.
    let out = dmap(&[
        "stream",
        s(&r),
        "--calibration",
        s(&cal),
        "--threshold",
        "1",
    ]);
    assert!(!out.status.success());
    // A file that is not a calibration, and a tampered threshold.
    let junk = tmp("bad-junk.json");
    std::fs::write(&junk, "{\"a\": 1}").unwrap();
    one_line_error(
        &dmap(&["stream", s(&r), "--calibration", s(&junk)]),
        "not a calibration file",
    );
    let mut v = json(&cal);
    let t = v["channels"]["cvm"]["threshold"].as_f64().unwrap();
    v["channels"]["cvm"]["threshold"] = serde_json::json!(t * 1.01);
    let tampered = tmp("bad-tampered.json");
    std::fs::write(&tampered, v.to_string()).unwrap();
    one_line_error(
        &dmap(&["stream", s(&r), "--calibration", s(&tampered)]),
        "is not the integer",
    );
    one_line_error(
        &dmap(&["stream", s(&r), "--calibration", s(&tmp("none.json"))]),
        "none.json",
    );
    // calibrate's own input.
    one_line_error(
        &dmap(&["calibrate", s(&r), s(&r3), "-o", s(&tmp("x.json"))]),
        "one detector geometry at a time",
    );
    one_line_error(
        &dmap(&["calibrate", s(&junk), "-o", s(&tmp("x.json"))]),
        "bad-junk.json",
    );
    one_line_error(
        &dmap(&[
            "calibrate",
            s(&r),
            "--quantile",
            "0",
            "-o",
            s(&tmp("x.json")),
        ]),
        "--quantile",
    );
    one_line_error(
        &dmap(&["calibrate", s(&r), "--k=-1", "-o", s(&tmp("x.json"))]),
        "--k",
    );
    one_line_error(&dmap(&["calibrate", s(&r), "-o", s(&r)]), "refusing");
    assert!(!tmp("x.json").exists());
}

#[test]
fn calibration_reaches_the_emulated_board_and_the_h743_build() {
    // The emulated board's scan header and the H743 build configuration
    // carry the threshold in distance units, which each converts to the
    // scorer's integer; with a calibration they carry `thr * 2^-q` exactly.
    let (r, scan) = (tmp("board-r.npy"), tmp("board-scan.npy"));
    reference(&r, 5, 6, 5, 7);
    part(&scan, 5, 6, 5, 8, true);
    let cal = tmp("board.json");
    ok(&dmap(&["calibrate", s(&r), "-o", s(&cal)]));
    let ch = &json(&cal)["channels"]["cvm"];
    let exact = ch["thr"].as_f64().unwrap() * 2f64.powi(-(ch["q"].as_i64().unwrap() as i32));
    let args = dmap::emulate::EmulateArgs {
        scan: scan.clone(),
        scoring: Default::default(),
        output: dmap::stream::OutputArgs {
            calibration: Some(cal.clone()),
            ..Default::default()
        },
        elf: None,
        icount: false,
    };
    let (file, _) = dmap::emulate::scan_file_and_warnings(&args).unwrap();
    let header = cvm_fw_app::emufile::ScanHeader::parse(&file).unwrap();
    assert_eq!(header.threshold_units, exact);
    let scorer = dmap::options::ScoringArgs::default().scorer(5, 5).unwrap();
    assert_eq!(
        scorer.threshold_from_units(header.threshold_units) as f64,
        ch["thr"].as_f64().unwrap()
    );
    let config = dmap::twin::h743_config(&header).unwrap();
    assert!(
        config.contains(&format!("threshold={exact:?} ")),
        "{config}"
    );
    // Refused there too for another configuration.
    let raw = dmap::emulate::EmulateArgs {
        scoring: dmap::options::ScoringArgs {
            raw: true,
            ..Default::default()
        },
        ..args
    };
    let e = dmap::emulate::scan_file_and_warnings(&raw).unwrap_err();
    assert!(format!("{e:#}").contains("normalise"), "{e:#}");
}

#[test]
fn calibration_on_precomputed_scores_is_for_eval_only() {
    // Magnitudes 1..=9 and 100 (a 2x5 image): median 5.5, MAD 2.5, k = 2:
    // 100 + 2 * 1.4826 * 2.5.
    let g = tmp("pre-g.npy");
    let mag = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 100.0];
    let data: Vec<f64> = mag.iter().flat_map(|&m| [m, m, m]).collect();
    npy::write_gradient(&g, 2, 5, &data).unwrap();
    let cal = tmp("pre.json");
    ok(&dmap(&[
        "calibrate",
        "--scores",
        s(&g),
        "--k",
        "2",
        "-o",
        s(&cal),
    ]));
    let t = json(&cal)["channels"]["scores"]["threshold"]
        .as_f64()
        .unwrap();
    assert!((t - (100.0 + 2.0 * 1.4826 * 2.5)).abs() < 1e-12, "{t}");
    let (r, m) = (tmp("pre-r.npy"), tmp("pre-m.npy"));
    reference(&r, 2, 5, 3, 9);
    one_line_error(
        &dmap(&["stream", s(&r), "--calibration", s(&cal)]),
        "precomputed scores",
    );
    npy::write_mask(
        &m,
        &npy::Mask {
            rows: 2,
            cols: 5,
            data: vec![false; 10],
        },
    )
    .unwrap();
    let out = dmap(&[
        "eval",
        s(&g),
        "--truth",
        s(&m),
        "--calibration",
        s(&cal),
        "--json",
    ]);
    ok(&out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["threshold"].as_f64().unwrap(), t);
    assert_eq!(v["objects"]["false_objects"], 0);
}
