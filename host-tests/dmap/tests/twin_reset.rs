//! The reset cause and the start count in the header (`rst`, `boots`) of
//! the H743 release firmware on the chip model: `por` and 1 after
//! power-on; after the watchdog resets a wedged firmware, the next scan's
//! header says `wdg` and 2, and `dmap listen` reports both. Needs what
//! tests/twin.rs needs (python3 with unicorn and pyelftools, the
//! `thumbv7em-none-eabihf` target).

use cvm_reference::Geometry;
use dmap::listen::Decoder;
use dmap::npy::write_scan_u16;
use std::process::Command;

#[test]
fn header_counts_a_watchdog_reset() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    let (rows, cols, j) = (30, 9, 3);
    let mut state = 7u64;
    let data: Vec<u16> = (0..rows * cols * j * j)
        .map(|_| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            500 + (state >> 33) as u16 % 300
        })
        .collect();
    write_scan_u16(&scan, rows, cols, Geometry::new(j, j).unwrap(), &data).unwrap();
    // Beam 20 wedges the firmware; the watchdog resets it about a second
    // later, while the beams (8 ms apart) still come: a second scan starts.
    let out = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(["twin", scan.to_str().unwrap(), "--beam-us", "8000"])
        .args(["--fault", "wedge@20"])
        .output()
        .expect("running dmap twin");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let mut dec = Decoder::new();
    for line in out.stdout.split_inclusive(|&b| b == b'\n') {
        dec.feed(line);
    }
    dec.finish();
    let starts: Vec<(Option<&str>, u32)> = dec
        .scans
        .iter()
        .map(|s| (s.reset_cause.map(|c| c.as_str()), s.boots))
        .collect();
    assert_eq!(
        starts,
        [(Some("por"), 1), (Some("wdg"), 2)],
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}
