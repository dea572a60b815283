//! The emulated firmware (QEMU mps2-an386) and the host pipeline print the
//! same bytes for the same scan and settings. Needs `qemu-system-arm` and
//! the `thumbv7em-none-eabihf` target (scripts/setup.sh installs
//! both).

use cvm_reference::Geometry;
use dmap::npy::write_scan_u16;
use std::io::Read;
use std::path::Path;
use std::process::{Command, Stdio};

/// A scan with a planted bright blob, a dark map and a saturated map,
/// over a random background.
fn write_scan(path: &Path, j1: usize, j2: usize, cols: usize, rows: usize, seed: u64) {
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
                    v = 0; // dark map
                }
                if (r, c) == (rows - 2, 1) {
                    v = u16::MAX; // saturated map
                }
                data.push(v);
            }
        }
    }
    write_scan_u16(path, rows, cols, Geometry::new(j1, j2).unwrap(), &data).unwrap();
}

fn dmap(args: &[&str]) -> Vec<u8> {
    let out = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(args)
        .output()
        .expect("running dmap");
    assert!(
        out.status.success(),
        "dmap {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout
}

fn compare(name: &str, j1: usize, j2: usize, cols: usize, rows: usize, extra: &[&str]) {
    let dir = std::env::temp_dir().join(format!("dmap-emulate-test-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scan = dir.join("scan.npy");
    write_scan(&scan, j1, j2, cols, rows, cols as u64 * 31 + rows as u64);
    let scan = scan.to_str().unwrap();
    let mut args = vec![scan, "--scores", "--threshold", "0.05"];
    args.extend_from_slice(extra);
    let host = dmap(&[&["stream"], &args[..]].concat());
    let target = dmap(&[&["emulate"], &args[..]].concat());
    let _ = std::fs::remove_dir_all(&dir);
    let text = String::from_utf8(host.clone()).unwrap();
    assert!(
        text.starts_with("H,") && text.contains("\nE,"),
        "unexpected stream output: {text}"
    );
    assert!(
        text.lines().any(|l| l.starts_with("O,")),
        "the planted defect must show as an object"
    );
    if extra.contains(&"--max-defect-lines") {
        assert!(
            text.lines().any(|l| l.starts_with("D,")),
            "defect lines were asked for"
        );
    }
    assert!(
        host == target,
        "emulated firmware and host pipeline differ for {name}:\n--- stream\n{text}\n--- emulate\n{}",
        String::from_utf8_lossy(&target)
    );
}

#[test]
fn emulated_firmware_matches_host_pipeline_paper_9x9() {
    compare("paper9", 9, 9, 23, 9, &["--max-defect-lines", "4"]);
}

/// The spread channel on: its threshold reaches the emulated board through
/// the scan file's header and decides there as on the host.
#[test]
fn emulated_firmware_matches_host_pipeline_with_the_spread_channel() {
    let sthr = ["--spread-threshold", "0.002", "--max-defect-lines", "4"];
    compare("spread9", 9, 9, 23, 9, &sthr);
    // And the threshold is not idle: it changes the scan's lines.
    let dir = std::env::temp_dir().join(format!("dmap-emulate-test-{}-sthr", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scan = dir.join("scan.npy");
    write_scan(&scan, 9, 9, 23, 9, 23 * 31 + 9);
    let scan = scan.to_str().unwrap();
    let base = [scan, "--threshold", "0.05", "--max-defect-lines", "4"];
    let off = dmap(&[&["stream"], &base[..]].concat());
    let on = dmap(&[&["stream"], &base[..], &sthr[..2]].concat());
    let _ = std::fs::remove_dir_all(&dir);
    assert_ne!(off, on, "the spread threshold changed nothing");
}

#[test]
fn emulated_firmware_matches_host_pipeline_square_raw_15x15() {
    compare("square15", 15, 15, 17, 7, &["--kernels", "square", "--raw"]);
}

#[test]
fn emulated_firmware_matches_host_pipeline_non_square_unit_weights() {
    compare(
        "unit5x7",
        5,
        7,
        40,
        6,
        &["--weights", "unit", "--bmax", "3"],
    );
}

/// The largest square kernels' factor table (16x16, four blocks of 64
/// cells), normalised maps.
#[test]
fn emulated_firmware_matches_host_pipeline_square_16x16() {
    compare("square16", 16, 16, 9, 5, &["--kernels", "square"]);
}

/// The Cortex-M row and column passes are generated per axis length
/// (`cvm-core/src/scorer/embed/passes/passes_arm.s`): `j1 x (17 - j1)` runs each of the
/// 16 row passes and the 16 column passes once, on the board's code.
#[test]
fn emulated_firmware_matches_host_pipeline_every_axis_length() {
    every_axis_length("paper", &[]);
}

/// The square kernels' embedding loop on every block shape that
/// `j1 x (17 - j1)` folds into (odd and even axes, empty odd blocks of
/// one-cell axes, rows of 1 to 64 coefficients).
#[test]
fn emulated_firmware_matches_host_pipeline_square_every_axis_length() {
    every_axis_length("square", &["--kernels", "square"]);
}

fn every_axis_length(label: &str, extra: &[&str]) {
    for j1 in 1..=16 {
        let j2 = 17 - j1;
        let dir = std::env::temp_dir().join(format!(
            "dmap-emulate-axes-{label}-{}-{j1}",
            std::process::id()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        let scan = dir.join("scan.npy");
        write_scan(&scan, j1, j2, 7, 4, j1 as u64);
        let scan = scan.to_str().unwrap();
        let args = [&[scan, "--scores", "--threshold", "0.05"], extra].concat();
        let host = dmap(&[&["stream"], &args[..]].concat());
        let target = dmap(&[&["emulate"], &args[..]].concat());
        let _ = std::fs::remove_dir_all(&dir);
        let text = String::from_utf8(host.clone()).unwrap();
        // The rows' score lines (encoded scores), not all the same.
        let scores: std::collections::BTreeSet<&str> = text
            .lines()
            .filter(|l| l.starts_with("S,"))
            .filter_map(|l| l.split(',').nth(3))
            .collect();
        assert!(
            scores.len() >= 2,
            "{j1}x{j2}: the score lines do not vary:\n{text}"
        );
        assert!(
            host == target,
            "{j1}x{j2}: emulated firmware and host pipeline differ:\n--- stream\n{text}\n--- emulate\n{}",
            String::from_utf8_lossy(&target)
        );
    }
}

/// Running `qemu-system-arm` processes whose command line mentions `needle`.
fn qemu_processes(needle: &str) -> Vec<u32> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(cmdline) = std::fs::read(entry.path().join("cmdline")) else {
            continue;
        };
        let cmdline = String::from_utf8_lossy(&cmdline);
        if cmdline.starts_with("qemu-system-arm") && cmdline.contains(needle) {
            out.push(pid);
        }
    }
    out
}

/// `dmap emulate` with its temporary files in a directory of the test's
/// own, so that its QEMU can be told from any other.
fn emulate_in(name: &str, rows: usize) -> (std::path::PathBuf, Command) {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("emulate-edges-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    let tmp = dir.join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    let scan = dir.join("scan.npy");
    // Enough score lines (about 2 kB a row) to outlast a pipe's buffer.
    write_scan(&scan, 9, 9, 300, rows, 5);
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_dmap"));
    cmd.args(["emulate", "--scores", "--threshold", "0.05"])
        .arg(&scan)
        .env("TMPDIR", &tmp);
    (tmp, cmd)
}

/// Nothing of a run is left: no QEMU, no scan file.
fn assert_nothing_left(tmp: &Path) {
    let needle = tmp.to_str().unwrap();
    assert_eq!(
        qemu_processes(needle),
        Vec::<u32>::new(),
        "QEMU outlived dmap"
    );
    let left: Vec<_> = std::fs::read_dir(tmp).unwrap().flatten().collect();
    assert!(left.is_empty(), "temporary files left: {left:?}");
}

/// Standard output on a full disk: a one-line error, QEMU gone with it.
#[test]
fn emulate_to_a_full_stdout_leaves_no_qemu() {
    let (tmp, mut cmd) = emulate_in("full", 60);
    let full = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .unwrap();
    let out = cmd.stdout(full).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("No space left on device"), "{err}");
    assert_nothing_left(&tmp);
}

/// `dmap emulate ... | head -c 100`: a quiet exit 141, QEMU gone with it.
#[test]
fn emulate_into_a_closed_pipe_leaves_no_qemu() {
    let (tmp, mut cmd) = emulate_in("pipe", 200);
    let mut child = cmd.stdout(Stdio::piped()).spawn().unwrap();
    let mut stdout = child.stdout.take().unwrap();
    let mut first = [0u8; 100];
    stdout.read_exact(&mut first).unwrap();
    assert!(first.starts_with(b"H,"));
    drop(stdout);
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(141));
    assert_nothing_left(&tmp);
}

/// SIGTERM while QEMU runs (and dmap is blocked writing to a pipe nobody
/// reads): dmap kills and reaps QEMU, removes its scan file, and dies of
/// the signal.
#[test]
fn emulate_terminated_by_a_signal_leaves_no_qemu() {
    use std::os::unix::process::ExitStatusExt;
    let (tmp, mut cmd) = emulate_in("signal", 200);
    let mut child = cmd.stdout(Stdio::piped()).spawn().unwrap();
    let mut stdout = child.stdout.take().unwrap();
    let mut first = [0u8; 100];
    stdout.read_exact(&mut first).unwrap();
    let qemu = qemu_processes(tmp.to_str().unwrap());
    assert_eq!(qemu.len(), 1, "one QEMU while the run goes on");
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let status = child.wait().unwrap();
    assert_eq!(status.signal(), Some(15), "{status}");
    assert!(
        !Path::new(&format!("/proc/{}", qemu[0])).exists(),
        "QEMU still there"
    );
    assert_nothing_left(&tmp);
    drop(stdout);
}

/// Killed by SIGINT or SIGKILL while QEMU runs: QEMU goes with dmap. On
/// SIGKILL dmap cannot act; the kernel's parent-death signal ends QEMU
/// (its scan file, which dmap would have removed, stays behind).
#[test]
fn emulate_killed_by_any_signal_leaves_no_qemu() {
    use std::os::unix::process::ExitStatusExt;
    for (sig, name) in [(libc::SIGINT, "sigint"), (libc::SIGKILL, "sigkill")] {
        let (tmp, mut cmd) = emulate_in(name, 200);
        let mut child = cmd.stdout(Stdio::piped()).spawn().unwrap();
        let mut stdout = child.stdout.take().unwrap();
        let mut first = [0u8; 100];
        stdout.read_exact(&mut first).unwrap();
        let qemu = qemu_processes(tmp.to_str().unwrap());
        assert_eq!(qemu.len(), 1, "{name}: one QEMU while the run goes on");
        // SAFETY: kill(2) on the pid of our own child.
        assert_eq!(unsafe { libc::kill(child.id() as i32, sig) }, 0);
        let status = child.wait().unwrap();
        assert_eq!(status.signal(), Some(sig), "{name}: {status}");
        // The parent-death signal is delivered as the parent exits: allow
        // the kernel a moment to reap.
        let gone = (0..200).any(|_| {
            std::thread::sleep(std::time::Duration::from_millis(10));
            qemu_processes(tmp.to_str().unwrap()).is_empty()
        });
        assert!(gone, "{name}: QEMU (pid {}) outlived dmap", qemu[0]);
        if sig != libc::SIGKILL {
            assert_nothing_left(&tmp);
        }
        drop(stdout);
    }
}

/// A damaged or foreign ELF is one error line before QEMU starts (QEMU
/// itself dumps its registers, or waits forever on a truncated one).
#[test]
fn emulate_refuses_a_damaged_elf_in_one_line() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("emulate-bad-elf");
    std::fs::create_dir_all(&dir).unwrap();
    let scan = dir.join("scan.npy");
    write_scan(&scan, 9, 9, 300, 2, 5);
    let elf = dmap::emulate::build_elf().unwrap();
    let whole = std::fs::read(&elf).unwrap();
    let cases: [(&str, Vec<u8>, &str); 4] = [
        ("empty", Vec::new(), "not an ELF file"),
        (
            "garbage",
            b"garbage, not a firmware".to_vec(),
            "not an ELF file",
        ),
        ("truncated", whole[..whole.len() / 3].to_vec(), "truncated"),
        (
            "host",
            std::fs::read("/proc/self/exe").unwrap()[..4096].to_vec(),
            "not a 32-bit",
        ),
    ];
    for (name, bytes, what) in cases {
        let bad = dir.join(format!("{name}.elf"));
        std::fs::write(&bad, bytes).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_dmap"))
            .args(["emulate", "--elf"])
            .arg(&bad)
            .arg(&scan)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{name}: {err}");
        assert_eq!(err.lines().count(), 1, "{name}: {err}");
        assert!(err.contains(what), "{name}: {err}");
    }
}
