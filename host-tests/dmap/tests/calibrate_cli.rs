//! `dmap calibrate` and `--calibration` on stream, emulate and twin, run
//! as a user would: real files, the real binary.

use std::path::{Path, PathBuf};

use dmap::npy;

use crate::common;
use common::{dmap, ok, one_line_error, s};

fn tmp(name: &str) -> PathBuf {
    common::tmp_in("cal", name)
}

/// A small synthetic reference: a spot drifting across a `j x j` detector
/// with pseudo-random noise (a 64-bit LCG, so the test needs no RNG crate).
/// Returns its samples.
fn reference(path: &Path, rows: usize, cols: usize, j: usize, seed: u64) -> Vec<u16> {
    part(path, rows, cols, j, seed, false)
}

/// [`reference`], with a defect (the spot thrown two cells aside) at the
/// centre position if `defect`.
fn part(path: &Path, rows: usize, cols: usize, j: usize, seed: u64, defect: bool) -> Vec<u16> {
    part_dimmed(path, rows, cols, j, seed, defect, 1.0)
}

/// [`part`], with the spot of position `(1, 1)` at `dim` times its power (a
/// defect only the power channel sees).
fn part_dimmed(
    path: &Path,
    rows: usize,
    cols: usize,
    j: usize,
    seed: u64,
    defect: bool,
    dim: f64,
) -> Vec<u16> {
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
                    let a = if (r, c) == (1, 1) { dim } else { 1.0 };
                    data.push((a * 3000.0 * (-d2).exp() + noise / 16.0).round() as u16);
                }
            }
        }
    }
    let g = cvm_reference::Geometry::new(j, j).unwrap();
    npy::write_scan_u16(path, rows, cols, g, &data).unwrap();
    data
}

/// Power magnitudes (`Q15`) of a scan's positions from their definition
/// (docs/method.md §6), in f64 and independent of the core: per direction
/// the contrast `|P+ - P-| / (P+ + P-)` of the neighbours' sample sums (a
/// missing neighbour is the position itself), floored to `Q15`, then
/// `floor(sqrt(c0² + c1²))`. Exact in f64 at these sizes: sums are far
/// below 2^53, and a quotient or root is never within an ulp of an
/// integer it is not.
fn power_magnitudes(data: &[u16], rows: usize, cols: usize, n: usize) -> Vec<f64> {
    let p: Vec<f64> = data
        .chunks(n)
        .map(|m| m.iter().map(|&x| f64::from(x)).sum())
        .collect();
    let at = |r: usize, c: usize| p[r * cols + c];
    let contrast = |a: f64, b: f64| {
        if a + b == 0.0 {
            0.0
        } else {
            ((a - b).abs() * 32768.0 / (a + b)).floor()
        }
    };
    let mut out = Vec::new();
    for r in 0..rows {
        for c in 0..cols {
            let c0 = contrast(at(r, c.saturating_sub(1)), at(r, (c + 1).min(cols - 1)));
            let c1 = contrast(at(r.saturating_sub(1), c), at((r + 1).min(rows - 1), c));
            out.push((c0 * c0 + c1 * c1).sqrt().floor());
        }
    }
    out
}

/// The power magnitudes of `dmap stream --scores`'s S lines, raster order.
fn streamed_power(scan: &Path) -> Vec<f64> {
    let out = dmap(&["stream", s(scan), "--scores"]);
    ok(&out);
    let mut v = Vec::new();
    for line in out.stdout.split_inclusive(|&b| b == b'\n') {
        if let Ok(cvm_core::protocol::Line::Scores { chars, .. }) = cvm_core::protocol::parse(line)
        {
            for c in chars.chunks(cvm_core::protocol::SCORE_CHARS) {
                v.push(f64::from(cvm_core::protocol::decode_score(c).unwrap().pmag));
            }
        }
    }
    v
}

/// The spread magnitudes (`Q16`) of a `rows x cols` scan of `j x j` maps,
/// in the firmware's arithmetic.
fn spread_magnitudes(data: &[u16], rows: usize, cols: usize, j: usize) -> Vec<f64> {
    let scorer = dmap::options::ScoringArgs::default().scorer(j, j).unwrap();
    let mut scores = dmap::fixed::score_scan(&scorer, rows, cols, data);
    dmap::fixed::add_spread(&scorer, rows, cols, data, &mut scores);
    scores.iter().map(|x| f64::from(x.smag)).collect()
}

/// The documented rule (docs/experiments.md, "Calibration") on integer
/// magnitudes `m`, with p = 1 and `k = k_milli / 1000`, from its text:
/// each magnitude taken as its bin's representative (itself below 2^8;
/// else bins of width `w = 2^(floor(log2 v) - 7)` starting at multiples
/// of `w`, represented by `lo + w / 2`), lower medians by rank
/// `ceil(n / 2)`, the margin `ceil(k * 1.4826 * MAD)` as an exact
/// rational: (max, median, MAD, thr).
fn rule(m: &[f64], k_milli: u128) -> (f64, f64, f64, f64) {
    let rep = |v: u64| {
        if v < 256 {
            return v;
        }
        let w = 1u64 << (v.ilog2() - 7);
        v / w * w + w / 2
    };
    let mut r: Vec<u64> = m.iter().map(|&x| rep(x as u64)).collect();
    r.sort_unstable();
    let mid = r.len().div_ceil(2) - 1;
    let median = r[mid];
    let mut dev: Vec<u64> = r.iter().map(|&x| x.abs_diff(median)).collect();
    dev.sort_unstable();
    let mad = dev[mid];
    let max = m.iter().copied().fold(0.0, f64::max);
    let margin = (k_milli * 14826 * mad as u128).div_ceil(10_000_000);
    (max, median as f64, mad as f64, max + margin as f64 + 1.0)
}

/// The header line of `dmap stream` output.
fn header(out: &[u8]) -> String {
    String::from_utf8_lossy(out)
        .lines()
        .next()
        .unwrap()
        .to_string()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn threshold_follows_the_documented_rule() {
    let (r1, r2) = (tmp("rule-r1.npy"), tmp("rule-r2.npy"));
    let d1 = reference(&r1, 7, 9, 5, 1);
    let d2 = reference(&r2, 6, 9, 5, 2);
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
    // In integer scores (exact in f64 at these sizes), then in units.
    let ints: Vec<f64> = m.iter().map(|x| x / unit).collect();
    let (max, median, mad, want_thr) = rule(&ints, 2500);
    for (k, want) in [("max", max), ("median", median), ("mad", mad)] {
        assert_eq!(
            v["channels"]["cvm"]["integers"][k].as_f64(),
            Some(want),
            "{k}"
        );
    }
    let (max, median, mad) = (max * unit, median * unit, mad * unit);
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
    // The power channel: the same rule on the Q15 power magnitudes, here
    // from their definition on the samples; the firmware's S lines carry
    // the same values.
    let mut pm = power_magnitudes(&d1, 7, 9, 25);
    assert_eq!(pm, streamed_power(&r1));
    let pm2 = power_magnitudes(&d2, 6, 9, 25);
    assert_eq!(pm2, streamed_power(&r2));
    pm.extend(pm2);
    let (pmax, pmedian, pmad, want_pthr) = rule(&pm, 2500);
    // A real spread and a threshold a magnitude can reach.
    assert!(
        pmad >= 1.0 && want_pthr > pmax && want_pthr < 46340.0,
        "{pmad} {want_pthr}"
    );
    let pch = &v["channels"]["power"];
    assert_eq!(pch["thr"].as_f64().unwrap(), want_pthr);
    assert_eq!(pch["q"], 15);
    assert_eq!(pch["positions"], 7 * 9 + 6 * 9);
    assert_eq!(pch["threshold"].as_f64().unwrap(), want_pthr / 32768.0);
    for (k, want) in [("max", pmax), ("median", pmedian), ("mad", pmad)] {
        assert_eq!(pch[k].as_f64().unwrap(), want / 32768.0, "power {k}");
    }
    // Leave one out, per reference: the others' threshold and how many of
    // its positions reach it.
    let (n1, n2) = (7 * 9, 6 * 9);
    for (i, (own, others)) in [(&pm[..n1], &pm[n1..]), (&pm[n1..], &pm[..n1])]
        .into_iter()
        .enumerate()
    {
        assert_eq!(own.len() + others.len(), n1 + n2);
        let t = rule(others, 2500).3;
        let r = &v["references"][i]["power"];
        assert_eq!(r["others_threshold"].as_f64().unwrap(), t / 32768.0);
        assert_eq!(
            r["at_or_above_others_threshold"],
            own.iter().filter(|&&x| x >= t).count()
        );
    }
    // The spread channel: the same rule on the Q16 spread magnitudes the
    // firmware's arithmetic gives (dmap::fixed, checked against the
    // streaming engine in core-tests/spread.rs).
    let mut sm = spread_magnitudes(&d1, 7, 9, 5);
    sm.extend(spread_magnitudes(&d2, 6, 9, 5));
    let (smax, smedian, smad, want_sthr) = rule(&sm, 2500);
    let want_sthr = if want_sthr > 92680.0 {
        u32::MAX as f64
    } else {
        want_sthr
    };
    let sch = &v["channels"]["spread"];
    assert_eq!(sch["q"], 16);
    assert_eq!(sch["thr"].as_f64().unwrap(), want_sthr);
    assert_eq!(sch["threshold"].as_f64().unwrap(), want_sthr / 65536.0);
    for (k, want) in [("max", smax), ("median", smedian), ("mad", smad)] {
        assert_eq!(sch["integers"][k].as_f64().unwrap(), want, "spread {k}");
    }
    assert!(smax > 0.0, "the references have a spread");
    assert_eq!(v["version"], 5);
    assert_eq!(v["rule"]["name"], "spread");
    assert_eq!(v["scans"], 2);
    assert_eq!(v["references"].as_array().unwrap().len(), 2);
    assert_eq!(
        v["config"],
        serde_json::json!({"j1": 5, "j2": 5, "kernels": "paper", "b": 0,
            "weights": "uniform", "normalise": true, "full_scale": 65535})
    );
    // No reference position reaches either: nothing flagged on the
    // references, and the header carries both integers.
    let out = dmap(&[
        "stream",
        s(&r1),
        "--calibration",
        s(&cal),
        "--max-defect-lines",
        "9",
    ]);
    ok(&out);
    let h = header(&out.stdout);
    assert!(h.contains(&format!(",thr={want_thr},")), "{h}");
    assert!(h.contains(&format!(",pthr={want_pthr},")), "{h}");
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        !text
            .lines()
            .any(|l| l.starts_with('D') || l.starts_with('O')),
        "{text}"
    );
}

#[test]
fn calibration_streams_the_same_bytes_as_its_threshold() {
    let (r, scan) = (tmp("same-r.npy"), tmp("same-scan.npy"));
    reference(&r, 6, 8, 4, 3);
    // Two defects: the spot thrown aside at the centre (the CVM channel),
    // and at (1, 1) the spot at 80 % of its power (the power channel only).
    part_dimmed(&scan, 9, 8, 4, 4, true, 0.8);
    for (name, extra) in [
        ("norm", vec![]),
        ("raw", vec!["--raw"]),
        ("square", vec!["--kernels", "square"]),
    ] {
        let cal = tmp(&format!("same-{name}.json"));
        let mut args = vec!["calibrate", s(&r), "--k", "0", "-o", s(&cal)];
        args.extend(&extra);
        ok(&dmap(&args));
        // The thresholds as their integers in distance units and as a
        // contrast, exactly.
        let v = json(&cal);
        let ch = &v["channels"]["cvm"];
        let t = ch["thr"].as_f64().unwrap() * 2f64.powi(-(ch["q"].as_i64().unwrap() as i32));
        let t = format!("{t:?}");
        let pthr = v["channels"]["power"]["thr"].as_u64().unwrap();
        let pt = format!("{:?}", pthr as f64 / 32768.0);
        let sthr = v["channels"]["spread"]["thr"].as_u64().unwrap();
        let st = if sthr > 92680 {
            "inf".to_string()
        } else {
            format!("{:?}", sthr as f64 / 65536.0)
        };
        let run = |how: &[&str]| {
            let mut a = vec!["stream", s(&scan), "--scores"];
            a.extend(&extra);
            a.extend(how);
            let out = dmap(&a);
            ok(&out);
            out.stdout
        };
        let by_file = run(&["--calibration", s(&cal)]);
        let by_value = run(&[
            "--threshold",
            &t,
            "--power-threshold",
            &pt,
            "--spread-threshold",
            &st,
        ]);
        assert_eq!(by_file, by_value, "{name}");
        assert!(
            header(&by_file).contains(&format!(",pthr={pthr},")),
            "{name}"
        );
        // The scan differs from the reference: positions reach the
        // thresholds, and the dimmed spot is an object of the power channel.
        let objects: Vec<_> = by_file
            .split_inclusive(|&b| b == b'\n')
            .filter_map(|l| match cvm_core::protocol::parse(l) {
                Ok(cvm_core::protocol::Line::Object(o)) => Some(o),
                _ => None,
            })
            .collect();
        assert!(
            objects.iter().any(|o| o.row0 <= 1
                && 1 <= o.row1
                && o.col0 <= 1
                && 1 <= o.col1
                && o.channels & cvm_core::flags::POWER_DEFECT != 0),
            "{name}: {objects:?}"
        );
        assert!(
            objects
                .iter()
                .any(|o| o.channels & cvm_core::flags::CVM_DEFECT != 0),
            "{name}: {objects:?}"
        );
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
    // Both a threshold and a calibration, for any channel.
    for opt in ["--threshold", "--power-threshold", "--spread-threshold"] {
        let out = dmap(&["stream", s(&r), "--calibration", s(&cal), opt, "1"]);
        assert_eq!(out.status.code(), Some(2), "{opt}");
    }
    // A version 1 file (before the power channel): refused, not half
    // applied.
    let mut v1 = json(&cal);
    v1["version"] = serde_json::json!(1);
    v1["channels"].as_object_mut().unwrap().remove("power");
    let old = tmp("bad-v1.json");
    std::fs::write(&old, v1.to_string()).unwrap();
    one_line_error(
        &dmap(&["stream", s(&r), "--calibration", s(&old)]),
        "version 1 has no power-channel threshold",
    );
    // Power thresholds: tampered, not a Q15 threshold, missing; "off" is one.
    for (thr, threshold, needle) in [
        (None, Some(0.0), "channels.power.thr missing"),
        (
            Some(46341u64),
            Some(46341.0 / 32768.0),
            "not a power threshold",
        ),
        (
            Some(100),
            Some(100.5 / 32768.0),
            "is not the integer 100 in Q15",
        ),
        (Some(100), None, "channels.power.threshold missing"),
        (Some(u32::MAX as u64), Some(u32::MAX as f64 / 32768.0), ""),
    ] {
        let mut v = json(&cal);
        let p = &mut v["channels"]["power"];
        let o = p.as_object_mut().unwrap();
        o.remove("thr");
        o.remove("threshold");
        if let Some(t) = thr {
            p["thr"] = serde_json::json!(t);
        }
        if let Some(t) = threshold {
            p["threshold"] = serde_json::json!(t);
        }
        let f = tmp("bad-power.json");
        std::fs::write(&f, v.to_string()).unwrap();
        let out = dmap(&["stream", s(&r), "--calibration", s(&f)]);
        if needle.is_empty() {
            ok(&out);
            assert!(header(&out.stdout).contains(&format!(",pthr={},", u32::MAX)));
        } else {
            one_line_error(&out, needle);
        }
    }
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
    let v = json(&cal);
    let ch = &v["channels"]["cvm"];
    let exact = ch["thr"].as_f64().unwrap() * 2f64.powi(-(ch["q"].as_i64().unwrap() as i32));
    let pthr = v["channels"]["power"]["thr"].as_u64().unwrap() as u32;
    let pexact = f64::from(pthr) / 32768.0;
    let args = dmap::emulate::EmulateArgs {
        scan: scan.clone(),
        scoring: Default::default(),
        output: dmap::stream::OutputArgs {
            calibration: Some(cal.clone()),
            ..Default::default()
        },
        elf: None,
        icount: false,
        repo: Default::default(),
    };
    let (file, _) = dmap::emulate::scan_file_and_warnings(&args).unwrap();
    let header = cvm_fw_app::emufile::ScanHeader::parse(&file).unwrap();
    assert_eq!(header.threshold_units, exact);
    assert_eq!(header.power_threshold_units, pexact);
    assert_eq!(
        cvm_core::power::threshold_from_units(header.power_threshold_units),
        pthr
    );
    let scorer = dmap::options::ScoringArgs::default().scorer(5, 5).unwrap();
    assert_eq!(
        scorer.threshold_from_units(header.threshold_units) as f64,
        ch["thr"].as_f64().unwrap()
    );
    let config = dmap::twin::h743_config(&header).unwrap();
    // The H743 build takes the calibration's integers as they are.
    assert!(
        config.contains(&format!(" thr={} ", ch["thr"].as_u64().unwrap())),
        "{config}"
    );
    assert!(config.contains(&format!(" pthr={pthr} ")), "{config}");
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
