//! `--calibration` given what a user may give it (issue 37, items 2, 8
//! and 11): an endless source, a pipe read once, a byte order mark.

use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Output, Stdio};

use crate::common;
use common::{dmap, ok, s};

fn tmp(name: &str) -> PathBuf {
    common::tmp_in("calinput", name)
}

/// Runs `dmap args` with `feed` written to its standard input (a pipe)
/// from another thread; `feed` returns once its writes fail.
fn dmap_fed(args: &[&str], feed: impl FnOnce(&mut dyn Write) + Send + 'static) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || feed(&mut stdin));
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap();
    out
}

fn calibration() -> (PathBuf, PathBuf) {
    let (r1, r2, scan) = (tmp("r1.npy"), tmp("r2.npy"), tmp("scan.npy"));
    common::spot_scan(&r1, 6, 7, 5, 1);
    common::spot_scan(&r2, 6, 7, 5, 2);
    common::spot_scan(&scan, 6, 7, 5, 3);
    let cal = tmp("cal.json");
    ok(&dmap(&["calibrate", s(&r1), s(&r2), "-o", s(&cal)]));
    (cal, scan)
}

#[test]
fn an_endless_calibration_is_refused_after_a_bounded_read() {
    let (_, scan) = calibration();
    let out = dmap_fed(&["stream", s(&scan), "--calibration", "/dev/stdin"], |w| {
        let zeros = vec![0u8; 1 << 16];
        // 64 MiB at most: far past the cap, and an end if it is not kept.
        for _ in 0..1024 {
            if w.write_all(&zeros).is_err() {
                return;
            }
        }
    });
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("larger than 1024 KiB"), "{err}");
}

#[test]
fn a_calibration_on_a_pipe_is_read_once() {
    let (cal, scan) = calibration();
    let text = std::fs::read(&cal).unwrap();
    // eval, with the gradient image of the scan and an empty truth mask.
    let grad = tmp("grad.npy");
    ok(&dmap(&[
        "score",
        s(&scan),
        "--distance",
        "cvm-fixed",
        "-o",
        s(&grad),
    ]));
    let mask = tmp("mask.npy");
    std::fs::write(&mask, common::raw_npy("|b1", false, &[6, 7], &[0; 42])).unwrap();
    let args = |c: &str| {
        [
            "eval",
            s(&grad),
            "--truth",
            s(&mask),
            "--json",
            "--calibration",
        ]
        .iter()
        .map(|a| a.to_string())
        .chain([c.to_string()])
        .collect::<Vec<_>>()
    };
    let from_file = dmap(&args(s(&cal)).iter().map(String::as_str).collect::<Vec<_>>());
    ok(&from_file);
    let t = text.clone();
    let from_pipe = dmap_fed(
        &args("/dev/stdin")
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
        move |w| {
            let _ = w.write_all(&t);
        },
    );
    ok(&from_pipe);
    assert_eq!(from_pipe.stdout, from_file.stdout);
    // stream too.
    let want = dmap(&["stream", s(&scan), "--calibration", s(&cal)]);
    ok(&want);
    let got = dmap_fed(
        &["stream", s(&scan), "--calibration", "/dev/stdin"],
        move |w| {
            let _ = w.write_all(&text);
        },
    );
    ok(&got);
    assert_eq!(got.stdout, want.stdout);
}

#[test]
fn a_calibration_with_a_byte_order_mark_is_the_same_calibration() {
    let (cal, scan) = calibration();
    let bom = tmp("bom.json");
    let mut bytes = b"\xef\xbb\xbf".to_vec();
    bytes.extend(std::fs::read(&cal).unwrap());
    std::fs::write(&bom, bytes).unwrap();
    let want = dmap(&["stream", s(&scan), "--calibration", s(&cal)]);
    ok(&want);
    let got = dmap(&["stream", s(&scan), "--calibration", s(&bom)]);
    ok(&got);
    assert_eq!(got.stdout, want.stdout);
}
