//! `dmap console --port` against a fake sensor on a pseudo-terminal: the
//! board's own command logic (`cvm_fw_app::control::Control`) answers the
//! page's requests on the link that carries the demo part's result lines,
//! again and again, each reply between two lines as the H743 sends them.
//! One process decodes the parts while the requests go out: the parts and
//! the replies both arrive, no line is damaged, a refusal comes back in
//! the board's words, and `save` then `reset` bring the values back with
//! source `f`.

use crate::common;

use common::console::{Console, ask};
use cvm_core::command::{Capacity, Event, LineReader};
use cvm_core::protocol::{LineSink, Priority};
use cvm_core::settings::{KEYS, Settings, Store};
use cvm_fw_app::control::{Control, Effect};
use rustix::fd::OwnedFd;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

const CAP: Capacity = Capacity {
    max_cols: 300,
    max_rows: 1000,
    max_dcap: 16,
    max_pulse_us: 65536,
};

struct Lines(Vec<Vec<u8>>);

impl LineSink for Lines {
    fn line(&mut self, line: &[u8], _: Priority) {
        self.0.push(line.to_vec());
    }
}

fn put(master: &OwnedFd, mut bytes: &[u8]) {
    let until = Instant::now() + Duration::from_millis(200);
    while !bytes.is_empty() && Instant::now() < until {
        match rustix::io::write(master, bytes) {
            Ok(n) => bytes = &bytes[n..],
            Err(_) => std::thread::sleep(Duration::from_millis(1)),
        }
    }
}

/// The fake board: the part's lines one a millisecond, round and round,
/// and the replies to the requests between them.
fn board(master: OwnedFd, part: Vec<Vec<u8>>, stop: Arc<AtomicBool>) {
    let start = |record: Option<[u32; KEYS]>| {
        let store = if record.is_some() {
            Store::Loaded
        } else {
            Store::Empty
        };
        let compiled = Settings::new(300, 200, 4_194_304, 3277);
        let boot = cvm_core::Boot {
            store,
            ..cvm_core::Boot::power_on("fw-fake")
        };
        Control::new(compiled, boot, CAP, (9, 9), record)
    };
    let mut flash = None;
    let mut control = start(flash);
    let mut reader = LineReader::new();
    let mut buf = [0u8; 512];
    for line in part.iter().cycle() {
        if stop.load(Ordering::Relaxed) {
            return;
        }
        let mut out = Lines(Vec::new());
        let n = rustix::io::read(&master, &mut buf).unwrap_or(0);
        for &b in &buf[..n] {
            let Some(Event::Line(l)) = reader.push(b) else {
                continue;
            };
            match control.line(l, &mut out) {
                Effect::None => {}
                Effect::Save { id, values } => {
                    flash = Some(values);
                    control.saved(id, true, &mut out);
                }
                Effect::Reset => {
                    for l in out.0.drain(..) {
                        put(&master, &l);
                    }
                    control = start(flash);
                }
            }
        }
        for l in &out.0 {
            put(&master, l);
        }
        put(&master, line);
        std::thread::sleep(Duration::from_millis(1));
    }
}

fn pty() -> (OwnedFd, std::fs::File, String) {
    use rustix::pty::{OpenptFlags, grantpt, openpt, ptsname, unlockpt};
    let master = openpt(OpenptFlags::RDWR | OpenptFlags::NOCTTY).unwrap();
    grantpt(&master).unwrap();
    unlockpt(&master).unwrap();
    let path = ptsname(&master, Vec::new()).unwrap().into_string().unwrap();
    let slave = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&path)
        .unwrap();
    let mut t = rustix::termios::tcgetattr(&slave).unwrap();
    t.make_raw();
    rustix::termios::tcsetattr(&slave, rustix::termios::OptionalActions::Now, &t).unwrap();
    rustix::fs::fcntl_setfl(&master, rustix::fs::OFlags::NONBLOCK).unwrap();
    (master, slave, path)
}

fn setting(s: &serde_json::Value, key: &str) -> (String, String) {
    let k = s["settings"]
        .as_array()
        .unwrap()
        .iter()
        .find(|k| k["key"] == key)
        .unwrap();
    (
        k["value"].as_str().unwrap_or("?").to_string(),
        k["source"]["letter"].as_str().unwrap_or("?").to_string(),
    )
}

#[test]
fn requests_and_results_share_the_port() {
    let dir = common::tmp_in("console-port", "");
    let scan = common::demo_scan(&dir);
    let lines = common::dmap_ok(&["stream", common::s(&scan), "--scores"]).stdout;
    let part: Vec<Vec<u8>> = lines
        .split_inclusive(|&b| b == b'\n')
        .map(<[u8]>::to_vec)
        .collect();
    let (master, slave, path) = pty();
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = Arc::clone(&stop);
    let fake = std::thread::spawn(move || {
        board(master, part, s2);
        drop(slave);
    });
    let console = Console::start(&["--port", &path, "--pitch-um", "334"]);
    // Its own status request at the first header fills the settings.
    let s = console.wait(60, "the settings", |s| setting(s, "thr").0 != "?");
    assert_eq!(setting(&s, "thr"), ("4194304".into(), "d".into()));
    let errors_before = s["counters"]["line_errors"].clone();
    let (status, v) = ask(&console.addr, "set thr=5000000", None);
    assert_eq!(status, 200, "{v}");
    assert_eq!(v["result"]["replies"][0]["reply"]["source"], "c", "{v}");
    let (status, v) = ask(&console.addr, "set cols=301", None);
    assert_eq!(status, 422, "{v}");
    assert_eq!(
        v["error"], "set cols=301 refused: value out of range 1..=300",
        "{v}"
    );
    assert_eq!(ask(&console.addr, "save", None).0, 200);
    assert_eq!(ask(&console.addr, "reset", None).0, 200);
    // After the restart, the console asks again at the next header.
    let s = console.wait(60, "thr from flash", |s| {
        setting(s, "thr") == ("5000000".into(), "f".into())
    });
    let parts = s["counters"]["parts"].as_u64().unwrap();
    let s = console.wait(60, "two more parts", |s| {
        s["counters"]["parts"].as_u64() >= Some(parts + 2)
    });
    // The link joined mid-stream: the lines before the first header are
    // outside a scan; none is damaged since the requests began.
    assert_eq!(
        s["counters"]["line_errors"], errors_before,
        "{}",
        s["health"]
    );
    assert_eq!(s["last"]["verdict"], "obj");
    // Two status requests (its line and 16 values each), set, save, reset.
    assert!(
        s["counters"]["replies"].as_u64() >= Some(2 * 17 + 3),
        "{}",
        s["counters"]
    );
    stop.store(true, Ordering::Relaxed);
    drop(console);
    fake.join().unwrap();
}
