//! The field device on the H743 release firmware, run on the chip model
//! over several simulated parts scanned one after the other (`dmap twin
//! --parts`): settings changed on the command channel take effect when
//! the next scan starts, never in the middle of one, and the header says
//! where each value came from. Every part is checked against `dmap
//! stream` of that part alone, with the settings the part was scanned
//! with.

mod common;

use common::dmap_ok as dmap;
use cvm_core::command::Key;
use cvm_core::protocol::{self, Line};
use cvm_core::settings::Source;
use dmap::npy::{read_scan, write_scan_u16};
use dmap::twin_requests::write_requests;
use std::path::{Path, PathBuf};

/// Rows and columns of one part: a window of the prototype preset.
const ROWS: usize = 8;
const COLS: usize = 24;
/// The options of every run in this file: one firmware build serves them all.
const OPTS: [&str; 2] = ["--full-scale", "4095"];

/// CRC-16/CCITT-FALSE, bit by bit.
fn crc(data: &[u8]) -> u16 {
    let mut c: u16 = 0xFFFF;
    for &b in data {
        c ^= (b as u16) << 8;
        for _ in 0..8 {
            c = if c & 0x8000 != 0 {
                (c << 1) ^ 0x1021
            } else {
                c << 1
            };
        }
    }
    c
}

fn framed(body: &str) -> Vec<u8> {
    format!("{body}*{:04X}\n", crc(body.as_bytes())).into_bytes()
}

/// A simulated part: the prototype's set-up, `seed`'s noise, with its
/// defects or without.
fn part(dir: &Path, seed: u64, defects: bool) -> PathBuf {
    let p = dir.join(format!("part{seed}{}.npy", if defects { "d" } else { "" }));
    let (rows, cols, seed_s) = (ROWS.to_string(), COLS.to_string(), seed.to_string());
    let mut args = vec![
        "simulate",
        "--preset",
        "prototype",
        "--rows",
        &rows,
        "--cols",
        &cols,
    ];
    args.extend([
        "--seed",
        &seed_s,
        "--threads",
        "1",
        "-o",
        p.to_str().unwrap(),
    ]);
    if !defects {
        args.push("--defect-free");
    }
    dmap(&args);
    p
}

/// The parts one after the other, as one scan.
fn concat(parts: &[PathBuf], out: &Path) {
    let mut data = Vec::new();
    let mut geometry = None;
    for p in parts {
        let s = read_scan(p).unwrap();
        assert_eq!((s.rows, s.cols), (ROWS, COLS));
        geometry = Some(s.geometry);
        data.extend(s.data.iter().map(|&v| v as u16));
    }
    write_scan_u16(out, ROWS * parts.len(), COLS, geometry.unwrap(), &data).unwrap();
}

/// The twin's output: its reply lines, and its result lines split into scans.
fn scans(out: &[u8]) -> (Vec<String>, Vec<Vec<String>>) {
    let text = String::from_utf8_lossy(out);
    let (mut replies, mut scans): (Vec<String>, Vec<Vec<String>>) = (vec![], vec![]);
    for l in text.lines() {
        if l.starts_with("A,") {
            replies.push(l.to_string());
        } else {
            if l.starts_with("H,") {
                scans.push(Vec::new());
            }
            scans
                .last_mut()
                .expect("a line before the first header")
                .push(l.to_string());
        }
    }
    (replies, scans)
}

/// `dmap stream` of one part with extra options, as lines.
fn stream(part: &Path, extra: &[&str]) -> Vec<String> {
    let out = dmap(&[&["stream", part.to_str().unwrap()][..], &OPTS, extra].concat());
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(String::from)
        .collect()
}

/// The header of a scan's lines, decoded.
fn header(lines: &[String]) -> protocol::HeaderInfo<'static> {
    let l: &'static str = Box::leak(format!("{}\n", lines[0]).into_boxed_str());
    match protocol::parse(l.as_bytes()) {
        Ok(Line::Header(h)) => h,
        other => panic!("{other:?}: {l}"),
    }
}

#[test]
fn a_changed_setting_takes_effect_when_the_next_scan_starts() {
    let dir = tempfile::tempdir().unwrap();
    let parts = [part(dir.path(), 21, true), part(dir.path(), 22, true)];
    let scan = dir.path().join("two.npy");
    concat(&parts, &scan);
    // The first part's threshold, and half of it in integer score units.
    let first = stream(&parts[0], &[]);
    let thr = header(&first).threshold;
    let q = header(&first).q;
    let half = thr / 2;
    // Mid-part: during the first scan, its row 3.
    let req = dir.path().join("req.txt");
    let set = [
        framed(&format!("C,1,set,thr={half}")),
        framed("C,2,set,dcap=3"),
        framed("C,3,get,thr"),
    ]
    .concat();
    write_requests(&req, &[(3 * COLS as u64 + 5, &set)]).unwrap();
    let out = dmap(
        &[
            &["twin", scan.to_str().unwrap()][..],
            &OPTS,
            &["--parts", "2", "--requests", req.to_str().unwrap()],
        ]
        .concat(),
    );
    let (replies, got) = scans(&out.stdout);
    assert_eq!(got.len(), 2);
    assert_eq!(
        replies,
        [
            String::from_utf8(framed(&format!("A,1,ok,thr={half}:c"))).unwrap(),
            String::from_utf8(framed("A,2,ok,dcap=3:c")).unwrap(),
            String::from_utf8(framed(&format!("A,3,ok,thr={half}:c"))).unwrap(),
        ]
        .map(|l| l.trim_end().to_string())
    );
    // The first scan went on with the settings it began with.
    assert_eq!(got[0], first, "the change reached the scan under way");
    // The second scan: the new values, sourced `c`, everything else
    // the compiled default, and otherwise `dmap stream`'s lines at that
    // threshold (a threshold in units that converts back to `half`).
    let units = format!("{:e}", f64::from(half) * 2f64.powi(-q));
    let want = stream(
        &parts[1],
        &["--threshold", &units, "--max-defect-lines", "3"],
    );
    let h = header(&got[1]);
    assert_eq!((h.threshold, h.max_defect_lines), (half, 3));
    let origin = h.origin.expect("a version 6 header");
    for k in Key::ALL {
        let changed = matches!(k, Key::Threshold | Key::DefectCap);
        let want_src = if changed {
            Source::Changed
        } else {
            Source::Default
        };
        assert_eq!(origin.sources[k.index()], want_src, "{}", k.name());
    }
    assert_eq!(header(&want).threshold, half);
    assert_eq!(got[1][1..], want[1..], "the second scan's lines");
    assert!(
        got[1].iter().filter(|l| l.starts_with("D,")).count()
            > got[0].iter().filter(|l| l.starts_with("D,")).count(),
        "the lower threshold and the defect lines show"
    );
}
