//! `dmap twin --requests`, `--flash` and `--power-cut` with today's
//! release firmware, which leaves USART3's receiver off and never writes
//! flash: whatever a host sends is lost in the receiver (counted), the
//! result lines stay byte-identical to `dmap stream`'s, bank 2 comes back
//! from the run as it went in, and no power cut fires. The receiver and
//! the flash interface themselves are tested rule by rule in
//! host-tests/twin/tests (test_usart_rx.py, test_flash.py).

mod common;

use common::dmap_ok as dmap;
use cvm_reference::Geometry;
use dmap::npy::write_scan_u16;
use dmap::twin_requests::write_requests;
use std::path::Path;
use std::process::{Command, Output};

const ROWS: usize = 4;
const COLS: usize = 10;
const J: usize = 9;
const BANK2: usize = 1 << 20;

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

fn counters(out: &Output) -> serde_json::Value {
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.lines().rfind(|l| !l.trim().is_empty()).unwrap_or("");
    serde_json::from_str(last).unwrap_or_else(|e| panic!("no JSON counters ({e}) in:\n{err}"))
}

/// CRC-16/CCITT-FALSE, bit by bit.
fn crc(data: &[u8]) -> u16 {
    let mut c: u16 = 0xFFFF;
    for &b in data {
        c ^= (b as u16) << 8;
        for _ in 0..8 {
            c = if c & 0x8000 != 0 {
                (c << 1) ^ 0x1021
            } else {
                c << 1
            };
        }
    }
    c
}

#[test]
fn requests_and_flash_leave_todays_firmware_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    write_scan(&scan);
    let scan = scan.to_str().unwrap();
    let opts = ["--scores", "--threshold", "0.05"];
    let host = dmap(&[&["stream", scan][..], &opts].concat());

    // 25 status requests at beam 0, queued on the line back to back, and
    // one damaged burst at beam 5: all of it reaches the receiver before
    // the scan ends (10.85 µs a byte, 200 µs a beam, 40 beams).
    let mut first = Vec::new();
    for id in 0..25u32 {
        let body = format!("C,{id},status");
        first.extend_from_slice(format!("{body}*{:04X}\n", crc(body.as_bytes())).as_bytes());
    }
    let req = dir.path().join("requests.txt");
    write_requests(&req, &[(0, &first)]).unwrap();
    let damaged = "5 432c312c73617665 fe@2 ne@4\n";
    let mut text = std::fs::read_to_string(&req).unwrap();
    text.push_str(damaged);
    std::fs::write(&req, text).unwrap();
    let sent = first.len() + 8;
    assert!(
        sent * 4340 < 40 * 80_000,
        "all bytes arrive within the scan"
    );

    let flash = dir.path().join("bank2.bin");
    let req = req.to_str().unwrap();
    let flash_s = flash.to_str().unwrap();
    let twin_args = [
        &["twin", scan][..],
        &opts,
        &["--requests", req, "--flash", flash_s, "--power-cut", "1"],
    ]
    .concat();
    let twin = dmap(&twin_args);
    assert!(
        twin.stdout == host.stdout,
        "requests changed the result lines:\n--- stream\n{}\n--- twin\n{}",
        String::from_utf8_lossy(&host.stdout),
        String::from_utf8_lossy(&twin.stdout)
    );
    let c = counters(&twin);
    assert_eq!(c["status"], "done", "{c}");
    assert_eq!(c["beams"], (ROWS * COLS) as u64, "{c}");
    assert_eq!(c["uart_rx_lost_while_off"], sent as u64, "{c}");
    assert_eq!(c["uart_rx_bytes"], 0, "{c}");
    assert_eq!(c["flash_operations"], 0, "{c}");

    // Bank 2 went out as it came in: erased cells, no word programmed.
    let bank = std::fs::read(&flash).unwrap();
    assert_eq!(bank.len(), BANK2 + BANK2 / 32);
    assert!(bank[..BANK2].iter().all(|&b| b == 0xFF));
    assert!(bank[BANK2..].iter().all(|&b| b == 0));

    // A second run on the same flash file: a reboot with the flash kept.
    let again = dmap(&[&["twin", scan][..], &opts, &["--flash", flash_s]].concat());
    assert_eq!(again.stdout, host.stdout);
    assert_eq!(std::fs::read(&flash).unwrap(), bank);
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
