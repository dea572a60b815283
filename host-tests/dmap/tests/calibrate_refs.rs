//! `dmap calibrate` given references that cannot calibrate, or that make
//! a calibration a user must hear about (issue 37, item 5).

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::common;
use common::{dmap, ok, s};

fn tmp(name: &str) -> PathBuf {
    common::tmp_in("calrefs", name)
}

fn scan_of(path: &Path, rows: usize, cols: usize, sample: u16) {
    let g = cvm_reference::Geometry::new(5, 5).unwrap();
    let data = vec![sample; rows * cols * 25];
    dmap::npy::write_scan_u16(path, rows, cols, g, &data).unwrap();
}

fn one_line_error(out: &Output, needle: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
    assert!(err.contains(needle), "{err:?} lacks {needle:?}");
}

fn warnings(out: &Output) -> Vec<String> {
    String::from_utf8_lossy(&out.stderr)
        .lines()
        .filter(|l| l.starts_with("dmap: warning: "))
        .map(str::to_string)
        .collect()
}

#[test]
fn references_that_cannot_calibrate_are_refused() {
    let good = tmp("good.npy");
    common::spot_scan(&good, 6, 7, 5, 1);
    let cal = tmp("unfit.json");
    for (name, rows, cols, sample, what) in [
        ("dark", 6, 7, 0, "is dark"),
        ("saturated", 6, 7, u16::MAX, "is saturated"),
        ("constant", 6, 7, 1000, "is constant (every sample is 1000)"),
        ("single", 1, 1, 1000, "1 x 1 positions"),
        ("row", 1, 9, 1000, "1 x 9 positions"),
    ] {
        let bad = tmp(&format!("{name}.npy"));
        scan_of(&bad, rows, cols, sample);
        let out = dmap(&["calibrate", s(&good), s(&bad), "-o", s(&cal)]);
        one_line_error(&out, what);
        assert!(!cal.exists(), "{name}: a calibration was written");
    }
    // Saturated against a lower full scale too.
    let bright = tmp("bright.npy");
    scan_of(&bright, 6, 7, 4095);
    let out = dmap(&[
        "calibrate",
        s(&bright),
        "--full-scale",
        "4095",
        "-o",
        s(&cal),
    ]);
    one_line_error(&out, "at or above the full scale 4095");
}

#[test]
fn a_reference_given_twice_is_refused() {
    let r = tmp("twice.npy");
    common::spot_scan(&r, 6, 7, 5, 1);
    let link = tmp("twice-link.npy");
    let _ = std::fs::remove_file(&link);
    std::fs::hard_link(&r, &link).unwrap();
    let cal = tmp("twice.json");
    for other in [&r, &link] {
        let out = dmap(&["calibrate", s(&r), s(other), "-o", s(&cal)]);
        one_line_error(&out, "are the same file");
    }
    assert!(!cal.exists());
}

#[test]
fn a_defective_reference_and_channels_turned_off_are_warned_about() {
    let (r1, r2, r3) = (tmp("w1.npy"), tmp("w2.npy"), tmp("w3.npy"));
    common::spot_scan(&r1, 6, 7, 5, 1);
    common::spot_scan(&r2, 6, 7, 5, 2);
    // r3: a third part with one position's spot thrown to the far corner (a
    // defect).
    common::spot_scan(&r3, 6, 7, 5, 3);
    let mut data = dmap::npy::read_scan(&r3).unwrap().to_u16().unwrap();
    let at = (3 * 7 + 3) * 25;
    data[at..at + 25].fill(0);
    data[at + 24] = 3000;
    let g = cvm_reference::Geometry::new(5, 5).unwrap();
    dmap::npy::write_scan_u16(&r3, 6, 7, g, &data).unwrap();
    let cal = tmp("w.json");
    let clean = dmap(&["calibrate", s(&r1), s(&r2), "-o", s(&cal)]);
    ok(&clean);
    assert_eq!(warnings(&clean), Vec::<String>::new());
    let out = dmap(&["calibrate", s(&r1), s(&r2), s(&r3), "-o", s(&cal)]);
    ok(&out);
    let w = warnings(&out);
    assert!(
        w.iter()
            .any(|l| l.contains("w3.npy") && l.contains("CVM threshold the other references give")),
        "{w:?}"
    );
    assert!(
        w.iter()
            .all(|l| !l.contains("w1.npy") && !l.contains("w2.npy")),
        "{w:?}"
    );
    // The JSON's own count agrees.
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&cal).unwrap()).unwrap();
    assert!(v["references"][2]["at_or_above_others_threshold"].as_u64() >= Some(1));
    // A margin that turns both channels off: the largest k the board's
    // integers hold (thousandths in a u32); a larger one is refused.
    one_line_error(
        &dmap(&["calibrate", s(&r1), s(&r2), "--k", "1e300", "-o", s(&cal)]),
        "--k-mad must be a multiple of 0.001 and at most 4294967.295",
    );
    let out = dmap(&[
        "calibrate",
        s(&r1),
        s(&r2),
        "--k",
        "4294967.295",
        "-o",
        s(&cal),
    ]);
    ok(&out);
    let w = warnings(&out);
    assert!(
        w.iter().any(|l| l.contains("the CVM channel is off")),
        "{w:?}"
    );
    assert!(
        w.iter().any(|l| l.contains("the power channel is off")),
        "{w:?}"
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&cal).unwrap()).unwrap();
    assert_eq!(v["channels"]["cvm"]["thr"], u32::MAX);
}
