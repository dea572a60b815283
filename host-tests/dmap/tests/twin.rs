//! `dmap twin`: the H743 release firmware, unmodified, on the chip model
//! (host-tests/twin). Its UART bytes equal `dmap stream`'s for the same
//! scan and settings; under every fault of the detector model every
//! position is accounted in the end line, the firmware neither hangs nor
//! resets, and a wedged firmware is reset by the watchdog. Needs python3
//! with unicorn and pyelftools and the `thumbv7em-none-eabihf` target
//! (scripts/setup.sh); each configuration's ELF is built once and cached in
//! target/twin/elf.

use cvm_reference::Geometry;
use dmap::npy::write_scan_u16;
use std::collections::HashMap;
use std::path::Path;
use std::process::{Command, Output};

const ROWS: usize = 6;
const COLS: usize = 12;

/// A scan with a planted bright blob, a dark map and a saturated map over
/// a random background.
fn write_scan(path: &Path, j1: usize, j2: usize, seed: u64) {
    let data = scan_samples(ROWS, COLS, j1, j2, seed);
    write_scan_u16(path, ROWS, COLS, Geometry::new(j1, j2).unwrap(), &data).unwrap();
}

/// The samples of [`write_scan`] with `rows` x `cols` beams, in raster
/// order, each map in (J1, J2) order.
fn scan_samples(rows: usize, cols: usize, j1: usize, j2: usize, seed: u64) -> Vec<u16> {
    let mut state = seed;
    let mut rnd = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 33) as u32
    };
    let cells = j1 * j2;
    let mut data = Vec::with_capacity(rows * cols * cells);
    for r in 0..rows {
        for c in 0..cols {
            for k in 0..cells {
                let mut v = 500 + (rnd() % 300) as u16;
                if (r, c) == (rows / 2, cols / 3) && k % 2 == 0 {
                    v += 6000;
                }
                if (r, c) == (1, cols - 2) {
                    v = 0;
                }
                if (r, c) == (rows - 2, 1) {
                    v = u16::MAX;
                }
                data.push(v);
            }
        }
    }
    data
}

fn dmap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(args)
        .output()
        .expect("running dmap")
}

fn ok(args: &[&str], out: &Output) {
    assert!(
        out.status.success(),
        "dmap {args:?} failed ({}):\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The model's counters: the last line of standard error.
fn counters(out: &Output) -> serde_json::Value {
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.lines().rfind(|l| !l.trim().is_empty()).unwrap_or("");
    serde_json::from_str(last).unwrap_or_else(|e| panic!("no JSON counters ({e}) in:\n{err}"))
}

/// The configuration of the fault scenarios: 9x9 maps, paper kernels,
/// score lines, a threshold the planted blob exceeds.
const FAULT_OPTS: [&str; 3] = ["--scores", "--threshold", "0.05"];

/// `dmap stream` and `dmap twin` over the same scan with `opts`: the twin
/// must print the same bytes. The only documented difference is the `fw`
/// field of the header (the H743 firmware announces `cvm-fw-<version>`,
/// `dmap stream` the scoring code's `<version>`), so the header may differ
/// in exactly that field and its checksum.
fn compare(j1: usize, j2: usize, opts: &[&str]) {
    compare_twin(j1, j2, opts, &[]);
}

/// [`compare`] with options of `dmap twin` only (`twin_opts`).
fn compare_twin(j1: usize, j2: usize, opts: &[&str], twin_opts: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    write_scan(&scan, j1, j2, (j1 * 100 + j2) as u64);
    let scan = scan.to_str().unwrap();
    let stream_args = [&["stream", scan, "--from-flash"], opts].concat();
    let host = dmap(&stream_args);
    ok(&stream_args, &host);
    let twin_args = [&["twin", scan], opts, twin_opts].concat();
    let twin = dmap(&twin_args);
    ok(&twin_args, &twin);
    let text = String::from_utf8(host.stdout.clone()).unwrap();
    assert!(
        text.starts_with("H,") && text.contains("\nE,"),
        "unexpected stream output: {text}"
    );
    assert!(
        text.lines().any(|l| l.starts_with("O,")),
        "the planted defect must show as an object"
    );
    if opts.contains(&"--max-defect-lines") {
        assert!(
            text.lines().any(|l| l.starts_with("D,")),
            "defect lines were asked for"
        );
    }
    assert!(
        twin.stdout == host.stdout,
        "the H743 firmware and the host pipeline differ for {opts:?}:\n--- stream\n{text}\n--- twin\n{}",
        String::from_utf8_lossy(&twin.stdout)
    );
    let c = counters(&twin);
    assert_eq!(c["status"], "done", "{c}");
    assert_eq!(c["resets"], serde_json::json!([]), "{c}");
    assert_eq!(c["beams"], (ROWS * COLS) as u64, "{c}");
    stack_to_spare(&c);
}

/// The stack (DTCM above the `.dtcm` statics) never came within 4 KiB of
/// the statics below it: the model paints it at power-on and finds the
/// deepest word written.
fn stack_to_spare(c: &serde_json::Value) {
    let free = c["stack_free_bytes"].as_u64();
    assert!(
        free >= Some(4096),
        "the stack came within {free:?} bytes of the .dtcm statics: {c}"
    );
}

#[test]
fn twin_matches_stream_paper_9x9_scores() {
    compare(9, 9, &FAULT_OPTS);
}

/// The spread channel on: `dmap twin` compiles its threshold in
/// (`CVM_H743_SCAN` `sthr`) and the H743 decides with it as the host does.
#[test]
fn twin_matches_stream_with_the_spread_channel() {
    compare(
        9,
        9,
        &[
            "--scores",
            "--threshold",
            "0.05",
            "--spread-threshold",
            "0.002",
            "--max-defect-lines",
            "4",
        ],
    );
}

/// The release firmware's default geometry, whose row and column passes
/// (generated assembly for 15 cells) no other twin test runs.
#[test]
fn twin_matches_stream_paper_15x15_scores() {
    compare(15, 15, &FAULT_OPTS);
}

#[test]
fn twin_matches_stream_square_raw_5x7() {
    compare(
        5,
        7,
        &[
            "--kernels",
            "square",
            "--bmax",
            "3",
            "--raw",
            "--threshold",
            "1e11",
            "--max-defect-lines",
            "2",
        ],
    );
}

/// The square kernels at 15x15 on the H743 build: the factor table built
/// at start-up (in DTCM), the fold and the two-row factor loop in the
/// firmware's assembly. The first beam comes after the table is built.
#[test]
fn twin_matches_stream_square_15x15() {
    compare_twin(
        15,
        15,
        &["--kernels", "square", "--threshold", "0.05"],
        &["--start-ms", "200"],
    );
}

/// The default geometry and width (15x15 maps, 300 columns: the release
/// build but for the number of rows, row buffer B in SRAM1..3), two scans
/// of three rows back to back, with beams 4 % further apart than a frame
/// takes on the SPI (144 us at 25 MHz): every beam is scored and the
/// output is `dmap stream`'s for each scan. The scoring task does a row's
/// decisions and lines in one go when the row below it is complete (about
/// 150 000 cycles here), and the last two rows of a scan at its end (about
/// 600 000 cycles: ten beams' time). With two frame buffers the second
/// beam of every row from the third on was lost at beam periods up to
/// 250 us; here two buffers lose 2 beams of the first scan, and buffers
/// for one row's burst (8) lose 3 of the second.
#[test]
fn twin_default_geometry_scores_every_beam_at_the_spi_limit() {
    back_to_back_scans_at(15, "150");
}

/// The same for 9x9 maps, whose frame takes 52 us: beams 58 us apart, 55
/// frame buffers of 96 samples, row buffer B in AXI SRAM with A.
#[test]
fn twin_9x9_scores_every_beam_at_the_spi_limit() {
    back_to_back_scans_at(9, "58");
}

/// Two scans of 3 x 300 beams of `j` x `j` maps back to back, `beam_us`
/// apart, through the firmware built for 3 rows: every beam scored, the
/// output `dmap stream`'s for each scan.
fn back_to_back_scans_at(j: usize, beam_us: &str) {
    let (rows, cols) = (3, 300);
    let dir = tempfile::tempdir().unwrap();
    let mut expected = Vec::new();
    let mut all = Vec::new();
    for (k, seed) in [j as u64 * 101, j as u64 * 101 + 1].into_iter().enumerate() {
        let data = scan_samples(rows, cols, j, j, seed);
        let scan = dir.path().join(format!("scan{k}.npy"));
        write_scan_u16(&scan, rows, cols, Geometry::new(j, j).unwrap(), &data).unwrap();
        let args = [&["stream", scan.to_str().unwrap()][..], &FAULT_OPTS].concat();
        let host = dmap(&args);
        ok(&args, &host);
        expected.extend_from_slice(&host.stdout);
        all.extend(data);
    }
    // Both scans in one file of the chip model's format (dmap::twin::twin_file).
    let mut file = b"CVMTWIN1".to_vec();
    for v in [2 * rows, cols, j, j] {
        file.extend_from_slice(&(v as u32).to_le_bytes());
    }
    for v in &all {
        file.extend_from_slice(&v.to_le_bytes());
    }
    let twin_scan = dir.path().join("both.twin");
    std::fs::write(&twin_scan, file).unwrap();
    let elf = dmap::twin::build_elf(&format!(
        "j1={j} j2={j} cols={cols} rows={rows} scores=1 thr={} fw={}",
        // 0.05 in distance units, as `--threshold 0.05` makes it.
        dmap::options::ScoringArgs::default()
            .scorer(j, j)
            .unwrap()
            .threshold_from_units(0.05),
        cvm_core::VERSION
    ))
    .unwrap();
    let twin = Path::new(env!("CARGO_MANIFEST_DIR")).join("../twin");
    let out = Command::new("python3")
        .args(["-m", "h743twin"])
        .arg(&elf)
        .arg("--scan")
        .arg(&twin_scan)
        .args(["--beam-us", beam_us, "--scans", "2"])
        .env("PYTHONPATH", &twin)
        .output()
        .expect("running the chip model");
    let c = counters(&out);
    for e in String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter(|l| l.starts_with("E,"))
    {
        assert!(e.contains(",missing=0,"), "{e}");
    }
    assert!(
        out.stdout == expected,
        "the H743 firmware and the host pipeline differ:\n--- stream\n{}\n--- twin\n{}",
        String::from_utf8_lossy(&expected),
        String::from_utf8_lossy(&out.stdout)
    );
    assert_eq!(c["status"], "done", "{c}");
    assert_eq!(c["beams"], (2 * rows * cols) as u64, "{c}");
    assert_eq!(c["spi_overruns"], 0, "{c}");
    stack_to_spare(&c);
}

/// The end line's numeric values by key (the verdict is not a number).
fn end_line(stdout: &[u8]) -> HashMap<String, u64> {
    let text = String::from_utf8_lossy(stdout);
    let line = text
        .lines()
        .rfind(|l| l.starts_with("E,"))
        .unwrap_or_else(|| panic!("no end line in:\n{text}"));
    let line = &line[2..line.find('*').unwrap_or(line.len())];
    line.split(',')
        .filter_map(|kv| {
            let (k, v) = kv.split_once('=').unwrap();
            Some((k.to_string(), v.parse().ok()?))
        })
        .collect()
}

/// The fault scenario `faults` on the 9x9 configuration; returns the run.
fn twin_with(faults: &[&str], extra: &[&str]) -> (Output, serde_json::Value) {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    write_scan(&scan, 9, 9, 909);
    let mut args = vec!["twin", scan.to_str().unwrap()];
    args.extend_from_slice(&FAULT_OPTS);
    for f in faults {
        args.extend_from_slice(&["--fault", f]);
    }
    args.extend_from_slice(extra);
    let out = dmap(&args);
    ok(&args, &out);
    let c = counters(&out);
    (out, c)
}

/// One fault: injected, the scan ends (no hang: the end line comes within
/// the settle time), no reset and no second boot, every position placed or
/// reported missing, and acquisition recovers (at most a row's worth of
/// positions lost to one fault).
fn survives(fault: &str) {
    let kind = &fault[..fault.find('@').unwrap()];
    let (out, c) = twin_with(&[fault], &[]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        c["faults_injected"][kind].as_u64() >= Some(1),
        "{fault} not injected: {c}"
    );
    assert_eq!(
        c["status"], "done",
        "{fault}: no end line within the settle time:\n{text}\n{c}"
    );
    assert_eq!(c["resets"], serde_json::json!([]), "{fault}: reset: {c}");
    assert_eq!(
        text.lines().filter(|l| l.starts_with("H,")).count(),
        1,
        "{fault}: one boot, one header:\n{text}"
    );
    let e = end_line(&out.stdout);
    let n = (ROWS * COLS) as u64;
    assert_eq!(e["rows"], ROWS as u64, "{fault}: {e:?}");
    assert_eq!(
        e["frames"] + e["missing"],
        n,
        "{fault}: positions unaccounted: {e:?}"
    );
    assert!(e["misplaced"] <= e["frames"], "{fault}: {e:?}");
    assert!(
        e["missing"] <= COLS as u64,
        "{fault}: acquisition did not recover: {e:?}"
    );
    stack_to_spare(&c);
}

/// The product binary itself (`cargo build --release`, default
/// configuration: 15x15 maps, 1 024 columns at most) boots on the chip
/// model and leaves stack to spare: `main` builds the pipeline on the
/// stack (about 48 KB) while DTCM also holds the scorer's tables, the near
/// buffer and the scoring side's state.
#[test]
fn twin_default_build_boots_with_stack_to_spare() {
    let elf = dmap::twin::build_elf("").unwrap();
    let twin = Path::new(env!("CARGO_MANIFEST_DIR")).join("../twin");
    let out = Command::new("python3")
        .args(["-m", "h743twin"])
        .arg(&elf)
        .args(["--run-ms", "30"])
        .env("PYTHONPATH", &twin)
        .output()
        .expect("running the chip model");
    let c = counters(&out);
    assert_eq!(c["status"], "time", "{c}");
    assert_eq!(c["fault"], serde_json::Value::Null, "{c}");
    assert!(
        c["stack_bytes"].as_u64() > Some(64 * 1024),
        "the stack should have most of DTCM: {c}"
    );
    let used = c["stack_bytes"].as_u64().unwrap() - c["stack_free_bytes"].as_u64().unwrap();
    assert!(
        used > 8 * 1024,
        "main builds the pipeline on the stack: {c}"
    );
    stack_to_spare(&c);
}

#[test]
fn twin_fault_drdy_gap() {
    survives("gap@20:50");
}

#[test]
fn twin_fault_drdy_burst_faster_than_spi() {
    survives("burst@20:6:20");
}

#[test]
fn twin_fault_line_sync_glitch() {
    survives("sync-glitch@17");
}

#[test]
fn twin_fault_line_sync_miss() {
    survives("sync-miss@24");
}

#[test]
fn twin_fault_uart_busy() {
    survives("uart-busy@10:30");
}

#[test]
fn twin_fault_spi_overrun() {
    survives("overrun@30");
}

#[test]
fn twin_fault_dma_transfer_error() {
    survives("dma-error@30");
}

#[test]
fn twin_fault_dma_stall() {
    survives("dma-stall@30");
}

#[test]
fn twin_wedged_firmware_is_reset_by_the_watchdog() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    write_scan(&scan, 9, 9, 909);
    let mut args = vec!["twin", scan.to_str().unwrap()];
    args.extend_from_slice(&FAULT_OPTS);
    args.extend_from_slice(&["--fault", "wedge@30"]);
    let out = dmap(&args);
    // The scan restarted after the reset never ends: a failed run.
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.trim_end().ends_with("the scan did not finish"), "{err}");
    let c: serde_json::Value =
        serde_json::from_str(err.trim_end().lines().rev().nth(1).unwrap()).unwrap();
    assert_eq!(c["faults_injected"]["wedge"], 1, "{c}");
    let resets = c["resets"].as_array().expect("resets list");
    assert!(
        resets.iter().any(|r| r["cause"] == "watchdog"),
        "no watchdog reset after the wedge: {c}"
    );
}

#[test]
fn twin_refuses_a_bad_fault_before_building() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    write_scan(&scan, 3, 3, 1);
    let scan = scan.to_str().unwrap();
    for (spec, what) in [
        ("jam@3", "unknown kind"),
        ("gap@3", "takes 1 number"),
        ("wedge@72", "past the scan's last beam"),
    ] {
        let out = dmap(&["twin", scan, "--fault", spec]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{spec}: {err}");
        assert_eq!(err.lines().count(), 1, "{spec}: one line: {err}");
        assert!(err.contains(what), "{spec}: {err}");
    }
}

/// The model never outlives `dmap`: killed by SIGTERM mid-run, `dmap`
/// kills and reaps the model and removes its scan file before it dies.
#[cfg(target_os = "linux")]
#[test]
fn twin_model_dies_with_dmap() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    write_scan(&scan, 9, 9, 909);
    let mut args = vec!["twin", scan.to_str().unwrap()];
    args.extend_from_slice(&FAULT_OPTS);
    // A beam a second: the model runs for over a minute.
    args.extend_from_slice(&["--beam-us", "1000000"]);
    let mut dmap = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(&args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let parent = dmap.id();
    let started = std::time::Instant::now();
    // The model: a child of dmap running python3 (after the build, if any).
    let (model, cmdline) = loop {
        let found = std::fs::read_dir("/proc").unwrap().flatten().find_map(|e| {
            let pid: u32 = e.file_name().to_str()?.parse().ok()?;
            let stat = std::fs::read_to_string(e.path().join("stat")).ok()?;
            let ppid: u32 = stat
                .rsplit(')')
                .next()?
                .split_whitespace()
                .nth(1)?
                .parse()
                .ok()?;
            let cmd = std::fs::read(e.path().join("cmdline")).ok()?;
            let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
            (ppid == parent && cmd.contains("h743twin")).then_some((pid, cmd))
        });
        if let Some(f) = found {
            break f;
        }
        assert!(
            dmap.try_wait().unwrap().is_none(),
            "dmap ended before the model started"
        );
        assert!(started.elapsed().as_secs() < 900, "the model did not start");
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    let scan_file = cmdline
        .split_whitespace()
        .skip_while(|a| *a != "--scan")
        .nth(1)
        .unwrap()
        .to_string();
    assert!(Path::new(&scan_file).exists(), "{cmdline}");
    std::thread::sleep(std::time::Duration::from_millis(300));
    // SAFETY: kill(2) on the pid of our own child.
    assert_eq!(unsafe { libc::kill(parent as i32, libc::SIGTERM) }, 0);
    let status = dmap.wait().unwrap();
    use std::os::unix::process::ExitStatusExt;
    assert_eq!(status.signal(), Some(libc::SIGTERM), "{status}");
    assert!(
        !Path::new(&format!("/proc/{model}")).exists(),
        "the model (pid {model}) outlived dmap"
    );
    assert!(
        !Path::new(&scan_file).exists(),
        "the model's scan file {scan_file} is left behind"
    );
}

/// The H743 firmware built with a calibration's thresholds compiled in,
/// as the settings `thr`, `pthr` and `sthr` of `CVM_H743_SCAN` (the
/// integers of `dmap calibrate`'s file), applies them bit for bit: its
/// output equals `dmap stream --calibration` with that file. The retired
/// `CVM_H743_CALIBRATION` and the old spelling `threshold=` are refused,
/// each naming what to write instead.
#[test]
fn twin_firmware_with_a_compiled_in_calibration_file() {
    let dir = tempfile::tempdir().unwrap();
    let (refs, scan) = (dir.path().join("ref.npy"), dir.path().join("scan.npy"));
    write_scan(&refs, 9, 9, 7);
    write_scan(&scan, 9, 9, 8);
    let cal = dir.path().join("cal.json");
    let (refs, scan, cal) = (
        refs.to_str().unwrap(),
        scan.to_str().unwrap(),
        cal.to_str().unwrap(),
    );
    let args = ["calibrate", refs, "-o", cal];
    ok(&args, &dmap(&args));
    let args = [
        "stream",
        scan,
        "--from-flash",
        "--scores",
        "--calibration",
        cal,
    ];
    let host = dmap(&args);
    ok(&args, &host);

    // The same target directory as `dmap twin`'s builds (their compiled
    // dependencies are reused), under the lock those builds take.
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let (target, lock) = dmap::twin::lock_build_dir(&root).unwrap();
    let build = |spec: &str| {
        Command::new(env!("CARGO"))
            .current_dir(&root)
            .args(["build", "--release", "--target-dir"])
            .arg(&target)
            .env("CVM_H743_SCAN", spec)
            .env_remove("CVM_H743_CALIBRATION")
            .env_remove("CARGO_TARGET_DIR")
            .env_remove("CARGO_BUILD_TARGET")
            .env_remove("RUSTFLAGS")
            .env_remove("CARGO_ENCODED_RUSTFLAGS")
            .output()
            .unwrap()
    };
    let file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(cal).unwrap()).unwrap();
    let thr = |channel: &str| file["channels"][channel]["thr"].as_u64().unwrap();
    let spec = format!(
        "j1=9 j2=9 cols={COLS} rows={ROWS} scores=1 fw={} thr={} pthr={} sthr={}",
        cvm_core::VERSION,
        thr("cvm"),
        thr("power"),
        thr("spread"),
    );
    let out = build(&spec);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let elf = dir.path().join("calibrated.elf");
    std::fs::copy(target.join("thumbv7em-none-eabihf/release/cvm-fw"), &elf).unwrap();
    let args = [
        "twin",
        scan,
        "--scores",
        "--calibration",
        cal,
        "--elf",
        elf.to_str().unwrap(),
    ];
    let twin = dmap(&args);
    ok(&args, &twin);
    assert!(
        twin.stdout == host.stdout,
        "--- stream\n{}\n--- twin\n{}",
        String::from_utf8_lossy(&host.stdout),
        String::from_utf8_lossy(&twin.stdout)
    );
    // The header carries the calibration's integers, not the defaults.
    let text = String::from_utf8_lossy(&host.stdout);
    assert!(!text.contains(",thr=4194304,"), "{text}");
    assert!(!text.contains(",pthr=3277,"), "{text}");

    // The retired variable and the old spelling: refused, saying what now.
    let out = Command::new(env!("CARGO"))
        .current_dir(&root)
        .args(["build", "--release", "--target-dir"])
        .arg(&target)
        .env("CVM_H743_SCAN", &spec)
        .env("CVM_H743_CALIBRATION", cal)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("CVM_H743_CALIBRATION is no longer read"),
        "{err}"
    );
    let out = build("j1=9 j2=9 threshold=0.3");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("threshold=0.3: write thr"), "{err}");
    // A threshold above the channel's largest value is written as off,
    // by the same rule as `--set` (`Key::off_above`).
    let out = build("j1=9 j2=9 pthr=46341");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("pthr=46341: above 46340 the channel is off; write pthr=4294967295"),
        "{err}"
    );
    drop(lock);
}
