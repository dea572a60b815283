//! The fail-safe matrix (docs/firmware.md, "Fail-safe"): the H743
//! release firmware, unmodified, on the chip model, through every event
//! that can leave a part unjudged — power-on, the reset pin, a brown-out,
//! the watchdog, a panic, a HardFault, the `reset` command, a detector
//! fault mid-scan, a power cut during a save, a `reset` sent during a
//! save — in part mode and in row mode (set at boot over the command
//! channel, as a user deploys it).
//!
//! The PLC's inputs read low when nothing drives them (docs/firmware.md,
//! "Wiring"), so a pin the model records as Hi-Z (`"z"`) reads low. From
//! each event to the end line of the first clean scan after it, READY
//! must never read "ready" (high), and must come back with that end line;
//! in part mode REJECT must read "reject" (low) from the event until the
//! next scan begins, since the part on the line at the event was never
//! judged. Needs what tests/twin.rs needs.

use crate::common;

use common::counters;
use cvm_core::command::{Key, Request, encode_request};
use cvm_reference::Geometry;
use dmap::npy::write_scan_u16;
use std::path::{Path, PathBuf};
use std::process::Command;

const J: usize = 3;
const ROWS: usize = 3;
const COLS: usize = 9;
const BEAMS: usize = ROWS * COLS;
/// The model's first beam, after reset (`--start-ms`).
const START_US: f64 = 20_000.0;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Mode {
    Part,
    Row,
}

/// What the PLC reads on one input: a driven level, or Hi-Z, which its
/// pull-down reads low.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Level {
    Low,
    High,
    Z,
}

impl Level {
    fn reads_high(self) -> bool {
        self == Level::High
    }

    /// REJECT at this level reads "pass": high, REJECT being active low.
    /// (`FAILSAFE_REJECT_ACTIVE_HIGH` judges a firmware whose REJECT was
    /// active high, with [`elf`]'s `FAILSAFE_ELF`: low and Hi-Z pass.)
    fn passes(self) -> bool {
        self.reads_high() != std::env::var_os("FAILSAFE_REJECT_ACTIVE_HIGH").is_some()
    }
}

/// The pins' timeline and the UART lines' times of one run.
struct Run {
    /// (µs, pin, level, the end of the last frame read before it in µs
    /// or -1), in time order.
    pins: Vec<(f64, String, Level, f64)>,
    /// (µs, line), every `H` and `E` line with the time of its last byte.
    lines: Vec<(f64, String)>,
    /// Times of the chip's resets, µs.
    resets: Vec<f64>,
    counters: serde_json::Value,
    stdout: String,
}

impl Run {
    fn from(stdout: &[u8], c: serde_json::Value) -> Run {
        let pins = c["pins"]
            .as_array()
            .expect("pins in the counters")
            .iter()
            .map(|e| {
                let level = match &e["level"] {
                    serde_json::Value::String(s) if s == "z" => Level::Z,
                    v if v.as_u64() == Some(1) => Level::High,
                    v if v.as_u64() == Some(0) => Level::Low,
                    v => panic!("pin level {v}"),
                };
                (
                    e["us"].as_f64().unwrap(),
                    e["pin"].as_str().unwrap().to_string(),
                    level,
                    e["read_end_us"].as_f64().unwrap(),
                )
            })
            .collect();
        let lines = c["lines"]
            .as_array()
            .expect("lines in the counters")
            .iter()
            .map(|e| {
                (
                    e["us"].as_f64().unwrap(),
                    e["line"].as_str().unwrap().to_string(),
                )
            })
            .collect();
        let resets = c["resets"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["ms"].as_f64().unwrap() * 1e3)
            .collect();
        Run {
            pins,
            lines,
            resets,
            counters: c,
            stdout: String::from_utf8_lossy(stdout).into_owned(),
        }
    }

    /// What `pin` reads at time `t` (µs): its last recorded level at or
    /// before `t`; Hi-Z before any (every pin is Hi-Z out of reset).
    fn level(&self, pin: &str, t: f64) -> Level {
        self.pins
            .iter()
            .rfind(|e| e.1 == pin && e.0 <= t)
            .map_or(Level::Z, |e| e.2)
    }

    /// The times in `(from, to)` at which `pin` reads high: its level just
    /// after `from`, and every edge to high inside.
    fn high_within(&self, pin: &str, from: f64, to: f64) -> Vec<f64> {
        let mut at: Vec<f64> = self
            .pins
            .iter()
            .filter(|e| e.1 == pin && e.0 > from && e.0 < to && e.2.reads_high())
            .map(|e| e.0)
            .collect();
        if self.level(pin, from).reads_high() {
            at.insert(0, from);
        }
        at
    }

    /// The first end line after `t` whose verdict is not a fault: its time.
    fn first_clean_end(&self, t: f64) -> Option<f64> {
        self.lines
            .iter()
            .find(|(u, l)| *u > t && l.starts_with("E,") && !l.contains("verdict=fault"))
            .map(|l| l.0)
    }

    /// The last header before `t`: the scan that `t`'s end line ends.
    fn header_before(&self, t: f64) -> Option<f64> {
        self.lines
            .iter()
            .rfind(|(u, l)| *u < t && l.starts_with("H,"))
            .map(|l| l.0)
    }
}

/// `parts` good parts back to back, in the chip model's scan format.
fn parts_file(dir: &Path, parts: usize) -> PathBuf {
    let data = common::flat_samples(parts * BEAMS, J * J, 11);
    // Each part alone is good on the host.
    let one = dir.join("part.npy");
    write_scan_u16(
        &one,
        ROWS,
        COLS,
        Geometry::new(J, J).unwrap(),
        &data[..BEAMS * J * J],
    )
    .unwrap();
    let host = common::dmap_ok(&["stream", one.to_str().unwrap(), "--scores"]);
    assert!(String::from_utf8_lossy(&host.stdout).contains("verdict=good"));
    let path = dir.join("parts.twin");
    common::write_twin_scan(&path, parts * ROWS, COLS, J, &data);
    path
}

/// The release firmware for one part of ROWS x COLS beams of JxJ maps;
/// everything else is set at run time. `FAILSAFE_ELF` runs the matrix on
/// another build of the same configuration instead (an earlier firmware,
/// to see which rows it fails: CHANGELOG).
fn elf() -> PathBuf {
    if let Some(p) = std::env::var_os("FAILSAFE_ELF") {
        return PathBuf::from(p);
    }
    dmap::twin::build_elf(&format!(
        "j1={J} j2={J} cols={COLS} rows={ROWS} scores=1 fw={}",
        cvm_core::VERSION
    ))
    .unwrap()
}

/// A request line as `dmap sensor` frames it, in hex for `--requests`.
fn hex_request(id: u32, r: &Request) -> String {
    struct Bytes(Vec<u8>);
    impl cvm_core::protocol::LineSink for Bytes {
        fn line(&mut self, l: &[u8], _: cvm_core::protocol::Priority) {
            self.0.extend_from_slice(l);
        }
    }
    let mut b = Bytes(Vec::new());
    encode_request(id, r, &mut b);
    b.0.iter().map(|x| format!("{x:02x}")).collect()
}

/// One run of the chip model: `parts` good parts at `beam_us`, `requests`
/// (beam, request), `faults`, and `--flash`/`--power-cut` when given. Row
/// mode is set and saved at beam 0 (200 µs pulses), as a user deploys
/// it, so that it outlives the resets (in a flash file of its own when
/// none is given).
fn run(
    mode: Mode,
    parts: usize,
    beam_us: f64,
    faults: &[String],
    requests: &[(usize, Request)],
    flash: Option<(&Path, Option<u32>)>,
) -> Run {
    let dir = tempfile::tempdir().unwrap();
    let scan = parts_file(dir.path(), parts);
    let mut reqs = String::new();
    let mut all: Vec<(usize, Request)> = Vec::new();
    let own_flash = dir.path().join("bank2.bin");
    let flash = match (mode, flash) {
        (Mode::Row, None) => Some((own_flash.as_path(), None)),
        (_, f) => f,
    };
    if mode == Mode::Row {
        all.push((0, Request::Set(Key::Pulse, 200)));
        all.push((0, Request::Set(Key::RejectMode, 1)));
        all.push((0, Request::Save));
    }
    all.extend(requests.iter().cloned());
    for (id, (beam, r)) in (1..).zip(&all) {
        reqs.push_str(&format!("{beam} {}\n", hex_request(id, r)));
    }
    let req_file = dir.path().join("requests.txt");
    std::fs::write(&req_file, reqs).unwrap();
    let twin = Path::new(env!("CARGO_MANIFEST_DIR")).join("../twin");
    let mut cmd = Command::new("python3");
    cmd.args(["-m", "h743twin"])
        .arg(elf())
        .arg("--scan")
        .arg(&scan)
        .args(["--beam-us", &beam_us.to_string()])
        .args(["--scans", "1", "--settle-ms", "5"])
        .arg("--requests")
        .arg(&req_file)
        .env("PYTHONPATH", &twin);
    for f in faults {
        cmd.args(["--fault", f]);
    }
    // `FAILSAFE_MODEL_ARGS`: more options for the model, to run an
    // earlier firmware past the rules it breaks (`--clock-drops count
    // --psize any`), with `FAILSAFE_ELF`.
    if let Ok(more) = std::env::var("FAILSAFE_MODEL_ARGS") {
        cmd.args(more.split_whitespace());
    }
    if let Some((f, cut)) = flash {
        cmd.arg("--flash").arg(f);
        if let Some(n) = cut {
            cmd.args(["--power-cut", &n.to_string()]);
        }
    }
    let out = cmd.output().expect("running the chip model");
    let c = counters(&out);
    assert_ne!(c["status"], "error", "{c}");
    // No register access lost to a clock enable's delay (with the model
    // told to go on past them, an earlier firmware's are only shown).
    let drops = c["clock_enable_drops"].as_array().map_or(0, Vec::len);
    if std::env::var_os("FAILSAFE_MODEL_ARGS").is_some() {
        println!("clock-enable drops: {drops}");
    } else {
        assert_eq!(drops, 0, "{c}");
    }
    Run::from(&out.stdout, c)
}

/// The DRDY time of beam `b`, µs.
fn beam_us(b: usize, period: f64) -> f64 {
    START_US + b as f64 * period
}

/// The matrix's assertions for an event at `t` (µs) in `run`: READY
/// never reads ready from `t + slack` until the first clean scan after it
/// has begun (its header), and its first return comes within that scan,
/// by its end line (the pins move as soon as its last beam decides the
/// verdict, ahead of the lines); in part mode REJECT reads "reject" from
/// `t + slack` until the next scan's header. `slack`: the time the
/// firmware may take to react (0 for a reset, which takes the pins to
/// Hi-Z at once). Returns the times (µs) of READY's return and REJECT's
/// release, for the table.
fn judged_safe(r: &Run, what: &str, mode: Mode, t: f64, slack: f64) -> (f64, f64) {
    let t0 = t + slack;
    let clean = r
        .first_clean_end(t0)
        .unwrap_or_else(|| panic!("{what}: no clean scan after the event:\n{}", r.stdout));
    let begun = r.header_before(clean).unwrap_or(0.0).max(t0);
    let high = r.high_within("READY", t0, begun);
    assert!(
        high.is_empty(),
        "{what}: READY reads ready at {high:?} µs, before the first clean scan after the event at {t:.1} µs (begun {begun:.1} µs, its end line at {clean:.1} µs)"
    );
    let back = r
        .pins
        .iter()
        .find(|e| e.1 == "READY" && e.0 > t0 && e.2.reads_high())
        .map_or(f64::NAN, |e| e.0);
    assert!(
        back > begun && back <= clean,
        "{what}: READY back at {back:.1} µs, not with the first clean scan after the event ({begun:.1} to {clean:.1} µs)"
    );
    let mut released = f64::NAN;
    if mode == Mode::Part {
        assert!(
            !r.level("REJECT", t0).passes(),
            "{what}: REJECT reads \"pass\" at {t0:.1} µs, after the event"
        );
        // Its release: the next part's, which only a frame read after the
        // event can begin.
        if let Some(e) = r
            .pins
            .iter()
            .find(|e| e.1 == "REJECT" && e.0 > t0 && e.2.passes())
        {
            assert!(
                e.3 > t0,
                "{what}: REJECT released at {:.1} µs before any frame was read after the event ({t:.1} µs)",
                e.0
            );
            released = e.0;
        }
    }
    (back, released)
}

/// The beam of the event: in the middle of the third part, so that two
/// clean parts came before it (row mode is in effect from the second).
const AT: usize = 2 * BEAMS + 13;

fn both_modes(f: impl Fn(Mode)) {
    f(Mode::Part);
    f(Mode::Row);
}

/// A reset event injected by the model at beam AT: the pins go Hi-Z with
/// the reset and READY waits for a clean scan.
fn reset_event(fault: &str, rst: &str) {
    both_modes(|mode| {
        let period = 1000.0;
        let r = run(mode, 10, period, &[format!("{fault}@{AT}")], &[], None);
        let what = format!("{fault} ({mode:?} mode)");
        assert_eq!(r.resets.len(), 1, "{what}: {}", r.counters);
        let t = r.resets[0];
        assert!(
            r.stdout.contains(&format!(",rst={rst},")),
            "{what}: {}",
            r.stdout
        );
        let (back, released) = judged_safe(&r, &what, mode, t, 0.0);
        println!(
            "{what}: event {t:.1} µs, READY back {back:.1} µs, REJECT released {released:.1} µs"
        );
    });
}

#[test]
fn power_on_drives_not_ready_and_reject_until_the_firmware_runs() {
    both_modes(|mode| {
        let r = run(mode, 4, 1000.0, &[], &[], None);
        // Hi-Z out of reset, then driven low ("not ready", "reject") first
        // thing, then the power-on's levels: READY up, REJECT released.
        for pin in ["READY", "REJECT"] {
            let e: Vec<Level> = r.pins.iter().filter(|e| e.1 == pin).map(|e| e.2).collect();
            assert_eq!(e.first(), Some(&Level::Z), "{pin}: {e:?}");
            assert_eq!(e.get(1), Some(&Level::Low), "{pin}: {e:?}");
            assert_eq!(e.get(2), Some(&Level::High), "{pin}: {e:?}");
        }
        let low = |pin: &str| {
            r.pins
                .iter()
                .find(|e| e.1 == pin && e.2 == Level::Low)
                .unwrap()
                .0
        };
        // Driven as soon as the reset path (zeroing .bss) has run, before
        // the clocks, embassy's init and the store; Hi-Z, which reads the
        // same, until then.
        assert!(
            low("READY") < 1000.0 && low("REJECT") < 1000.0,
            "{:?}",
            r.pins
        );
        assert!(!r.stdout.contains("verdict=fault"), "{}", r.stdout);
    });
}

#[test]
fn pin_reset_is_judged_safe() {
    reset_event("pin-reset", "pin");
}

#[test]
fn brown_out_is_judged_safe() {
    reset_event("bor", "other");
}

/// A fault injected at beam AT whose handler drives the safe state
/// within `slack` µs and resets the chip within `reset_us` µs (`rst=sw`).
fn fault_drives_the_safe_state_and_resets(fault: &str, slack: f64, reset_us: f64) {
    both_modes(|mode| {
        let period = 1000.0;
        let r = run(mode, 10, period, &[format!("{fault}@{AT}")], &[], None);
        let what = format!("{fault} ({mode:?} mode)");
        assert_eq!(r.resets.len(), 1, "{what}: {}", r.counters);
        let t = beam_us(AT, period);
        assert!(
            r.resets[0] - t < reset_us,
            "{what}: reset at {} µs",
            r.resets[0]
        );
        assert!(r.stdout.contains(",rst=sw,"), "{what}: {}", r.stdout);
        judged_safe(&r, &what, mode, t, slack);
    });
}

#[test]
fn hardfault_drives_the_safe_state_and_resets() {
    fault_drives_the_safe_state_and_resets("hardfault", 5.0, 50.0);
}

#[test]
fn panic_drives_the_safe_state_and_resets() {
    fault_drives_the_safe_state_and_resets("panic", 50.0, 1000.0);
}

#[test]
fn watchdog_reset_is_judged_safe() {
    // The watchdog (1 s) resets a wedged firmware: beams 8 ms apart.
    both_modes(|mode| {
        let period = 8000.0;
        let r = run(mode, 12, period, &[format!("wedge@{AT}")], &[], None);
        let what = format!("watchdog ({mode:?} mode)");
        assert_eq!(r.resets.len(), 1, "{what}: {}", r.counters);
        assert!(r.stdout.contains(",rst=wdg,"), "{what}: {}", r.stdout);
        judged_safe(&r, &what, mode, r.resets[0], 0.0);
    });
}

#[test]
fn reset_command_is_judged_safe() {
    both_modes(|mode| {
        let period = 1000.0;
        let r = run(mode, 10, period, &[], &[(AT, Request::Reset)], None);
        let what = format!("reset command ({mode:?} mode)");
        assert_eq!(r.resets.len(), 1, "{what}: {}", r.counters);
        assert!(r.stdout.contains(",rst=sw,"), "{what}: {}", r.stdout);
        judged_safe(&r, &what, mode, r.resets[0], 0.0);
    });
}

#[test]
fn detector_fault_mid_scan_is_judged_safe() {
    both_modes(|mode| {
        let period = 1000.0;
        let r = run(mode, 6, period, &[format!("dma-stall@{AT}")], &[], None);
        let what = format!("detector fault ({mode:?} mode)");
        assert!(r.resets.is_empty(), "{what}");
        let t = beam_us(AT, period);
        // The faulty scan's end line says so.
        let end = r
            .lines
            .iter()
            .find(|(u, l)| *u > t && l.starts_with("E,"))
            .unwrap_or_else(|| panic!("{what}: no end line:\n{}", r.stdout));
        assert!(end.1.contains("verdict=fault-missing"), "{what}: {}", end.1);
        // READY drops within the faulty scan (once the read's deadline has
        // passed), and waits for a clean scan from there.
        let drop = r
            .pins
            .iter()
            .find(|e| e.1 == "READY" && e.0 > t && !e.2.reads_high())
            .map(|e| e.0)
            .unwrap_or(f64::INFINITY);
        assert!(
            drop <= end.0,
            "{what}: READY dropped at {drop:.1} µs, after the faulty scan"
        );
        judged_safe(&r, &what, Mode::Row, drop, 0.0);
        if mode == Mode::Part {
            // The faulty part is rejected at its end, and REJECT holds until
            // a frame of the next part has been read.
            let low = r
                .pins
                .iter()
                .find(|e| e.1 == "REJECT" && e.0 > t && !e.2.passes())
                .unwrap_or_else(|| panic!("{what}: REJECT never asserted"));
            assert!(low.0 <= end.0, "{what}: REJECT asserted after the end line");
            let release = r
                .pins
                .iter()
                .find(|e| e.1 == "REJECT" && e.0 > low.0 && e.2.passes());
            if let Some(e) = release {
                assert!(
                    e.3 > low.0,
                    "{what}: REJECT released before the next part began"
                );
            }
        }
    });
}

/// A bank whose first page is full of records (of another build: the
/// scan's firmware ignores them, `store=foreign`), so that the next save
/// erases a sector.
fn full_page_bank(path: &Path) {
    use cvm_fw_app::settings_store::{VALUES, Values};
    use cvm_fw_app_tests::bank::{self, Bank, SECTOR};
    let tag = cvm_core::record::Tag::new(&cvm_core::Config::paper(
        // 7x7: no build the tests scan with.
        cvm_core::Geometry::new(7, 7).unwrap(),
    ));
    let b = Bank::erased();
    let item = cvm_fw_app::flash_words::WORD
        + cvm_core::record::encoded_len(VALUES).next_multiple_of(cvm_fw_app::flash_words::WORD);
    let per_page = (SECTOR - 2 * cvm_fw_app::flash_words::WORD) / item;
    let mut v: Values = [0; VALUES];
    for n in 0..per_page {
        v[Key::Threshold.index()] = 1000 + n as u32;
        embassy_futures::block_on(bank::h743_store(&b).save(&tag, &v)).unwrap();
    }
    b.save(path).unwrap();
}

/// A `save` over a full store page at beam 5 and a `reset` at beam 20,
/// on `scan` at `beam_us` with `opts`: the save's sector erase (up to 2 s
/// at x64, the model's time for it) outlasts the whole scan, no beam is
/// lost and the lines are `dmap stream`'s; the `reset` is refused `busy`
/// and nothing resets.
fn save_during_a_scan(scan: &Path, opts: &[&str], beam_us: &str) {
    let dir = tempfile::tempdir().unwrap();
    let p = |x: &Path| x.to_str().unwrap().to_string();
    let flash = dir.path().join("bank2.bin");
    full_page_bank(&flash);
    let host = common::dmap_ok(&[&["stream", &p(scan)], opts].concat());
    let twin = common::dmap_ok(
        &[
            &["twin", &p(scan)],
            opts,
            &[
                "--beam-us",
                beam_us,
                "--flash",
                &p(&flash),
                "--command",
                "5:save",
                "--command",
                "20:reset",
            ],
        ]
        .concat(),
    );
    let c = counters(&twin);
    let err = String::from_utf8_lossy(&twin.stderr);
    let (host, out) = (
        String::from_utf8(host.stdout).unwrap(),
        String::from_utf8(twin.stdout).unwrap(),
    );
    // The save on a full page: the two pages' markers, the newest record
    // copied (its header word and data words), then the erase, which was
    // under way when the scan ended.
    let words = 1 + cvm_core::record::encoded_len(cvm_fw_app::settings_store::VALUES)
        .div_ceil(cvm_fw_app::flash_words::WORD);
    assert!(
        c["flash_operations"].as_u64() >= Some(2 + words as u64 + 1),
        "no erase: {c}"
    );
    let lines: Vec<&str> = out.lines().filter(|l| !l.starts_with("A,")).collect();
    let want: Vec<&str> = host.lines().collect();
    assert_eq!(lines.len(), want.len(), "{out}");
    // The header differs only in the store's state (a foreign record).
    assert_eq!(
        lines[0].split(",store=").next(),
        want[0].split(",store=").next()
    );
    assert!(lines[0].contains(",store=foreign"), "{}", lines[0]);
    assert!(
        lines[1..] == want[1..],
        "the lines differ from dmap stream's"
    );
    assert!(out.contains(",missing=0,"), "{out}");
    assert!(
        out.lines().any(|l| l.starts_with("A,2,err,busy")),
        "reset during the save: {out}\n{err}"
    );
    assert!(c["resets"].as_array().unwrap().is_empty(), "{c}");
}

/// The demo part (39 x 39 beams of 9x9 maps) at the 9x9 SPI-limit beam
/// rate, 53 µs.
#[test]
fn a_save_erases_while_the_demo_scans_at_the_spi_limit_and_reset_waits() {
    let dir = tempfile::tempdir().unwrap();
    let scan = common::demo_scan(dir.path());
    save_during_a_scan(&scan, &["--scores", "--threshold", "0.5"], "53");
}

/// A part of 50 x 40 beams of 15x15 maps with one object at the 15x15
/// SPI-limit beam rate, 146 µs (the build of twin_outputs.rs's 15x15 test).
#[test]
fn a_save_erases_while_a_15x15_part_scans_at_the_spi_limit_and_reset_waits() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    common::blob_scan(&scan, 50, 40, 15, 11);
    save_during_a_scan(&scan, &["--threshold", "0.05"], "146");
}

/// The power goes during a `save` (the model cuts it at the save's second
/// flash operation: a flash word half programmed); the board then starts
/// again from power-on with that flash. The part on the line was never
/// judged: READY must wait for a clean scan although the start is a
/// power-on (the flash shows the cut save).
#[test]
fn power_cut_during_a_save_is_judged_safe() {
    both_modes(|mode| {
        let dir = tempfile::tempdir().unwrap();
        let flash = dir.path().join("bank2.bin");
        let period = 1000.0;
        // The flash operations before the save at AT (row mode saves its
        // settings at beam 0).
        let before = run(mode, 3, period, &[], &[], Some((&flash, None)));
        let ops = before.counters["flash_operations"].as_u64().unwrap() as u32;
        std::fs::remove_file(&flash).unwrap();
        let cut = run(
            mode,
            10,
            period,
            &[],
            &[(AT, Request::Save)],
            Some((&flash, Some(ops + 2))),
        );
        let what = format!("power cut during a save ({mode:?} mode)");
        assert_eq!(
            cut.counters["status"], "power cut",
            "{what}: {}",
            cut.counters
        );
        let after = run(mode, 6, period, &[], &[], Some((&flash, None)));
        assert!(
            after.stdout.contains(",rst=por,"),
            "{what}: {}",
            after.stdout
        );
        judged_safe(&after, &what, mode, 0.0, 0.0);
    });
}

/// USART3's overrun: the core is halted (a debugger) while a request of
/// 16 bytes, the receive FIFO's size, arrives, then a second one that
/// finds the FIFO full and is lost. The first arrived whole before the
/// loss: it is answered; the loss is reported as an overrun after it.
/// (A firmware that reports the overrun before the FIFO's bytes refuses
/// the intact request instead.)
#[test]
fn an_overrun_costs_the_line_after_the_fifos_bytes_not_the_fifos() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    common::blob_scan(&scan, 4, 10, 9, 7);
    let framed = |id: u32, r: &Request| {
        let hex = hex_request(id, r);
        (0..hex.len() / 2)
            .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap())
            .collect::<Vec<u8>>()
    };
    let first = framed(1, &Request::Status);
    assert_eq!(first.len(), 16, "{:?}", String::from_utf8_lossy(&first));
    let mut both = first.clone();
    both.extend(framed(2, &Request::Get(Key::Threshold)));
    let req = dir.path().join("requests.txt");
    dmap::twin::requests::write_requests(&req, &[(5, &both)]).unwrap();
    let p = |x: &Path| x.to_str().unwrap().to_string();
    let twin = common::dmap_ok(&[
        "twin",
        &p(&scan),
        "--requests",
        &p(&req),
        "--fault",
        "halt@5:2",
    ]);
    let c = counters(&twin);
    assert!(c["uart_rx_overruns"].as_u64() >= Some(1), "no overrun: {c}");
    let out = String::from_utf8(twin.stdout).unwrap();
    let replies: Vec<&str> = out.lines().filter(|l| l.starts_with("A,")).collect();
    assert!(
        replies
            .first()
            .is_some_and(|r| r.starts_with("A,1,ok,status,")),
        "{replies:?}"
    );
    assert!(
        !replies.iter().any(|r| r.starts_with("A,2,")),
        "request 2 was lost: {replies:?}"
    );
}
