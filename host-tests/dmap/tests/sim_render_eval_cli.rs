//! `dmap simulate`, `render` and `eval` run as a user would: real files,
//! the real binary, one-line errors on bad input.

use std::path::{Path, PathBuf};
use std::process::Output;

use dmap::npy;

use crate::common;
use common::{dmap, ok, s};

fn tmp(name: &str) -> PathBuf {
    common::tmp_in("sre", name)
}

/// The command failed with exactly one line on stderr, naming the problem.
fn assert_one_line_error(out: &Output, needle: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "expected failure, stderr: {err}");
    assert_eq!(out.status.code(), Some(1), "stderr: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
    assert!(err.starts_with("dmap: error:"), "{err}");
    assert!(err.contains(needle), "{err:?} lacks {needle:?}");
    assert!(!err.contains("panicked"));
}

/// A usage error (clap refused the value): status 2, one line naming the
/// option, before any work.
fn assert_usage_error(out: &Output, option: &str, needle: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
    assert!(err.starts_with("dmap: error:"), "{err}");
    assert!(
        err.contains(&format!("'{option} <")),
        "{err:?} lacks {option:?}"
    );
    assert!(err.contains(needle), "{err:?} lacks {needle:?}");
    assert!(out.stdout.is_empty());
}

#[test]
fn simulate_writes_scan_and_truth_of_the_asked_shape_whatever_the_threads() {
    let a = tmp("sim-a.npy");
    let b = tmp("sim-b.npy");
    let mask = tmp("sim-a-mask.npy");
    let args = [
        "simulate",
        "--preset",
        "prototype",
        "--rows",
        "5",
        "--cols",
        "7",
        "--rays",
        "64",
        "--center-mm",
        "-3,3",
    ];
    ok(&dmap(
        &[
            &args[..],
            &["-o", s(&a), "--truth", s(&mask), "--threads", "1"],
        ]
        .concat(),
    ));
    ok(&dmap(
        &[&args[..], &["-o", s(&b), "--threads", "2"]].concat(),
    ));
    let scan = npy::read_scan(&a).unwrap();
    assert_eq!(
        (scan.rows, scan.cols, scan.geometry.j1(), scan.geometry.j2()),
        (5, 7, 9, 9)
    );
    assert_eq!(scan.dtype, npy::ScanDtype::U16);
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    // Default truth path sits beside the scan.
    let m = npy::read_mask(&mask).unwrap();
    assert_eq!(m, npy::read_mask(&tmp("sim-b.truth.npy")).unwrap());
    // Centred on the 2.8 mm patch at (-3, 3): every position is on the defect.
    assert_eq!((m.rows, m.cols), (5, 7));
    assert!(m.data.iter().all(|&t| t));
}

#[test]
fn simulate_rejects_bad_parameters_in_one_line() {
    let o = tmp("bad.npy");
    // Every case fails while checking the configuration, before simulating.
    let base = ["simulate", "--preset", "prototype", "-o", s(&o)];
    for (extra, needle) in [
        (
            vec!["--bubble", "1,2"],
            "--bubble 1,2: expected 4 comma-separated numbers, got 2",
        ),
        (
            vec!["--scratch", "1,2,3,4,0.1,9"],
            "--scratch 1,2,3,4,0.1,9: expected 4..=5 comma-separated numbers, got 6",
        ),
        (
            vec!["--center-mm", "1"],
            "--center-mm 1: expected 2 comma-separated numbers, got 1",
        ),
        (vec!["--bubble", "0,0,-3,0.1"], "not inside the part"),
        (vec!["--bits", "17"], "bit depth"),
        (vec!["--rows", "0"], "at least one position"),
        (vec!["--rays", "0"], "rays per beam"),
        (vec!["--pitch-um=-5"], "pitch"),
        (vec!["--index", "nan"], "refractive index"),
        (vec!["--part", "plate", "--radius-mm", "5"], "flat plate"),
    ] {
        assert_one_line_error(&dmap(&[&base[..], &extra[..]].concat()), needle);
    }
    // Values clap refuses: a usage error naming the option.
    let axes = "expected J1xJ2 with each axis in 1..=16, e.g. 15x15";
    for (extra, option, needle) in [
        (vec!["--detector", "20x20"], "--detector", axes),
        (vec!["--detector", "0x5"], "--detector", axes),
        (vec!["--detector", "9by9"], "--detector", axes),
        (vec!["--detector", "9"], "--detector", axes),
        (
            vec!["--bubble", "1,x,3,4"],
            "--bubble",
            "'x': expected a finite number",
        ),
        (
            vec!["--scratch=-1,-1,1,inf"],
            "--scratch",
            "'inf': expected a finite number",
        ),
        (
            vec!["--center-mm", "1,nan"],
            "--center-mm",
            "invalid value 'nan'",
        ),
        (
            vec!["--center-mm", "1,2", "--center-mm", "3,4"],
            "--center-mm",
            "cannot be used multiple times",
        ),
    ] {
        assert_usage_error(&dmap(&[&base[..], &extra[..]].concat()), option, needle);
    }
    assert!(!o.exists());
    let nowhere = tmp("no/such/dir/x.npy");
    assert_one_line_error(
        &dmap(&[
            "simulate",
            "--preset",
            "prototype",
            "--rows",
            "1",
            "--cols",
            "1",
            "-o",
            s(&nowhere),
        ]),
        "no/such/dir",
    );
}

/// `--detector`, `--bubble` and `--scratch` as typed reach the simulator:
/// the scan has the detector's cells, a bubble or a scratch under the whole
/// raster makes every position a defect, and without them the raster (far
/// from the preset's patches) has none.
#[test]
fn simulate_takes_detector_bubble_and_scratch_as_typed() {
    let base = [
        "simulate",
        "--preset",
        "prototype",
        "--rows",
        "3",
        "--cols",
        "3",
        "--rays",
        "64",
        "--center-mm",
        "10, 10",
        "--detector",
        "5x7",
        "--threads",
        "1",
    ];
    for (name, extra, defect) in [
        ("plain", vec![], false),
        ("bubble", vec!["--bubble", "10,10,2.5,1"], true),
        ("scratch", vec!["--scratch", "9, 9, 11, 11, 0.2"], true),
        // Each --bubble is one bubble: the second one lies elsewhere.
        (
            "bubbles",
            vec!["--bubble=-10,-10,2.5,1", "--bubble", "10,10,2.5,1"],
            true,
        ),
    ] {
        let out = tmp(&format!("typed-{name}.npy"));
        let truth = tmp(&format!("typed-{name}.truth.npy"));
        ok(&dmap(&[&base[..], &extra[..], &["-o", s(&out)]].concat()));
        let scan = npy::read_scan(&out).unwrap();
        assert_eq!(
            (scan.rows, scan.cols, scan.geometry.j1(), scan.geometry.j2()),
            (3, 3, 5, 7),
            "{name}"
        );
        let m = npy::read_mask(&truth).unwrap();
        assert!(m.data.iter().all(|&t| t == defect), "{name}: {:?}", m.data);
    }
}

/// Share of a map's counts outside the 3x3 cells around its brightest cell.
fn outside_core(map: &[f64], j1: usize, j2: usize) -> f64 {
    let (mut best, mut at) = (f64::MIN, 0);
    for (i, &v) in map.iter().enumerate() {
        if v > best {
            (best, at) = (v, i);
        }
    }
    let (r0, c0) = (at / j2, at % j2);
    let total: f64 = map.iter().sum();
    let core: f64 = (0..j1 * j2)
        .filter(|i| (i / j2).abs_diff(r0) <= 1 && (i % j2).abs_diff(c0) <= 1)
        .map(|i| map[i])
        .sum();
    1.0 - core / total
}

/// `--scatter` places a scattering disc: its positions are marked in the
/// truth mask (the beam's footprint reaching the disc, as for the other
/// defects), the map of a beam through it spreads light into a halo, and
/// the positions whose beam misses it are the scan without it, bit for bit.
#[test]
fn simulate_places_scattering_discs_in_the_scan_and_the_truth() {
    let base = [
        "simulate",
        "--preset",
        "prototype",
        "--rows",
        "7",
        "--cols",
        "7",
        "--rays",
        "64",
        "--center-mm",
        "10,10",
        "--threads",
        "1",
    ];
    let run = |name: &str, extra: &[&str]| {
        let out = tmp(&format!("scatter-{name}.npy"));
        ok(&dmap(&[&base[..], extra, &["-o", s(&out)]].concat()));
        let truth = tmp(&format!("scatter-{name}.truth.npy"));
        (
            npy::read_scan(&out).unwrap(),
            npy::read_mask(&truth).unwrap(),
        )
    };
    let (plain, none) = run("plain", &[]);
    assert!(none.data.iter().all(|&t| !t));
    // One position across (radius 0.167 mm) at the raster's centre: the
    // truth reaches radius + one waist (0.25 mm) = 0.417 mm, so the centre
    // and its four neighbours (0.334 mm away), not the diagonals (0.472 mm).
    let (disc, truth) = run("disc", &["--scatter", "10,10,1,0.5"]);
    let marked: Vec<(usize, usize)> = (0..49)
        .filter(|&i| truth.data[i])
        .map(|i| (i / 7, i % 7))
        .collect();
    assert_eq!(marked, vec![(2, 3), (3, 2), (3, 3), (3, 4), (4, 3)]);
    let (j1, j2) = (plain.geometry.j1(), plain.geometry.j2());
    let (before, after) = (
        outside_core(plain.map(3, 3), j1, j2),
        outside_core(disc.map(3, 3), j1, j2),
    );
    // Half the light crossing the disc (59 % of the beam) goes into a halo
    // of 0.06 rad, 3 mm rms on the 1 mm cells: far more outside the core.
    assert!(after > before + 0.1, "outside the core {before} -> {after}");
    for (r, c) in [(0, 0), (0, 6), (6, 0), (6, 6)] {
        assert_eq!(plain.map(r, c), disc.map(r, c), "({r}, {c})");
    }
    // A wider halo puts less of it on the array than the default 0.06 rad.
    let (wide, _) = run("wide", &["--scatter", "10, 10, 1, 0.5, 0.3"]);
    let on = |m: &[f64]| m.iter().sum::<f64>();
    assert!(on(wide.map(3, 3)) < on(disc.map(3, 3)));
    // A disc elsewhere, even scattering everything, changes nothing here.
    let (far, nothing) = run("far", &["--scatter=-10,-10,2,1"]);
    assert_eq!(far.data, plain.data);
    assert!(nothing.data.iter().all(|&t| !t));
    // The reference part has none.
    let (free, clean) = run("free", &["--scatter", "10,10,1,0.5", "--defect-free"]);
    assert_eq!(free.data, plain.data);
    assert!(clean.data.iter().all(|&t| !t));
}

#[test]
fn simulate_refuses_bad_scattering_discs_in_one_line() {
    let o = tmp("bad-scatter.npy");
    let base = ["simulate", "--preset", "prototype", "-o", s(&o)];
    for (v, needle) in [
        (
            "1,2,3",
            "--scatter 1,2,3: expected 4..=5 comma-separated numbers, got 3",
        ),
        (
            "1,2,3,0.1,0.06,7",
            "expected 4..=5 comma-separated numbers, got 6",
        ),
        (
            "1,2,0,0.1",
            "--scatter 1,2,0,0.1: the disc's size must be positive",
        ),
        (
            "1,2,-1,0.1",
            "size must be positive (raster positions across), got -1",
        ),
        ("1,2,3,0", "the scattered share must be in (0, 1], got 0"),
        (
            "1,2,3,1.5",
            "the scattered share must be in (0, 1], got 1.5",
        ),
        (
            "1,2,3,0.2,0",
            "the halo width must be in (0, 0.5) rad, got 0",
        ),
        (
            "1,2,3,0.2,0.5",
            "the halo width must be in (0, 0.5) rad, got 0.5",
        ),
    ] {
        let arg = format!("--scatter={v}");
        assert_one_line_error(&dmap(&[&base[..], &[arg.as_str()]].concat()), needle);
    }
    assert_usage_error(
        &dmap(&[&base[..], &["--scatter", "1,2,nan,0.1"]].concat()),
        "--scatter",
        "'nan': expected a finite number",
    );
    assert!(!o.exists());
}

/// A 4x5 gradient whose magnitude channel is `mag`.
fn gradient(path: &Path, mag: &[f64]) {
    let data: Vec<f64> = mag.iter().flat_map(|&m| [m * 0.6, m * 0.8, m]).collect();
    npy::write_gradient(path, 4, 5, &data).unwrap();
}

fn mask(path: &Path, rows: usize, cols: usize, on: &[(usize, usize)]) {
    let mut data = vec![false; rows * cols];
    for &(r, c) in on {
        data[r * cols + c] = true;
    }
    npy::write_mask(path, &npy::Mask { rows, cols, data }).unwrap();
}

#[test]
fn eval_json_matches_hand_computed_metrics_and_sizes() {
    // Defect (truth) = 2x2 block rows 1-2, cols 1-2 with scores 10, 20, 30, NaN.
    #[rustfmt::skip]
    let mag = [
        1.0, 1.0, 1.0, 1.0, 1.0,
        1.0, 10.0, 20.0, 3.0, 1.0,
        1.0, 30.0, f64::NAN, 1.0, 1.0,
        1.0, 1.0, 1.0, 1.0, 3.0,
    ];
    let g = tmp("eval-g.npy");
    let m = tmp("eval-m.npy");
    gradient(&g, &mag);
    mask(&m, 4, 5, &[(1, 1), (1, 2), (2, 1), (2, 2)]);
    let out = dmap(&[
        "eval",
        s(&g),
        "--truth",
        s(&m),
        "--json",
        "--threshold",
        "5",
        "--pitch-um",
        "500",
    ]);
    ok(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    assert_eq!(text.trim_end().lines().count(), 1);
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    // Defect-free: 14 ones and two threes: mean 20/16 = 1.25, E[x^2] = (14 + 18)/16 = 2,
    // variance 2 - 1.5625 = 0.4375. Defect (NaN left out): mean 20, max 30.
    let sd = 0.4375f64.sqrt();
    let close = |k: &str, want: f64| {
        let got = v[k].as_f64().unwrap();
        assert!(
            (got - want).abs() < 1e-12 * want.abs(),
            "{k}: {got} vs {want}"
        );
    };
    close("snr", 20.0 / sd);
    close("psnr", 30.0 / sd);
    close("cnr", (30.0 - 1.25) / sd);
    close("threshold", 5.0);
    // Above 5 near the defect: (1,1), (1,2), (2,1): 2 wide, 2 high -> 1.0 mm at 500 um.
    assert_eq!(
        v["defects"],
        serde_json::json!([{"truth_mm": [1.0, 1.0], "estimated_mm": [1.0, 1.0]}])
    );
    let keys: Vec<&String> = v.as_object().unwrap().keys().collect();
    assert_eq!(keys.len(), 6);
}

#[test]
fn eval_table_states_the_automatic_threshold_rule() {
    let g = tmp("eval-auto-g.npy");
    let m = tmp("eval-auto-m.npy");
    let mut mag = [0.0; 20];
    mag[7] = 9.0;
    mag[0] = 1.0;
    gradient(&g, &mag);
    mask(&m, 4, 5, &[(1, 2)]);
    let out = dmap(&["eval", s(&g), "--truth", s(&m)]);
    ok(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    // 19 defect-free values: one 1 and eighteen 0: mean 1/19, variance 1/19 - 1/361.
    let mean: f64 = 1.0 / 19.0;
    let t = mean + 5.0 * (mean - mean * mean).sqrt();
    assert!(
        text.contains(&format!("threshold {t:.6} (defect-free mean + 5 x std)")),
        "{text}"
    );
    assert!(text.contains("0.33 x 0.33"), "{text}");
}

#[test]
fn eval_and_render_reject_bad_input_in_one_line() {
    let g = tmp("bad-g.npy");
    let m = tmp("bad-m.npy");
    let m2 = tmp("bad-m2.npy");
    gradient(&g, &[1.0; 20]);
    mask(&m, 4, 5, &[(0, 0)]);
    mask(&m2, 5, 4, &[(0, 0)]);
    let missing = tmp("missing.npy");
    let junk = tmp("junk.npy");
    std::fs::write(&junk, b"not an npy file").unwrap();
    let scan = tmp("bad-scan.npy");
    npy::write_scan_u16(
        &scan,
        1,
        1,
        cvm_reference::Geometry::new(2, 2).unwrap(),
        &[1, 2, 3, 4],
    )
    .unwrap();
    assert_one_line_error(
        &dmap(&["eval", s(&g), "--truth", s(&m2)]),
        "is 5x4 but the scores are 4x5",
    );
    assert_one_line_error(
        &dmap(&["eval", s(&missing), "--truth", s(&m)]),
        "missing.npy",
    );
    assert_one_line_error(
        &dmap(&["eval", s(&g), "--truth", s(&missing)]),
        "missing.npy",
    );
    assert_one_line_error(&dmap(&["eval", s(&junk), "--truth", s(&m)]), "junk.npy");
    assert_one_line_error(&dmap(&["eval", s(&g), "--truth", s(&g)]), "bad-g.npy");
    assert_one_line_error(&dmap(&["eval", s(&scan), "--truth", s(&m)]), "bad-scan.npy");
    assert_one_line_error(
        &dmap(&["eval", s(&g), "--truth", s(&m), "--pitch-um", "0"]),
        "--pitch-um",
    );
    // A component by its old name and an index out of range: a usage error.
    assert_usage_error(
        &dmap(&["eval", s(&g), "--truth", s(&m), "--channel", "3"]),
        "--component",
        "invalid value '3'",
    );
    let png = tmp("bad.png");
    assert_one_line_error(
        &dmap(&["render", s(&missing), "-o", s(&png)]),
        "missing.npy",
    );
    assert_one_line_error(&dmap(&["render", s(&junk), "-o", s(&png)]), "junk.npy");
    assert_one_line_error(&dmap(&["render", s(&scan), "-o", s(&png)]), "bad-scan.npy");
    // A component by its old name and an index out of range: a usage error.
    assert_usage_error(
        &dmap(&["render", s(&g), "-o", s(&png), "--channel", "3"]),
        "--component",
        "invalid value '3'",
    );
    assert_one_line_error(
        &dmap(&["render", s(&g), s(&g), "-o", s(&png), "--titles", "one"]),
        "--titles has 1 entries for 2 input files",
    );
    let render = ["render", s(&g), "-o", s(&png)];
    for (crop, needle) in [
        ("1,2,3", "--crop 1,2,3: expected R0,C0,H,W with H, W >= 1"),
        ("1,2,3,4,5", "--crop 1,2,3,4,5: expected R0,C0,H,W"),
        (
            "0,0,0,2",
            "--crop 0,0,0,2: expected R0,C0,H,W with H, W >= 1",
        ),
    ] {
        assert_one_line_error(&dmap(&[&render[..], &["--crop", crop]].concat()), needle);
    }
    for (extra, option, needle) in [
        (
            vec!["--crop", "1,2,a,4"],
            "--crop",
            "invalid value 'a' for '--crop <R0,C0,H,W>': expected a whole number >= 0",
        ),
        (vec!["--crop", "0,-1,2,2"], "--crop", "invalid value '-1'"),
        (
            vec!["--titles", "a", "--titles", "b"],
            "--titles",
            "cannot be used multiple times",
        ),
    ] {
        assert_usage_error(&dmap(&[&render[..], &extra[..]].concat()), option, needle);
    }
    assert!(!png.exists());
    assert_one_line_error(
        &dmap(&["render", s(&g), "-o", s(&png), "--vmin", "2", "--vmax", "1"]),
        "--vmin",
    );
    assert_one_line_error(
        &dmap(&["render", s(&g), "-o", s(&tmp("no/dir/x.png"))]),
        "no/dir/x.png",
    );
}

#[test]
fn render_writes_a_png_with_one_panel_per_file() {
    let g = tmp("render-g.npy");
    let mut mag: Vec<f64> = (0..20).map(f64::from).collect();
    mag[3] = f64::NAN;
    gradient(&g, &mag);
    let one = tmp("one.png");
    let two = tmp("two.png");
    ok(&dmap(&["render", s(&g), "-o", s(&one), "--scale", "10"]));
    ok(&dmap(&[
        "render",
        s(&g),
        s(&g),
        "-o",
        s(&two),
        "--scale",
        "10",
        "--titles",
        " a , b ",
        "--log",
    ]));
    let dims = |p: &Path| {
        let bytes = std::fs::read(p).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        // IHDR: width and height, big-endian, right after the chunk header.
        let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
        let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
        (w, h)
    };
    let (w1, h1) = dims(&one);
    let (w2, h2) = dims(&two);
    assert_eq!(h1, h2);
    assert!(w1 > 50 && w2 > 2 * w1 - 20 && w2 < 2 * w1, "{w1} {w2}");
}
