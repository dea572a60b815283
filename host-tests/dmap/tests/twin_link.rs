//! `dmap twin --requests`: a requests file is checked against the scan
//! before anything runs. What the firmware does with the requests is
//! `twin_commands.rs`; the receiver and the flash interface of the chip
//! model are tested rule by rule in host-tests/twin/tests
//! (test_usart_rx.py, test_flash.py).

use crate::common;

use std::process::Command;

const ROWS: usize = 4;
const COLS: usize = 10;
const J: usize = 9;

#[test]
fn a_requests_file_must_start_at_beams_of_the_scan() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    common::blob_scan(&scan, ROWS, COLS, J, 7);
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
