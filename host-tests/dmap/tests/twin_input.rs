//! `dmap twin` under bad or unusual input (issue 37): an ELF built for
//! another run, a damaged ELF, model time without bound, a scan that never
//! ends, faults that would do nothing; and the model's output and life
//! tied to dmap's (lines as they come, no model left after any signal).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use crate::common;

/// The run the tests build for: 6 x 12 beams of 9x9 maps, score lines.
const OPTS: [&str; 3] = ["--scores", "--threshold", "0.05"];

fn scan_in(dir: &Path, j: usize) -> PathBuf {
    let scan = dir.join(format!("scan{j}.npy"));
    common::spot_scan(&scan, 6, 12, j, 909);
    scan
}

fn twin(scan: &Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dmap"))
        .arg("twin")
        .arg(scan)
        .args(OPTS)
        .args(extra)
        .output()
        .unwrap()
}

fn one_line_error(what: &str, out: &Output, needle: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{what}: {err}");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{what}: not one line: {err}"
    );
    assert!(err.contains(needle), "{what}: {err:?} lacks {needle:?}");
}

/// The ELF of the 9x9 run of [`OPTS`] (built and cached as `dmap twin`
/// builds it).
fn elf_9x9(dir: &Path) -> PathBuf {
    let scan = scan_in(dir, 9);
    #[derive(clap::Parser)]
    struct Emulate {
        #[command(flatten)]
        args: dmap::emulate::EmulateArgs,
    }
    let cli = [scan.to_str().unwrap()].into_iter().chain(OPTS);
    let parsed =
        <Emulate as clap::Parser>::try_parse_from(["emulate"].into_iter().chain(cli)).unwrap();
    let (file, _) = dmap::emulate::scan_file_and_warnings(&parsed.args).unwrap();
    let header = cvm_fw_app::emufile::ScanHeader::parse(&file).unwrap();
    dmap::twin::build_elf(&dmap::twin::h743_build_config(&header).unwrap()).unwrap()
}

#[test]
fn an_elf_built_for_another_run_is_refused_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let elf = elf_9x9(dir.path());
    let e = elf.to_str().unwrap();
    let scan9 = scan_in(dir.path(), 9);
    let scan7 = scan_in(dir.path(), 7);
    one_line_error(
        "7x7 scan",
        &twin(&scan7, &["--elf", e]),
        "built for j1=9, this run has j1=7",
    );
    let wider = dir.path().join("wider.npy");
    common::spot_scan(&wider, 6, 13, 9, 909);
    one_line_error(
        "size",
        &twin(&wider, &["--elf", e]),
        "cols=12, this run has cols=13",
    );
    // The run's settings come from its settings record: another
    // threshold and no score lines run on the same ELF, as on a board,
    // and print `dmap stream --from-flash`'s bytes.
    let scan9 = scan9.to_str().unwrap();
    let out = common::dmap_ok(&["twin", scan9, "--elf", e, "--threshold", "0.5"]);
    let host = common::dmap_ok(&["stream", scan9, "--from-flash", "--threshold", "0.5"]);
    assert!(
        out.stdout == host.stdout,
        "--- stream\n{}\n--- twin\n{}",
        String::from_utf8_lossy(&host.stdout),
        String::from_utf8_lossy(&out.stdout)
    );
    // With --flash the settings are compiled in, so every field counts:
    // this ELF has the build's default rows.
    let flash = dir.path().join("bank2.bin");
    one_line_error(
        "rows",
        &twin(
            Path::new(scan9),
            &["--elf", e, "--flash", flash.to_str().unwrap()],
        ),
        "built for rows=200, this run has rows=6",
    );
}

#[test]
fn a_damaged_elf_is_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let scan = scan_in(dir.path(), 9);
    let whole = std::fs::read(elf_9x9(dir.path())).unwrap();
    let cases: [(&str, Vec<u8>, &str); 4] = [
        ("empty", Vec::new(), "not an ELF file"),
        ("garbage", b"\x7fELF garbage".to_vec(), "truncated"),
        ("truncated", whole[..whole.len() / 2].to_vec(), "truncated"),
        (
            "host",
            std::fs::read("/proc/self/exe").unwrap()[..4096].to_vec(),
            "not a 32-bit",
        ),
    ];
    for (name, bytes, what) in cases {
        let bad = dir.path().join(format!("{name}.elf"));
        std::fs::write(&bad, bytes).unwrap();
        one_line_error(name, &twin(&scan, &["--elf", bad.to_str().unwrap()]), what);
    }
    let d = dir.path().to_str().unwrap();
    one_line_error("directory", &twin(&scan, &["--elf", d]), "is a directory");
    // An ELF without the configuration section (an older build).
    let mut stripped = whole.clone();
    let at = stripped
        .windows(11)
        .position(|w| w == b".cvm_config")
        .expect("the section's name");
    stripped[at + 1] = b'X';
    let old = dir.path().join("old.elf");
    std::fs::write(&old, stripped).unwrap();
    one_line_error(
        "old",
        &twin(&scan, &["--elf", old.to_str().unwrap()]),
        "does not say what it was built for",
    );
}

#[test]
fn the_chip_model_refuses_an_elf_it_cannot_load_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.elf");
    std::fs::write(&bad, b"garbage").unwrap();
    let out = Command::new("python3")
        .args(["-m", "h743twin"])
        .arg(&bad)
        .args(["--run-ms", "1"])
        .env(
            "PYTHONPATH",
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../twin"),
        )
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(4), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.starts_with("h743twin: cannot load the ELF"), "{err}");
}

#[test]
fn model_time_is_bounded_before_anything_is_built() {
    let dir = tempfile::tempdir().unwrap();
    let scan = scan_in(dir.path(), 9);
    for (what, extra) in [
        ("gap", &["--fault", "gap@10:1e9"][..]),
        ("halt", &["--fault", "halt@10:600001"][..]),
        ("beam", &["--beam-us", "1e9"][..]),
        ("start", &["--start-ms", "1e9"][..]),
        ("settle", &["--settle-ms", "1e9"][..]),
    ] {
        let started = std::time::Instant::now();
        one_line_error(what, &twin(&scan, extra), "more than the limit of 600 s");
        assert!(started.elapsed().as_secs() < 30, "{what}: refused late");
    }
}

#[test]
fn faults_that_would_do_nothing_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scan = scan_in(dir.path(), 9);
    for (spec, what) in [
        ("burst@0:0:10", "from 1"),
        ("burst@0:1000:1", "runs past the scan's last beam (71)"),
        ("sync-miss@5", "not a row start"),
        ("sync-glitch@0", "row start"),
    ] {
        one_line_error(spec, &twin(&scan, &["--fault", spec]), what);
    }
}

/// A scan whose end line never comes is a failed run, not a warning.
#[test]
fn a_scan_that_never_ends_exits_non_zero() {
    let dir = tempfile::tempdir().unwrap();
    let scan = scan_in(dir.path(), 9);
    let out = twin(&scan, &["--fault", "halt@60:3000", "--settle-ms", "0"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        !String::from_utf8_lossy(&out.stdout).contains("\nE,"),
        "an end line came"
    );
    let last = err.trim_end().lines().last().unwrap();
    assert!(
        last.contains("no complete end line") && last.contains("did not finish"),
        "{err}"
    );
    // The model's counters come just before, with its status.
    let counters = err.trim_end().lines().rev().nth(1).unwrap();
    let c: serde_json::Value = serde_json::from_str(counters).unwrap();
    assert_eq!(c["status"], "time", "{c}");
}

/// Pids of processes whose parent is `parent` and whose command line has
/// `needle`.
fn children(parent: u32, needle: &str) -> Vec<u32> {
    std::fs::read_dir("/proc")
        .unwrap()
        .flatten()
        .filter_map(|e| {
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
            (ppid == parent && String::from_utf8_lossy(&cmd).contains(needle)).then_some(pid)
        })
        .collect()
}

/// The model's lines come as the firmware sends them (the header while
/// the scan is still running), and no signal leaves the model behind:
/// SIGINT and SIGTERM are caught by dmap, which ends the model; SIGKILL
/// is not, and the kernel's parent-death signal ends it.
#[test]
fn twin_streams_and_its_model_dies_with_dmap_on_any_signal() {
    use std::os::unix::process::ExitStatusExt;
    let dir = tempfile::tempdir().unwrap();
    let scan = scan_in(dir.path(), 9);
    let elf = elf_9x9(dir.path());
    for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGKILL] {
        let mut dmap = Command::new(env!("CARGO_BIN_EXE_dmap"))
            .arg("twin")
            .arg(&scan)
            .args(OPTS)
            .arg("--elf")
            .arg(&elf)
            // A beam every 2 s: over two minutes of model time.
            .args(["--beam-us", "2000000"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut lines = BufReader::new(dmap.stdout.take().unwrap());
        let mut header = String::new();
        lines.read_line(&mut header).unwrap();
        assert!(header.starts_with("H,"), "{sig}: {header:?}");
        let model = children(dmap.id(), "h743twin");
        assert_eq!(model.len(), 1, "{sig}: the model runs on after the header");
        // SAFETY: kill(2) on the pid of our own child.
        assert_eq!(unsafe { libc::kill(dmap.id() as i32, sig) }, 0);
        let status = dmap.wait().unwrap();
        assert_eq!(status.signal(), Some(sig), "{status}");
        let gone = (0..300).any(|_| {
            std::thread::sleep(std::time::Duration::from_millis(10));
            !Path::new(&format!("/proc/{}", model[0])).exists()
        });
        assert!(gone, "{sig}: the model (pid {}) outlived dmap", model[0]);
    }
}
