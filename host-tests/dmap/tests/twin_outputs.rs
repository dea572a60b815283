//! READY and REJECT on the chip model: the H743 release firmware,
//! unmodified, drives its output pins and the model records every change
//! (`pins` in its counters, `dmap twin --pins`). The pins agree with the
//! end lines' verdicts, which equal `dmap stream`'s: the demo part is
//! rejected at its scan's end; defect-free parts are never rejected and
//! READY stays up; each fault that loses beams drops READY, makes the
//! part's verdict a fault and rejects it, and READY comes back only with
//! the next clean scan. Needs what tests/twin.rs needs.

use crate::common;

use common::dmap_ok as dmap;
use cvm_reference::Geometry;
use dmap::npy::write_scan_u16;
use std::path::Path;
use std::process::Command;

/// The model's counters: the last line of standard error.
fn counters(stderr: &[u8]) -> serde_json::Value {
    let err = String::from_utf8_lossy(stderr);
    let last = err.lines().rfind(|l| l.starts_with('{')).unwrap_or("");
    serde_json::from_str(last).unwrap_or_else(|e| panic!("no JSON counters ({e}) in:\n{err}"))
}

/// Whether `pin` at a recorded level is asserted as a PLC input reads
/// it: Hi-Z reads low (the input's pull-down); READY and the LEDs are
/// asserted (lit) high, REJECT low (docs/firmware.md, "Fail-safe").
fn asserted(pin: &str, level: &serde_json::Value) -> bool {
    let high = matches!(
        dmap::twin::pins::Level::from_json(level),
        Some(dmap::twin::pins::Level::High)
    );
    assert!(
        dmap::twin::pins::Level::from_json(level).is_some(),
        "level {level}"
    );
    if pin == "REJECT" { !high } else { high }
}

/// The changes of `pin`'s asserted state after power-on: (µs, 1 when
/// asserted, beam). Every pin is Hi-Z at power-on (READY not ready,
/// REJECT reject, the LEDs dark); a level that reads as the one before
/// (Hi-Z, then driven low) is no change.
fn edges(c: &serde_json::Value, pin: &str) -> Vec<(f64, u64, i64)> {
    let mut now = asserted(pin, &serde_json::json!("z"));
    let mut out = Vec::new();
    for e in c["pins"]
        .as_array()
        .expect("pins in the counters")
        .iter()
        .filter(|e| e["pin"] == pin)
    {
        let a = asserted(pin, &e["level"]);
        if a != now {
            out.push((
                e["us"].as_f64().unwrap(),
                a as u64,
                e["beam"].as_i64().unwrap(),
            ));
            now = a;
        }
    }
    out
}

/// The same from a `--pins` CSV: its rows where `pin`'s asserted state
/// changes, the level field replaced by 1 (asserted) or 0.
fn csv_changes(csv: &str, pin: &str) -> Vec<Vec<String>> {
    let mut now = asserted(pin, &serde_json::json!("z"));
    let mut out = Vec::new();
    for l in csv.lines().skip(1) {
        let mut f: Vec<String> = l.split(',').map(str::to_string).collect();
        if f[1] != pin {
            continue;
        }
        let level = match f[2].as_str() {
            "z" => serde_json::json!("z"),
            v => serde_json::json!(v.parse::<u64>().unwrap()),
        };
        let a = asserted(pin, &level);
        if a != now {
            f[2] = (a as u8).to_string();
            out.push(f);
            now = a;
        }
    }
    out
}

/// The verdicts of the end lines, in order.
fn verdicts(stdout: &[u8]) -> Vec<String> {
    dmap::twin::pins::verdicts(stdout)
}

const J: usize = 3;
const ROWS: usize = 3;
const COLS: usize = 9;
const BEAMS: usize = ROWS * COLS;

/// `parts` defect-free parts of ROWS x COLS beams back to back through
/// the firmware built for one part, with `faults`; returns the UART bytes
/// and the counters. Each part alone, through `dmap stream`, is good.
fn parts_on_the_twin(parts: usize, faults: &[&str], beam_us: &str) -> (Vec<u8>, serde_json::Value) {
    let dir = tempfile::tempdir().unwrap();
    let mut all = Vec::new();
    for k in 0..parts {
        let data = common::flat_samples(BEAMS, J * J, 11 + k as u64);
        let scan = dir.path().join(format!("part{k}.npy"));
        write_scan_u16(&scan, ROWS, COLS, Geometry::new(J, J).unwrap(), &data).unwrap();
        let host = dmap(&["stream", scan.to_str().unwrap(), "--scores"]);
        assert_eq!(
            verdicts(&host.stdout),
            ["good"],
            "part {k} is not defect-free"
        );
        all.extend(data);
    }
    let twin_scan = dir.path().join("parts.twin");
    common::write_twin_scan(&twin_scan, parts * ROWS, COLS, J, &all);
    let elf = dmap::twin::build_elf(&format!(
        "j1={J} j2={J} cols={COLS} rows={ROWS} scores=1 fw={}",
        cvm_core::VERSION
    ))
    .unwrap();
    let twin = Path::new(env!("CARGO_MANIFEST_DIR")).join("../twin");
    let mut cmd = Command::new("python3");
    cmd.args(["-m", "h743twin"])
        .arg(&elf)
        .arg("--scan")
        .arg(&twin_scan)
        .args(["--beam-us", beam_us, "--scans", &parts.to_string()])
        .env("PYTHONPATH", &twin);
    for f in faults {
        cmd.args(["--fault", f]);
    }
    let out = cmd.output().expect("running the chip model");
    let c = counters(&out.stderr);
    assert_eq!(c["fault"], serde_json::Value::Null, "{c}");
    (out.stdout, c)
}

/// The last level of `e` at or before beam `beam` (`start` before any edge).
fn level_after(e: &[(f64, u64, i64)], beam: i64, start: u64) -> u64 {
    e.iter().rfind(|x| x.2 <= beam).map_or(start, |x| x.1)
}

#[test]
fn five_good_parts_never_reject_and_ready_stays_up() {
    let (out, c) = parts_on_the_twin(5, &[], "200");
    assert_eq!(
        verdicts(&out),
        ["good"; 5],
        "{}",
        String::from_utf8_lossy(&out)
    );
    // READY rises once, at start-up before the first beam, and stays.
    let ready = edges(&c, "READY");
    assert_eq!(ready.len(), 1, "{ready:?}");
    assert_eq!((ready[0].1, ready[0].2), (1, -1));
    assert_eq!(edges(&c, "LD1").len(), 1);
    // REJECT reads "reject" (Hi-Z, then driven low) until the firmware's
    // start releases it, and never again; LD3 lit for that time.
    let reject: Vec<(u64, i64)> = edges(&c, "REJECT").iter().map(|e| (e.1, e.2)).collect();
    assert_eq!(reject, [(0, -1)]);
    let ld3: Vec<(u64, i64)> = edges(&c, "LD3").iter().map(|e| (e.1, e.2)).collect();
    assert_eq!(ld3, [(1, -1), (0, -1)]);
}

/// A fault in the first of three parts at beam `at`: READY drops within
/// that scan, its verdict is `verdict`, REJECT goes up at its end and
/// down when the next scan starts; READY comes back at the end of the
/// second scan, the first clean one.
fn fault_drops_ready_until_a_clean_scan(fault: &str, at: i64, verdict: &str) {
    let (out, c) = parts_on_the_twin(3, &[fault], "200");
    let kind = &fault[..fault.find('@').unwrap()];
    assert!(c["faults_injected"][kind].as_u64() >= Some(1), "{c}");
    let text = String::from_utf8_lossy(&out);
    assert_eq!(verdicts(&out), [verdict, "good", "good"], "{text}");
    let b = BEAMS as i64;
    let ready = edges(&c, "READY");
    assert_eq!(ready.len(), 3, "{fault}: {ready:?}");
    assert_eq!((ready[0].1, ready[0].2), (1, -1), "{fault}");
    assert_eq!(ready[1].1, 0, "{fault}");
    assert!(
        (at..b).contains(&ready[1].2),
        "{fault}: READY dropped after beam {}, not within the faulty scan",
        ready[1].2
    );
    assert_eq!(
        (ready[2].1, ready[2].2),
        (1, 2 * b - 1),
        "{fault}: {ready:?}"
    );
    let reject = edges(&c, "REJECT");
    // After the start's release (before the first beam).
    let after_start = |e: &[(f64, u64, i64)]| -> Vec<(u64, i64)> {
        e.iter().filter(|x| x.2 >= 0).map(|x| (x.1, x.2)).collect()
    };
    let r = after_start(&reject);
    assert_eq!(r, [(1, b - 1), (0, b)], "{fault}");
    // The pins agree with each scan's verdict at its end.
    for (k, v) in verdicts(&out).iter().enumerate() {
        let end = (k as i64 + 1) * b - 1;
        assert_eq!(level_after(&reject, end, 0) == 1, v != "good", "scan {k}");
        assert_eq!(
            level_after(&ready, end, 0) == 1,
            !v.starts_with("fault"),
            "scan {k}"
        );
    }
    // The LEDs mirror the pins edge for edge.
    let times = |e: Vec<(f64, u64, i64)>| e.iter().map(|x| (x.1, x.2)).collect::<Vec<_>>();
    assert_eq!(times(edges(&c, "LD1")), times(ready), "{fault}");
    assert_eq!(after_start(&edges(&c, "LD3")), r, "{fault}");
}

#[test]
fn missing_drdy_drops_ready_and_rejects_the_part() {
    fault_drops_ready_until_a_clean_scan("drdy-miss@13", 13, "fault-missing");
}

#[test]
fn spi_overrun_drops_ready_and_rejects_the_part() {
    fault_drops_ready_until_a_clean_scan("overrun@13", 13, "fault-missing");
}

#[test]
fn stuck_detector_bus_drops_ready_and_rejects_the_part() {
    // The detector's SPI DMA requests are never served: the read runs out
    // its deadline.
    fault_drops_ready_until_a_clean_scan("dma-stall@13", 13, "fault-missing");
}

/// A reset in the middle of a scan (the watchdog after a wedge): READY
/// falls with the reset, the restarted firmware rejects the part it never
/// judged and keeps READY down until a scan ends without a fault.
#[test]
fn reset_mid_scan_rejects_the_part_and_ready_waits_for_a_clean_scan() {
    // Beams 8 ms apart: the watchdog (1 s) resets the firmware about 125
    // beams after the wedge, and 12 parts leave it clean scans after.
    let parts = 12;
    let (out, c) = parts_on_the_twin(parts, &["wedge@13"], "8000");
    let resets = c["resets"].as_array().unwrap();
    assert_eq!(resets.len(), 1, "{c}");
    let reset_us = resets[0]["ms"].as_f64().unwrap() * 1e3;
    let text = String::from_utf8_lossy(&out);
    let headers: Vec<&str> = text.lines().filter(|l| l.starts_with("H,")).collect();
    assert!(
        headers.len() >= 2 && headers[1].contains(",rst=wdg,"),
        "{text}"
    );
    let ready = edges(&c, "READY");
    // After the start's release of REJECT (before the first beam).
    let reject: Vec<(f64, u64, i64)> = edges(&c, "REJECT")
        .into_iter()
        .filter(|e| e.2 >= 0)
        .collect();
    // Up at power-on, down with the reset, up again once.
    let levels: Vec<u64> = ready.iter().map(|e| e.1).collect();
    assert_eq!(levels, [1, 0, 1], "{ready:?}");
    assert!((ready[1].0 - reset_us).abs() < 1.0, "{ready:?} {reset_us}");
    // REJECT reads "reject" from the reset on (Hi-Z, then driven low at
    // the restart), before any scan ends after it.
    assert_eq!(reject[0].1, 1, "{reject:?}");
    assert!(
        (reject[0].0 - reset_us).abs() < 1.0 && reject[0].2 > 13,
        "{reject:?}"
    );
    // The part in progress at the reset has no end line; READY comes back
    // with the first end line after it that is not a fault, and only then.
    let v = verdicts(&out);
    let first_clean = v.iter().position(|v| !v.starts_with("fault"));
    assert!(
        first_clean.is_some(),
        "no clean scan after the reset: {v:?}"
    );
    // REJECT in part mode: up after every rejected part, down at the next
    // scan's start; its rises after the restart are the rejected parts.
    let rises_after = reject.iter().skip(1).filter(|e| e.1 == 1).count();
    let rejected_before_clean = v[..first_clean.unwrap()].len();
    assert!(rises_after >= rejected_before_clean, "{reject:?} {v:?}");
    assert!(ready[2].0 > reject[0].0, "{ready:?}");
}

fn s(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

/// The demo at the 9x9 SPI-limit beam rate: `dmap twin --pins` writes the
/// timeline; REJECT goes up once, after the scan's last beam, as the end
/// line says `obj`; READY stays up. The output is `dmap stream`'s byte for
/// byte, and the QEMU board's end line carries the same verdict.
#[test]
fn demo_part_is_rejected_at_the_scans_end() {
    let dir = tempfile::tempdir().unwrap();
    let scan = common::demo_scan(dir.path());
    let host = dmap(&[
        "stream",
        &s(&scan),
        "--from-flash",
        "--scores",
        "--threshold",
        "0.5",
    ]);
    let pins = dir.path().join("pins.csv");
    let twin = dmap(&[
        "twin",
        &s(&scan),
        "--scores",
        "--threshold",
        "0.5",
        "--beam-us",
        "53",
        "--pins",
        &s(&pins),
    ]);
    assert!(
        twin.stdout == host.stdout,
        "the twin's lines differ from dmap stream's"
    );
    assert_eq!(verdicts(&host.stdout), ["obj"]);
    let text = String::from_utf8_lossy(&host.stdout);
    assert_eq!(text.lines().filter(|l| l.starts_with("O,")).count(), 2);
    let csv = std::fs::read_to_string(&pins).unwrap();
    // Changes of the asserted states (1: asserted), once the start has
    // set the pins (beam -1: before the first beam).
    let of = |pin: &str| -> Vec<Vec<String>> {
        csv_changes(&csv, pin)
            .into_iter()
            .filter(|r| r[3] != "-1")
            .collect()
    };
    let ready = csv_changes(&csv, "READY");
    assert_eq!(ready.len(), 1, "{csv}");
    assert_eq!((ready[0][2].as_str(), ready[0][3].as_str()), ("1", "-1"));
    let reject = of("REJECT");
    assert_eq!(reject.len(), 1, "{csv}");
    // After the last beam (39 x 39), in the last row.
    assert_eq!(
        (
            reject[0][2].as_str(),
            reject[0][3].as_str(),
            reject[0][4].as_str()
        ),
        ("1", "1520", "38")
    );
    // The summary on standard error.
    let err = String::from_utf8_lossy(&twin.stderr);
    assert!(err.contains("scan 1: verdict obj"), "{err}");
    assert!(err.contains("pin REJECT low (reject) at"), "{err}");
    let us: f64 = reject[0][0].parse().unwrap();
    // The last beam's DRDY: 20 ms after reset, then 1 520 periods of 53 µs.
    let latency = us - (20_000.0 + 1520.0 * 53.0);
    // From the end of its frame's read: within one beam period.
    assert_eq!(reject[0][6], "1520", "{csv}");
    let after_read = us - reject[0][5].parse::<f64>().unwrap();
    println!(
        "demo: REJECT {latency:.1} us after the last beam's DRDY, {after_read:.1} us after its read"
    );
    assert!(after_read > 0.0 && after_read < 53.0, "{after_read}");
    let qemu = dmap(&["emulate", &s(&scan), "--scores", "--threshold", "0.5"]);
    assert_eq!(verdicts(&qemu.stdout), ["obj"]);
}

/// The demo in row mode (500 µs pulses, 2 rows' delay): one pulse per
/// object, each 500 µs wide (±1 µs, one TIM14 tick), starting after the
/// beam that puts out the row `row_delay` rows after the one closing the
/// object (a row goes out when the next one is complete), or at the scan's
/// end when the delay runs past it.
#[test]
fn demo_in_row_mode_pulses_once_per_object() {
    let dir = tempfile::tempdir().unwrap();
    let scan = common::demo_scan(dir.path());
    let pins = dir.path().join("pins.csv");
    let (period, delay, cols, rows) = (53.0, 2, 39, 39);
    let twin = dmap(&[
        "twin",
        &s(&scan),
        "--scores",
        "--threshold",
        "0.5",
        "--beam-us",
        "53",
        "--set",
        "pulse=500",
        "--set",
        "mode=row",
        "--set",
        "delay=2",
        "--pins",
        &s(&pins),
    ]);
    let text = String::from_utf8_lossy(&twin.stdout);
    assert_eq!(verdicts(&twin.stdout), ["obj"]);
    let last_rows: Vec<i64> = text
        .lines()
        .filter(|l| l.starts_with("O,"))
        .map(|l| l.split(',').nth(3).unwrap().parse().unwrap())
        .collect();
    assert_eq!(last_rows.len(), 2, "{text}");
    let csv = std::fs::read_to_string(&pins).unwrap();
    // REJECT's asserted state (1: asserted, its pin low), after the start.
    let reject: Vec<(f64, u8, i64, f64, i64)> = csv_changes(&csv, "REJECT")
        .into_iter()
        .filter(|f| f[3] != "-1")
        .map(|f| {
            (
                f[0].parse().unwrap(),
                f[2].parse().unwrap(),
                f[3].parse().unwrap(),
                f[5].parse().unwrap(),
                f[6].parse().unwrap(),
            )
        })
        .collect();
    assert_eq!(reject.len(), 4, "{csv}");
    for (k, row1) in last_rows.iter().enumerate() {
        let (up, down) = (reject[2 * k], reject[2 * k + 1]);
        assert_eq!((up.1, down.1), (1, 0), "{csv}");
        let width = down.0 - up.0;
        assert!((width - 500.0).abs() <= 1.0, "pulse {k}: {width} us");
        // Closed by row row1 + 1, which goes out with the last beam of the
        // row after it; due `delay` rows later.
        let due_rows = row1 + 2 + delay;
        let due_beam = if due_rows < rows {
            (due_rows + 1) * cols - 1
        } else {
            rows * cols - 1
        };
        assert!(
            (due_beam..=due_beam + 3).contains(&up.2),
            "pulse {k} after beam {}, due after beam {due_beam}",
            up.2
        );
        let latency = up.0 - (20_000.0 + due_beam as f64 * period);
        // From the end of the due beam's read: within one beam period.
        assert_eq!(up.4, due_beam, "pulse {k}: {csv}");
        let after_read = up.0 - up.3;
        println!(
            "demo, row mode: pulse {k} {latency:.1} us after beam {due_beam}'s DRDY, \
             {after_read:.1} us after its read"
        );
        assert!(
            after_read > 0.0 && after_read < period,
            "pulse {k}: {after_read}"
        );
    }
}

/// At 15x15 and its SPI-limit beam rate (146 µs), the scan of the
/// request-flood test (the same build): a part with one object is
/// rejected, REJECT going up within one beam period of the end of the
/// last frame's read.
#[test]
fn a_15x15_part_is_rejected_within_a_beam_period_of_its_last_read() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    common::blob_scan(&scan, 50, 40, 15, 11);
    let pins = dir.path().join("pins.csv");
    let twin = dmap(&[
        "twin",
        &s(&scan),
        "--threshold",
        "0.05",
        "--beam-us",
        "146",
        "--pins",
        &s(&pins),
    ]);
    assert_eq!(verdicts(&twin.stdout), ["obj"]);
    let csv = std::fs::read_to_string(&pins).unwrap();
    let up: Vec<Vec<String>> = csv_changes(&csv, "REJECT")
        .into_iter()
        .filter(|f| f[2] == "1" && f[3] != "-1")
        .collect();
    assert_eq!(up.len(), 1, "{csv}");
    assert_eq!(up[0][6], "1999", "{csv}");
    let after_read = up[0][0].parse::<f64>().unwrap() - up[0][5].parse::<f64>().unwrap();
    println!("15x15: REJECT {after_read:.1} us after the last frame's read");
    assert!(after_read > 0.0 && after_read < 146.0, "{after_read}");
}
