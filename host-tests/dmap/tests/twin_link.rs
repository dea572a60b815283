//! `dmap twin --requests`: a requests file is checked against the scan
//! before anything runs. What the firmware does with the requests is
//! `twin_commands.rs`; the receiver and the flash interface of the chip
//! model are tested rule by rule in host-tests/twin/tests
//! (test_usart_rx.py, test_flash.py).

use cvm_reference::Geometry;
use dmap::npy::write_scan_u16;
use std::path::Path;
use std::process::Command;

const ROWS: usize = 4;
const COLS: usize = 10;
const J: usize = 9;

fn write_scan(path: &Path) {
    let mut state = 7u64;
    let mut data = Vec::with_capacity(ROWS * COLS * J * J);
    for i in 0..ROWS * COLS * J * J {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let blob = i / (J * J) == COLS + 3 && i % 2 == 0;
        data.push(500 + (state >> 33) as u16 % 300 + if blob { 6000 } else { 0 });
    }
    write_scan_u16(path, ROWS, COLS, Geometry::new(J, J).unwrap(), &data).unwrap();
}

#[test]
fn a_requests_file_must_start_at_beams_of_the_scan() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    write_scan(&scan);
    let req = dir.path().join("late.txt");
    std::fs::write(&req, format!("{} 0a\n", ROWS * COLS)).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(["twin", scan.to_str().unwrap(), "--requests"])
        .arg(&req)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("is not a beam of this scan (0..40)"), "{err}");
}
