//! `dmap sensor` against a fake sensor on a pseudo-terminal: the board's
//! own command logic (`cvm_fw_app::control::Control`) answers on the
//! master side, with result lines written between the replies, the way
//! the H743 interleaves them on its UART. The binary opens the slave side
//! as it opens a real serial port. Expected values come from the settings
//! the fake board is built with here.

use cvm_core::calibration::rule::Rule;
use cvm_core::command::{Calibration, Capacity, Event, LineReader};
use cvm_core::protocol::{LineSink, Priority, crc16};
use cvm_core::settings::{KEYS, Settings, Store};
use cvm_fw_app::control::{Control, Effect};
use rustix::fd::OwnedFd;
use std::process::{Command, Output};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

const CAP: Capacity = Capacity {
    max_cols: 300,
    max_rows: 1000,
    max_dcap: 16,
    max_pulse_us: 65536,
};
const THR: u32 = 4_194_304;
const PTHR: u32 = 3277;
/// What the fake board's calibration finds.
const CAL: Calibration = Calibration {
    scans: 3,
    positions: 2700,
    threshold: 5_123_456,
    power_threshold: 4321,
    median: 1_000_000,
    mad: 123_456,
    power_median: 800,
    power_mad: 99,
    spread_threshold: 9876,
    spread_median: 1500,
    spread_mad: 321,
    rate_ppm: 1000,
};

fn compiled() -> Settings {
    Settings::new(300, 200, THR, PTHR)
}

#[derive(Clone, Copy, PartialEq)]
enum Mode {
    /// Answers every request.
    Answer,
    /// Reads requests and answers none.
    Silent,
    /// Sends each reply line first with a bad checksum, then as the reply
    /// to another id, then as it is.
    Damage,
    /// Answers every request, but a calibration's result is for 1 scan
    /// at the default rate, whatever was asked.
    WrongCalibration,
}

struct Lines(Vec<Vec<u8>>);

impl LineSink for Lines {
    fn line(&mut self, line: &[u8], _: Priority) {
        self.0.push(line.to_vec());
    }
}

/// A line with its CRC: `body*XXXX\n`.
fn framed(body: &str) -> Vec<u8> {
    format!("{body}*{:04X}\n", crc16(body.as_bytes())).into_bytes()
}

/// A fake board on the master side of a pseudo-terminal.
struct Fake {
    path: String,
    received: Arc<Mutex<Vec<u8>>>,
    /// Result lines written so far.
    written: Arc<Mutex<Vec<Vec<u8>>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Fake {
    fn start(mode: Mode) -> Fake {
        use rustix::pty::{OpenptFlags, grantpt, openpt, ptsname, unlockpt};
        let master = openpt(OpenptFlags::RDWR | OpenptFlags::NOCTTY).unwrap();
        grantpt(&master).unwrap();
        unlockpt(&master).unwrap();
        let path = ptsname(&master, Vec::new()).unwrap().into_string().unwrap();
        // Raw from the start (no echo of what the board writes), and held
        // open so that the master never sees the slave hang up between runs.
        let slave = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&path)
            .unwrap();
        let mut t = rustix::termios::tcgetattr(&slave).unwrap();
        t.make_raw();
        rustix::termios::tcsetattr(&slave, rustix::termios::OptionalActions::Now, &t).unwrap();
        rustix::fs::fcntl_setfl(&master, rustix::fs::OFlags::NONBLOCK).unwrap();
        let received = Arc::new(Mutex::new(Vec::new()));
        let written = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (r, w, s) = (received.clone(), written.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            board(master, mode, r, w, s);
            drop(slave);
        });
        Fake {
            path,
            received,
            written,
            stop,
            thread: Some(thread),
        }
    }

    /// Runs `dmap sensor --port <pty> ARGS`.
    fn dmap(&self, args: &[&str]) -> Output {
        Command::new(env!("CARGO_BIN_EXE_dmap"))
            .args(["sensor", "--port", &self.path])
            .args(args)
            .output()
            .unwrap()
    }

    /// Every request line the board received so far.
    fn requests(&self) -> Vec<String> {
        // Whatever the client wrote before it exited is in the pty already.
        std::thread::sleep(Duration::from_millis(30));
        let r = self.received.lock().unwrap();
        String::from_utf8_lossy(&r)
            .lines()
            .map(str::to_string)
            .collect()
    }
}

impl Drop for Fake {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Writes `bytes` to the master; what does not fit (nobody reading) is
/// lost, as on a UART with nothing attached.
fn put(master: &OwnedFd, mut bytes: &[u8]) {
    let until = Instant::now() + Duration::from_millis(20);
    while !bytes.is_empty() && Instant::now() < until {
        match rustix::io::write(master, bytes) {
            Ok(n) => bytes = &bytes[n..],
            Err(_) => std::thread::sleep(Duration::from_millis(1)),
        }
    }
}

/// A reply line as another id's: `A,<id + 1000>,...` with its own CRC.
fn other_id(line: &[u8]) -> Vec<u8> {
    let text = String::from_utf8_lossy(line);
    let body = text.trim_end().rsplit_once('*').unwrap().0;
    let mut f = body.splitn(3, ',');
    let (a, id, rest) = (f.next().unwrap(), f.next().unwrap(), f.next().unwrap());
    let id: u32 = id.parse().unwrap();
    framed(&format!("{a},{},{rest}", id + 1000))
}

/// The fake board's loop: requests in, replies out with a result line
/// before each, a result line every 5 ms besides, a calibration finishing
/// 40 ms per scan after it was asked for, `save` kept for the next
/// `reset`, which restarts the control with it.
fn board(
    master: OwnedFd,
    mode: Mode,
    received: Arc<Mutex<Vec<u8>>>,
    written: Arc<Mutex<Vec<Vec<u8>>>>,
    stop: Arc<AtomicBool>,
) {
    let start = |record: Option<[u32; KEYS]>| {
        let store = if record.is_some() {
            Store::Loaded
        } else {
            Store::Empty
        };
        let boot = cvm_core::Boot {
            store,
            ..cvm_core::Boot::power_on("fw-fake")
        };
        Control::new(compiled(), boot, CAP, (15, 15), record)
    };
    let mut flash: Option<[u32; KEYS]> = None;
    let mut control = start(flash);
    let mut reader = LineReader::new();
    let mut calibration_due: Option<Instant> = None;
    let mut armed_scans = 0u16;
    let mut next_result = Instant::now();
    let mut rows = 0u32;
    let mut result_line = |master: &OwnedFd| {
        rows += 1;
        let line = framed(&format!("R,{rows},0,0"));
        put(master, &line);
        written.lock().unwrap().push(line);
    };
    let mut buf = [0u8; 512];
    while !stop.load(Ordering::Relaxed) {
        let mut out = Lines(Vec::new());
        let n = rustix::io::read(&master, &mut buf).unwrap_or(0);
        received.lock().unwrap().extend_from_slice(&buf[..n]);
        for &b in &buf[..n] {
            let Some(Event::Line(line)) = reader.push(b) else {
                continue;
            };
            if mode == Mode::Silent {
                continue;
            }
            match control.line(line, &mut out) {
                Effect::None => {}
                Effect::Save { id, values } => {
                    flash = Some(values);
                    control.saved(id, true, &mut out);
                }
                Effect::Reset => {
                    // The reply goes out before the restart.
                    for l in out.0.drain(..) {
                        put(&master, &l);
                    }
                    control = start(flash);
                }
            }
            if let Some(scans) = control.calibration_to_arm() {
                armed_scans = scans;
                calibration_due =
                    Some(Instant::now() + Duration::from_millis(40) * u32::from(scans));
            }
        }
        if calibration_due.is_some_and(|t| Instant::now() >= t) {
            calibration_due = None;
            // The request's target, as the board's rule would use it.
            let rate_ppm = match control.calibration_rule() {
                Rule::Tail { rate_ppm, .. } => rate_ppm,
                Rule::Spread { .. } => 0,
            };
            let c = match mode {
                Mode::WrongCalibration => Calibration {
                    scans: 1,
                    rate_ppm: 1000,
                    ..CAL
                },
                _ => Calibration {
                    scans: armed_scans,
                    rate_ppm,
                    ..CAL
                },
            };
            control.calibrated(&c, &mut out);
        }
        for l in &out.0 {
            result_line(&master);
            if mode == Mode::Damage {
                let mut bad = l.clone();
                bad[2] ^= 0x01; // a flipped bit in the id: the CRC no longer matches
                put(&master, &bad);
                put(&master, &other_id(l));
            }
            put(&master, l);
        }
        if Instant::now() >= next_result {
            next_result += Duration::from_millis(5);
            result_line(&master);
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "dmap failed ({}):\n{}",
        out.status,
        text(&out.stderr)
    );
    text(&out.stdout)
}

/// The `status` table's rows: key -> (value, source).
fn table(stdout: &str) -> Vec<(String, String, String)> {
    let mut rows = Vec::new();
    let mut inside = false;
    for l in stdout.lines() {
        if l.starts_with("key ") {
            inside = true;
            continue;
        }
        if inside {
            let mut f = l.split_whitespace();
            let key = f.next().unwrap().to_string();
            let value = f.next().unwrap().to_string();
            rows.push((key, value, f.collect::<Vec<_>>().join(" ")));
        }
    }
    rows
}

fn row(t: &[(String, String, String)], key: &str) -> (String, String) {
    let r = t.iter().find(|r| r.0 == key).unwrap();
    (r.1.clone(), r.2.clone())
}

#[test]
fn every_action_round_trips_and_sources_follow() {
    let fake = Fake::start(Mode::Answer);
    let out = fake.dmap(&["status"]);
    let s = ok(&out);
    assert!(
        s.contains(
            "firmware fw-fake, command protocol 7, detector 15x15, capacity 300 columns x 1000 rows"
        ),
        "{s}"
    );
    assert!(s.contains("settings record: none in flash"), "{s}");
    assert!(s.contains("last scan: none since start-up"), "{s}");
    let t = table(&s);
    let names: Vec<&str> = t.iter().map(|r| r.0.as_str()).collect();
    assert_eq!(
        names,
        [
            "cols", "rows", "thr", "pthr", "sthr", "scores", "dcap", "area", "peak", "miss",
            "misp", "mode", "pulse", "delay", "ready", "reject"
        ]
    );
    assert!(t.iter().all(|r| r.2 == "compiled default"), "{s}");
    assert_eq!(row(&t, "cols").0, "300");
    assert_eq!(row(&t, "rows").0, "200");
    assert_eq!(row(&t, "thr").0, THR.to_string());
    assert_eq!(row(&t, "pthr").0, PTHR.to_string());
    // The spread channel compiled off.
    assert_eq!(row(&t, "sthr").0, u32::MAX.to_string());
    assert_eq!(row(&t, "scores").0, "0");
    assert_eq!(row(&t, "mode").0, "part");

    let s = ok(&fake.dmap(&["set", "thr=100", "scores=1", "area=3"]));
    assert_eq!(
        s,
        "thr = 100 (changed, not saved)\nscores = 1 (changed, not saved)\narea = 3 (changed, not saved)\n"
    );
    // The outputs' levels are the fail-safe ones only: refused before
    // anything is sent.
    let out = fake.dmap(&["set", "ready=low"]);
    assert!(!out.status.success());
    // The spread threshold: any 32-bit value, like pthr; a sign or a word
    // is refused before anything is sent.
    let s = ok(&fake.dmap(&["set", "sthr=6554"]));
    assert_eq!(s, "sthr = 6554 (changed, not saved)\n");
    assert_eq!(
        ok(&fake.dmap(&["get", "sthr"])),
        "sthr = 6554 (changed, not saved)\n"
    );
    let out = fake.dmap(&["set", "sthr=off"]);
    assert!(!out.status.success());
    let s = ok(&fake.dmap(&["get", "thr"]));
    assert_eq!(s, "thr = 100 (changed, not saved)\n");
    assert_eq!(ok(&fake.dmap(&["save"])), "settings saved to flash\n");
    assert_eq!(ok(&fake.dmap(&["reset"])), "the sensor restarts\n");
    let s = ok(&fake.dmap(&["status"]));
    assert!(s.contains("settings record: read from flash"), "{s}");
    let t = table(&s);
    assert!(t.iter().all(|r| r.2 == "flash"), "{s}");
    assert_eq!(row(&t, "thr").0, "100");
    assert_eq!(row(&t, "area").0, "3");
    assert_eq!(
        ok(&fake.dmap(&["defaults"])),
        "compiled values in effect from the next scan (not saved)\n"
    );
    let t = table(&ok(&fake.dmap(&["status"])));
    // Compiled values again, but flash still holds the record: `c`.
    assert_eq!(
        row(&t, "thr"),
        (THR.to_string(), "changed, not saved".into())
    );
    assert_eq!(row(&t, "area"), ("0".into(), "changed, not saved".into()));
}

#[test]
fn requests_carry_consecutive_ids_and_json_reports_them() {
    let fake = Fake::start(Mode::Answer);
    let out = fake.dmap(&["--id", "41", "--json", "set", "thr=7", "mode=part"]);
    let v: serde_json::Value = serde_json::from_str(&ok(&out)).unwrap();
    assert_eq!(v["action"], "set");
    assert_eq!(v["error"], serde_json::Value::Null);
    // The board wrote a result line before each reply: both were seen, not printed.
    assert!(v["result_lines"].as_u64().unwrap() >= 2, "{v}");
    assert_eq!(v["skipped_replies"], 0);
    let r = &v["replies"];
    assert_eq!(r[0]["id"], 41);
    assert_eq!((&r[0]["key"], &r[0]["value"]), (&"thr".into(), &7.into()));
    assert_eq!(r[0]["source"], "changed");
    assert_eq!((&r[1]["id"], &r[1]["value"]), (&42.into(), &"part".into()));
    let req = fake.requests();
    assert_eq!(req.len(), 2, "{req:?}");
    assert!(req[0].starts_with("C,41,set,thr=7*"), "{req:?}");
    assert!(req[1].starts_with("C,42,set,mode=part*"), "{req:?}");

    let v: serde_json::Value =
        serde_json::from_str(&ok(&fake.dmap(&["--json", "status"]))).unwrap();
    let st = &v["replies"][0];
    assert_eq!(st["reply"], "status");
    assert_eq!(st["capacity"]["cols"], 300);
    assert_eq!(st["settings"]["thr"]["value"], 7);
    assert_eq!(st["settings"]["thr"]["source"], "changed");
    assert_eq!(st["settings"]["pthr"]["value"], PTHR);
    assert_eq!(st["settings"]["pthr"]["source"], "default");
    assert_eq!(st["store"], "none");
}

#[test]
fn bad_keys_and_values_are_refused_before_anything_is_sent() {
    let fake = Fake::start(Mode::Answer);
    for (args, why) in [
        (
            &["set", "thr=1", "thr=abc"][..],
            "`thr=abc`: value of the wrong type",
        ),
        (
            &["set", "thr=4294967296"][..],
            "value out of range 0..=4294967295",
        ),
        (&["set", "mode=sideways"][..], "mode takes part or row"),
        (&["get", "threshold"][..], "unknown setting `threshold`"),
        (&["calibrate", "--scans", "0"][..], "--scans"),
        (
            &["calibrate", "--scans", "1", "--rate", "0"][..],
            "--rate must be a multiple of 0.000001 in (0, 1] false positions per part, got 0",
        ),
        (&["calibrate", "--scans", "1", "--rate", "2"][..], "got 2"),
        (
            &["calibrate", "--scans", "1", "--rate", "0.0000005"][..],
            // Numbers in messages as dmap writes them (`fmt_num`).
            "got 5e-7",
        ),
        (
            &["calibrate", "--scans", "1", "--rate", "often"][..],
            "--rate",
        ),
    ] {
        let out = fake.dmap(args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = text(&out.stderr);
        assert!(
            err.starts_with("dmap: error: ") && err.contains(why),
            "{args:?}: {err}"
        );
        assert_eq!(err.lines().count(), 1, "{err}");
    }
    let err = text(&fake.dmap(&["get", "x"]).stderr);
    assert!(
        err.contains("cols, rows, thr, pthr, sthr, scores, dcap"),
        "{err}"
    );
    assert_eq!(fake.requests(), Vec::<String>::new());
}

#[test]
fn a_refusal_stops_the_run_with_its_reason() {
    let fake = Fake::start(Mode::Answer);
    // The board's capacity is 300 columns: the client's check lets 400 through.
    let out = fake.dmap(&["set", "thr=9", "cols=400", "scores=1"]);
    assert_eq!(out.status.code(), Some(3));
    assert_eq!(
        text(&out.stderr),
        "dmap: error: set cols=400 refused: value out of range 1..=300\n"
    );
    assert_eq!(text(&out.stdout), "thr = 9 (changed, not saved)\n");
    // scores=1 was never sent.
    assert_eq!(fake.requests().len(), 2);
    // Row mode without a pulse width conflicts.
    let out = fake.dmap(&["set", "mode=row"]);
    assert_eq!(out.status.code(), Some(3));
    assert!(text(&out.stderr).contains("set mode=row refused: conflicts with another setting"));
}

#[test]
fn a_silent_port_times_out() {
    let fake = Fake::start(Mode::Silent);
    let out = fake.dmap(&["--timeout", "0.3", "get", "thr"]);
    assert_eq!(out.status.code(), Some(4));
    assert_eq!(
        text(&out.stderr),
        format!(
            "dmap: error: get thr: no reply within 0.3 s (is the sensor connected to {}, at 921600 baud?)\n",
            fake.path
        )
    );
    assert_eq!(fake.requests().len(), 1);
}

#[test]
fn damaged_and_foreign_replies_are_reported_and_skipped() {
    let fake = Fake::start(Mode::Damage);
    let out = fake.dmap(&["--id", "5", "get", "pthr"]);
    assert_eq!(ok(&out), format!("pthr = {PTHR} (compiled default)\n"));
    let err = text(&out.stderr);
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 2, "{err}");
    assert!(
        lines[0].starts_with("dmap: warning: skipped a damaged reply line (checksum mismatch"),
        "{err}"
    );
    assert!(
        lines[1].starts_with(
            "dmap: warning: skipped a reply to request 1005 (waiting for 5): A,1005,ok,pthr="
        ),
        "{err}"
    );
    let v: serde_json::Value =
        serde_json::from_str(&ok(&fake.dmap(&["--json", "get", "pthr"]))).unwrap();
    assert_eq!(v["skipped_replies"], 2);
}

#[test]
fn calibrate_waits_for_the_result() {
    let fake = Fake::start(Mode::Answer);
    let dir = tempfile::tempdir().unwrap();
    let pass = dir.path().join("results.txt");
    let out = fake.dmap(&[
        "--pass-through",
        pass.to_str().unwrap(),
        "calibrate",
        "--scans",
        "3",
    ]);
    let s = ok(&out);
    assert_eq!(
        s,
        "calibrated on 3 scans (2700 positions with data), for 0.001 false positions per part and channel\n\
         thr  =    5123456  magnitudes: median 1000000, MAD 123456\n\
         pthr =       4321  power magnitudes: median 800, MAD 99\n\
         sthr =       9876  spread magnitudes: median 1500, MAD 321\n\
         all three in effect from the next scan (changed, not saved: save keeps them)\n"
    );
    assert!(
        text(&out.stderr).contains("the sensor calibrates on its next 3 scans"),
        "{}",
        text(&out.stderr)
    );
    // The 120 ms of the three scans brought result lines: each one passed
    // through as the board wrote it.
    let passed = std::fs::read(&pass).unwrap();
    let written = fake.written.lock().unwrap().concat();
    assert!(passed.len() > 5 * 10, "{}", text(&passed));
    let at = written
        .windows(passed.len())
        .position(|w| w == passed.as_slice());
    assert!(at.is_some(), "passed-through lines are not the board's");
    let t = table(&ok(&fake.dmap(&["status"])));
    assert_eq!(
        row(&t, "thr"),
        ("5123456".into(), "changed, not saved".into())
    );
    assert_eq!(
        row(&t, "pthr"),
        ("4321".into(), "changed, not saved".into())
    );
    assert_eq!(
        row(&t, "sthr"),
        ("9876".into(), "changed, not saved".into())
    );

    // A target of one in 10 000 parts reaches the board and comes back.
    let s = ok(&fake.dmap(&["calibrate", "--scans", "2", "--rate", "0.0001"]));
    assert!(
        s.starts_with(
            "calibrated on 2 scans (2700 positions with data), for 0.0001 false positions per part and channel\n"
        ),
        "{s}"
    );
    let v: serde_json::Value = serde_json::from_str(&ok(&fake.dmap(&[
        "--json",
        "calibrate",
        "--scans",
        "1",
        "--rate",
        "0.5",
    ])))
    .unwrap();
    assert_eq!(v["replies"][0]["rate_ppm"], 500_000, "{v}");

    // A result that takes longer than the scans may: the calibrate timeout.
    let out = fake.dmap(&["calibrate", "--scans", "3", "--scan-timeout", "0.01"]);
    assert_eq!(out.status.code(), Some(4));
    assert!(
        text(&out.stderr).contains("calibrate 3: accepted, but no result within 0.03 s"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn a_port_that_cannot_be_opened_is_a_link_error() {
    let out = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(["sensor", "--port", "/nonexistent/tty", "status"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(5));
    let err = text(&out.stderr);
    assert!(
        err.starts_with("dmap: error: cannot open serial port /nonexistent/tty at 921600 baud"),
        "{err}"
    );
}

/// Issue 47, item 11: a calibration result that is not for the scans and
/// rate asked for is an error, not the result.
#[test]
fn a_calibration_result_for_another_request_is_an_error() {
    let fake = Fake::start(Mode::WrongCalibration);
    let out = fake.dmap(&["calibrate", "--scans", "2", "--rate", "0.0001"]);
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("the sensor's result is for 1 scans at 0.001 false positions per part, not the 2 at 0.0001 asked for"),
        "{err}"
    );
}

/// Issue 47, item 11: `--baud 0` is a usage error; nothing is sent.
#[test]
fn baud_zero_is_refused_before_anything_is_sent() {
    let fake = Fake::start(Mode::Answer);
    let out = fake.dmap(&["--baud", "0", "status"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("--baud"),
        "{}",
        text(&out.stderr)
    );
    assert!(fake.requests().is_empty());
}

/// Issue 47, item 3: the --pass-through file is begun only once the port
/// is open (a port that fails leaves it whole) ...
#[test]
fn pass_through_is_not_touched_when_the_port_fails() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("old.log");
    std::fs::write(&log, b"yesterday's lines\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(["sensor", "--port", "/nonexistent/tty", "--pass-through"])
        .arg(&log)
        .arg("status")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(5), "{}", text(&out.stderr));
    assert_eq!(std::fs::read(&log).unwrap(), b"yesterday's lines\n");
    // ... and is never the port itself.
    let out = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(["sensor", "--port"])
        .arg(&log)
        .arg("--pass-through")
        .arg(&log)
        .arg("status")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert_eq!(std::fs::read(&log).unwrap(), b"yesterday's lines\n");
}

/// ... and on SIGINT, SIGTERM or SIGHUP the lines received until then
/// reach it, and `dmap` exits 128 + the signal.
#[test]
fn pass_through_keeps_the_lines_received_before_a_signal() {
    let fake = Fake::start(Mode::Silent);
    let dir = tempfile::tempdir().unwrap();
    for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
        let log = dir.path().join(format!("{sig}.log"));
        let child = Command::new(env!("CARGO_BIN_EXE_dmap"))
            .args([
                "sensor",
                "--port",
                &fake.path,
                "--timeout",
                "30",
                "--pass-through",
            ])
            .arg(&log)
            .arg("status")
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // Result lines come every 5 ms.
        std::thread::sleep(Duration::from_millis(400));
        // SAFETY: a signal to our own child.
        unsafe { libc::kill(child.id() as i32, sig) };
        let out = child.wait_with_output().unwrap();
        assert_eq!(
            out.status.code(),
            Some(128 + sig),
            "signal {sig}: {}",
            text(&out.stderr)
        );
        let passed = std::fs::read(&log).unwrap_or_default();
        assert!(
            passed.len() > 5 * 10,
            "signal {sig}: {} bytes passed through",
            passed.len()
        );
        let written = fake.written.lock().unwrap().concat();
        assert!(
            written
                .windows(passed.len())
                .any(|w| w == passed.as_slice()),
            "signal {sig}: the lines passed through are not the board's"
        );
    }
}
