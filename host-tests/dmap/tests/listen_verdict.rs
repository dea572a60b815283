//! The end line's verdict in `dmap listen`: shown in the scan's summary
//! and in `--json`, and checked against the line's own totals.

use cvm_reference::Geometry;
use dmap::listen::Decoder;
use dmap::npy::write_scan_u16;
use std::process::Command;

fn dmap(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(args)
        .output()
        .expect("running dmap")
}

/// `body` with its `*XXXX` trailer (CRC-16/CCITT-FALSE) and newline.
fn with_crc(body: &str) -> String {
    format!(
        "{body}*{:04X}\n",
        cvm_core::protocol::crc16(body.as_bytes())
    )
}

/// A 4 x 6 scan of flat 3x3 maps, one with a bright spot when `defect`.
fn stream(defect: bool) -> String {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    let mut data = vec![600u16; 4 * 6 * 9];
    if defect {
        for v in &mut data[(6 + 3) * 9..(6 + 3) * 9 + 9].iter_mut().step_by(2) {
            *v = 9000;
        }
    }
    write_scan_u16(&scan, 4, 6, Geometry::new(3, 3).unwrap(), &data).unwrap();
    let out = dmap(&["stream", scan.to_str().unwrap(), "--threshold", "0.05"]);
    assert!(out.status.success());
    String::from_utf8(out.stdout).unwrap()
}

fn problems(lines: &str) -> Vec<String> {
    let mut dec = Decoder::new();
    for l in lines.split_inclusive('\n') {
        dec.feed(l.as_bytes());
    }
    dec.finish();
    dec.scans[0]
        .problems
        .iter()
        .map(|p| p.what.clone())
        .collect()
}

#[test]
fn listen_shows_the_verdict_in_the_summary_and_json() {
    for (defect, verdict) in [(false, "good"), (true, "obj")] {
        let lines = stream(defect);
        assert!(lines.contains(&format!(",verdict={verdict}*")), "{lines}");
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("lines.txt");
        std::fs::write(&input, &lines).unwrap();
        let img = dir.path().join("img.npy");
        let args = [
            "listen",
            "--input",
            input.to_str().unwrap(),
            "-o",
            img.to_str().unwrap(),
        ];
        let text = String::from_utf8(dmap(&args).stdout).unwrap();
        assert!(
            text.contains(&format!("  verdict: {verdict} (part ")),
            "{text}"
        );
        assert!(
            text.contains(&format!(" dropped 0 verdict {verdict}\n")),
            "{text}"
        );
        let json = dmap(&[&args[..], &["--json"]].concat());
        let v: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
        assert_eq!(v["verdict"], verdict, "{v}");
        assert_eq!(v["totals"]["verdict"], verdict, "{v}");
        assert_eq!(v["scans"][0]["verdict"], verdict, "{v}");
        assert!(problems(&lines).is_empty(), "{:?}", problems(&lines));
    }
}

/// An end line whose verdict its own totals contradict is a problem of
/// its scan; one they allow is not.
#[test]
fn listen_checks_the_verdict_against_the_totals() {
    let good = stream(false);
    let obj = stream(true);
    let forge = |lines: &str, from: &str, to: &str| -> String {
        lines
            .lines()
            .map(|l| {
                if l.starts_with("E,") {
                    let body = l.split('*').next().unwrap().replace(from, to);
                    with_crc(&body)
                } else {
                    format!("{l}\n")
                }
            })
            .collect()
    };
    for (lines, from, to, bad) in [
        (&good, "verdict=good", "verdict=obj", true),
        (&good, "verdict=good", "verdict=fault-missing", true),
        (&good, "verdict=good", "verdict=fault-misplaced", true),
        (&good, "verdict=good", "verdict=fault-frames", true),
        (&good, "bad=0,", "bad=1,", true),
        // Objects that the board's minimum size leaves out: allowed.
        (&obj, "verdict=obj", "verdict=good", false),
        // Missing positions within the board's limit: allowed.
        (&good, "missing=0,", "missing=1,", false),
    ] {
        let forged = forge(lines, from, to);
        assert_ne!(&forged, lines);
        let p = problems(&forged);
        let verdict_problems = p.iter().filter(|w| w.contains("verdict")).count();
        assert_eq!(verdict_problems > 0, bad, "{from} -> {to}: {p:?}");
    }
    // Unknown verdicts do not parse.
    let unknown = forge(&good, "verdict=good", "verdict=fine");
    let mut dec = Decoder::new();
    for l in unknown.split_inclusive('\n') {
        dec.feed(l.as_bytes());
    }
    dec.finish();
    assert!(dec.error_count() > 0);
}
