//! The emulated firmware (QEMU mps2-an386) and the host pipeline print the
//! same bytes for the same scan and settings. Needs `qemu-system-arm` and
//! the `thumbv7em-none-eabihf` target (scripts/emulate-setup.sh installs
//! both).

use cvm_reference::Geometry;
use dmap::npy::write_scan_u16;
use std::path::Path;
use std::process::Command;

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
        text.lines().any(|l| l.starts_with("D,")),
        "the planted defect must show"
    );
    assert!(
        host == target,
        "emulated firmware and host pipeline differ for {name}:\n--- stream\n{text}\n--- emulate\n{}",
        String::from_utf8_lossy(&target)
    );
}

#[test]
fn emulated_firmware_matches_host_pipeline_paper_9x9() {
    compare("paper9", 9, 9, 23, 9, &[]);
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
