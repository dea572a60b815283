//! The field device on the H743 release firmware, run on the chip model
//! over several simulated parts scanned one after the other (`dmap twin
//! --parts`): settings changed on the command channel take effect when
//! the next scan starts, never in the middle of one, and the header says
//! where each value came from; `calibrate 5` on five defect-free parts
//! gives the very thresholds `dmap calibrate` gives on those scans, and
//! the next part is scored with them. Every part is checked against
//! `dmap stream` of that part alone, with the settings the part was
//! scanned with.

use crate::common;

use common::dmap_ok as dmap;
use common::{calibration_of_file, counters, framed};
use cvm_core::command::{Key, Reply, parse_reply};
use cvm_core::protocol::{self, Line};
use cvm_core::settings::Source;
use dmap::npy::{read_scan, write_scan_u16};
use dmap::twin::requests::write_requests;
use std::path::{Path, PathBuf};

/// Rows and columns of one part: a window of the prototype preset.
const ROWS: usize = 8;
const COLS: usize = 24;
/// The options of every run in this file: one firmware build serves them all.
const OPTS: [&str; 2] = ["--full-scale", "4095"];

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
    let out = dmap(
        &[
            &["stream", part.to_str().unwrap(), "--from-flash"][..],
            &OPTS,
            extra,
        ]
        .concat(),
    );
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
    // as loaded from flash at start-up (`f`), and otherwise `dmap stream`'s lines at that
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
            Source::Flash
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

#[test]
fn calibrate_5_for_a_target_rate_on_the_board_equals_dmap_calibrate_and_scores_the_next_part_with_it()
 {
    let dir = tempfile::tempdir().unwrap();
    // A part scanning while the request arrives, five defect-free
    // references (seeds the rule never saw elsewhere), then a defective
    // part.
    let mut parts = vec![part(dir.path(), 40, false)];
    parts.extend((41..46).map(|s| part(dir.path(), s, false)));
    parts.push(part(dir.path(), 1, true));
    let scan = dir.path().join("seven.npy");
    concat(&parts, &scan);
    let req = dir.path().join("req.txt");
    // For one false position in 10 000 parts, not the default 1 in 1000.
    write_requests(&req, &[(5, &framed("C,7,calibrate,5,100"))]).unwrap();
    let out = dmap(
        &[
            &["twin", scan.to_str().unwrap()][..],
            &OPTS,
            &["--parts", "7", "--requests", req.to_str().unwrap()],
        ]
        .concat(),
    );
    let (replies, got) = scans(&out.stdout);
    assert_eq!(got.len(), 7);
    let decoded: Vec<_> = replies
        .iter()
        .map(|l| {
            let l: &'static str = Box::leak(format!("{l}\n").into_boxed_str());
            parse_reply(l.as_bytes()).unwrap()
        })
        .collect();
    assert_eq!(decoded.len(), 2, "{replies:?}");
    assert_eq!(decoded[0], (Some(7), Reply::Calibrating(5)));
    let (Some(7), Reply::Calibrated(board)) = decoded[1] else {
        panic!("{:?}", decoded[1])
    };
    // `dmap calibrate` on the five references, with the same options and
    // target.
    let calibrate = |rate: &str, name: &str| {
        let cal = dir.path().join(name);
        let refs: Vec<&str> = parts[1..6].iter().map(|p| p.to_str().unwrap()).collect();
        dmap(
            &[
                &["calibrate"][..],
                &refs,
                &OPTS,
                &["--rate", rate, "-o", cal.to_str().unwrap()],
            ]
            .concat(),
        );
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&cal).unwrap()).unwrap();
        (cal, calibration_of_file(&v))
    };
    let (cal, host) = calibrate("0.0001", "cal.json");
    assert_eq!(board, host);
    assert_eq!(board.rate_ppm, 100);
    // The target took effect: a rarer false position needs higher
    // thresholds than the default's.
    let (_, default) = calibrate("0.001", "default.json");
    assert!(
        board.threshold > default.threshold
            && board.power_threshold > default.power_threshold
            && board.spread_threshold > default.spread_threshold,
        "{board:?} against {default:?}"
    );
    assert_eq!(board.positions, (5 * ROWS * COLS) as u32);
    // The spread measured with the board's channel off (compiled), and
    // its threshold set: the next part decides with it, as `dmap stream
    // --calibration` does (the lines compared below).
    assert!(
        board.spread_threshold <= cvm_core::spread::SPREAD_MAX,
        "{board:?}"
    );
    // The parts before the calibration ended: compiled thresholds.
    for (k, p) in parts[..6].iter().enumerate() {
        assert_eq!(got[k], stream(p, &[]), "part {k}");
    }
    // The defective part: the calibrated thresholds, sourced `c`, and
    // `dmap stream --calibration`'s lines.
    let want = stream(&parts[6], &["--calibration", cal.to_str().unwrap()]);
    let h = header(&got[6]);
    assert_eq!(
        (h.threshold, h.power_threshold),
        (board.threshold, board.power_threshold)
    );
    let origin = h.origin.expect("a version 6 header");
    for k in Key::ALL {
        let calibrated = matches!(
            k,
            Key::Threshold | Key::PowerThreshold | Key::SpreadThreshold
        );
        let want_src = if calibrated {
            Source::Changed
        } else {
            Source::Flash
        };
        assert_eq!(origin.sources[k.index()], want_src, "{}", k.name());
    }
    assert_eq!(got[6][1..], want[1..]);
    assert!(
        got[6].iter().any(|l| l.starts_with("O,")),
        "the defective part's object: {:?}",
        got[6]
    );
}

/// Replies as decoded: the id they echo and the reply.
type Replies = Vec<(Option<u32>, Reply<'static>)>;

/// The twin's run with these requests (`(beam, body)`, framed here) on
/// bank 2 kept in `flash`: its replies and its scans.
fn run_with_flash(
    scan: &Path,
    parts: u32,
    flash: &Path,
    requests: &[(u64, &str)],
) -> (Replies, Vec<Vec<String>>, serde_json::Value) {
    let dir = scan.parent().unwrap();
    let req = dir.join("req.txt");
    let bursts: Vec<(u64, Vec<u8>)> = requests.iter().map(|(b, r)| (*b, framed(r))).collect();
    let refs: Vec<(u64, &[u8])> = bursts.iter().map(|(b, v)| (*b, &v[..])).collect();
    write_requests(&req, &refs).unwrap();
    let parts_s = parts.to_string();
    let out = dmap(
        &[
            &["twin", scan.to_str().unwrap()][..],
            &OPTS,
            &["--parts", &parts_s, "--requests", req.to_str().unwrap()],
            &["--flash", flash.to_str().unwrap()],
        ]
        .concat(),
    );
    let (replies, got) = scans(&out.stdout);
    let decoded = replies
        .iter()
        .map(|l| {
            let l: &'static str = Box::leak(format!("{l}\n").into_boxed_str());
            parse_reply(l.as_bytes()).unwrap_or_else(|e| panic!("{e:?}: {l}"))
        })
        .collect();
    (decoded, got, counters(&out))
}

/// The value replies that follow a status reply, as (key, value, source).
fn status_values(replies: &Replies, id: u32) -> Vec<(Key, u32, Source)> {
    let at = replies
        .iter()
        .position(|r| matches!(r, (Some(i), Reply::Status(_)) if *i == id))
        .expect("a status reply");
    replies[at + 1..at + 1 + Key::ALL.len()]
        .iter()
        .map(|r| match *r {
            (Some(i), Reply::Value { key, value, source }) if i == id => (key, value, source),
            ref other => panic!("{other:?}"),
        })
        .collect()
}

#[test]
fn set_save_and_reset_keep_the_settings_and_defaults_save_brings_the_compiled_ones_back() {
    let dir = tempfile::tempdir().unwrap();
    let parts = [part(dir.path(), 31, true), part(dir.path(), 32, true)];
    let one = dir.path().join("one.npy");
    concat(&parts[..1], &one);
    let two = dir.path().join("two.npy");
    concat(&parts, &two);
    let flash = dir.path().join("bank2.bin");
    let compiled = header(&stream(&parts[0], &[]));
    let half = compiled.threshold / 2;

    // Set, save, then status: every value now in flash.
    let set = format!("C,1,set,thr={half}");
    let (r, _, c) = run_with_flash(
        &one,
        1,
        &flash,
        &[
            (2, &set),
            (3, "C,2,set,area=3"),
            (4, "C,3,save"),
            (60, "C,4,status"),
        ],
    );
    assert_eq!(c["status"], "done", "{c}");
    assert_eq!(
        r[0],
        (
            Some(1),
            Reply::Value {
                key: Key::Threshold,
                value: half,
                source: Source::Changed
            }
        )
    );
    assert_eq!(r[2], (Some(3), Reply::Saved));
    let values = status_values(&r, 4);
    assert!(values.iter().all(|v| v.2 == Source::Flash), "{values:?}");
    assert_eq!(values[Key::Threshold.index()].1, half);
    assert_eq!(values[Key::MinArea.index()].1, 3);

    // A power cycle: the saved values, from flash; then defaults, save
    // and a reset in the middle of the first scan.
    let (r, got, c) = run_with_flash(
        &two,
        2,
        &flash,
        &[
            (0, "C,5,status"),
            (10, "C,6,defaults"),
            (11, "C,7,save"),
            (40, "C,8,reset"),
        ],
    );
    let Some((_, Reply::Status(st))) = r.first() else {
        panic!("{r:?}")
    };
    assert_eq!(st.store, cvm_core::command::Store::Loaded);
    let values = status_values(&r, 5);
    assert_eq!(
        values[Key::Threshold.index()],
        (Key::Threshold, half, Source::Flash)
    );
    assert_eq!(
        values[Key::MinArea.index()],
        (Key::MinArea, 3, Source::Flash)
    );
    let h = header(&got[0]);
    assert_eq!((h.threshold, h.boots), (half, 1));
    let o = h.origin.unwrap();
    assert!(o.sources.iter().all(|&s| s == Source::Flash));
    assert_eq!(o.store, cvm_core::command::Store::Loaded);
    let tail: Vec<_> = r[1 + Key::ALL.len()..].to_vec();
    assert_eq!(
        tail,
        [
            (Some(6), Reply::Defaults),
            (Some(7), Reply::Saved),
            (Some(8), Reply::Resetting)
        ]
    );
    assert_eq!(c["resets"].as_array().map(Vec::len), Some(1), "{c}");
    // After the reset: a software reset, the second start, and the record
    // now holds the compiled values.
    let after = header(got.last().unwrap());
    assert_eq!(after.reset_cause, cvm_core::protocol::ResetCause::Software);
    assert_eq!(after.boots, 2);
    assert_eq!(after.threshold, compiled.threshold);
    let o = after.origin.unwrap();
    assert!(o.sources.iter().all(|&s| s == Source::Flash));
    assert_eq!(o.store, cvm_core::command::Store::Loaded);
}
