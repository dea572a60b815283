//! Helpers shared by the dmap integration tests.
// Each test file uses its own subset.
#![allow(dead_code)]

pub mod console;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A `.npy` file built by hand from the format description (version 1.0:
/// magic, version, little-endian header length, a Python dict literal padded
/// with spaces to a 64-byte boundary, then the raw data), independent of the
/// crate the tool reads with.
pub fn raw_npy(descr: &str, fortran: bool, shape: &[usize], data: &[u8]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let order = if fortran { "True" } else { "False" };
    let mut header =
        format!("{{'descr': '{descr}', 'fortran_order': {order}, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend((header.len() as u16).to_le_bytes());
    out.extend(header.as_bytes());
    out.extend(data);
    out
}

/// Runs the built `dmap` binary.
pub fn dmap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(args)
        .output()
        .expect("run dmap")
}

/// Runs the built `dmap` binary and requires it to succeed (its arguments
/// and stderr shown otherwise).
pub fn dmap_ok(args: &[&str]) -> Output {
    let out = dmap(args);
    assert!(
        out.status.success(),
        "dmap {args:?} failed ({}):\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A path `name` in a per-process scratch directory of the test file `tag`.
pub fn tmp_in(tag: &str, name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("dmap-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The command succeeded (its stderr shown otherwise).
pub fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A defect-free scan of `rows x cols` positions: a spot drifting across a
/// `j x j` detector
/// with pseudo-random noise (a 64-bit LCG).
pub fn spot_scan(path: &Path, rows: usize, cols: usize, j: usize, seed: u64) {
    let mut x = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
    let mut data = Vec::new();
    for r in 0..rows {
        for c in 0..cols {
            let (cy, cx) = (
                1.0 + r as f64 * (j as f64 - 3.0) / rows as f64,
                1.0 + c as f64 * (j as f64 - 3.0) / cols as f64,
            );
            for a in 0..j {
                for b in 0..j {
                    x = x
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    let noise = (x >> 54) as f64;
                    let d2 = (a as f64 - cy).powi(2) + (b as f64 - cx).powi(2);
                    data.push((3000.0 * (-d2).exp() + noise / 16.0).round() as u16);
                }
            }
        }
    }
    let g = cvm_reference::Geometry::new(j, j).unwrap();
    dmap::npy::write_scan_u16(path, rows, cols, g, &data).unwrap();
}

/// CRC-16/CCITT-FALSE, bit by bit (polynomial 0x1021, initial 0xFFFF):
/// the line checksum computed independently of the crate's table.
pub fn crc16_bitwise(data: &[u8]) -> u16 {
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

/// `body*XXXX\n`, framed with [`crc16_bitwise`].
pub fn framed(body: &str) -> Vec<u8> {
    format!("{body}*{:04X}\n", crc16_bitwise(body.as_bytes())).into_bytes()
}

/// What `dmap calibrate` wrote in a calibration file, in the terms of the
/// board's `calibrated` reply.
pub fn calibration_of_file(v: &serde_json::Value) -> cvm_core::command::Calibration {
    let int = |ch: &str, k: &str| v["channels"][ch]["integers"][k].as_u64().unwrap() as u32;
    let thr = |ch: &str| v["channels"][ch]["thr"].as_u64().unwrap() as u32;
    cvm_core::command::Calibration {
        scans: v["scans"].as_u64().unwrap() as u16,
        positions: v["channels"]["cvm"]["positions"].as_u64().unwrap() as u32,
        threshold: thr("cvm"),
        power_threshold: thr("power"),
        median: int("cvm", "median"),
        mad: int("cvm", "mad"),
        power_median: int("power", "median"),
        power_mad: int("power", "mad"),
        spread_threshold: thr("spread"),
        spread_median: int("spread", "median"),
        spread_mad: int("spread", "mad"),
        // The tail rule's target; 0 for the spread rule, which has none.
        rate_ppm: v["rule"]["rate_ppm"].as_u64().unwrap_or(0) as u32,
    }
}

/// The chip model's counters: the last JSON object `dmap twin` printed on
/// standard error.
pub fn counters(out: &Output) -> serde_json::Value {
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.lines().rfind(|l| l.starts_with('{')).unwrap_or("");
    serde_json::from_str(last).unwrap_or_else(|e| panic!("no JSON counters ({e}) in:\n{err}"))
}

/// A `rows` x `cols` scan of `j` x `j` maps of low noise with one bright
/// blob, in beam `cols + 3` (row 1): an object that closes early. The
/// noise comes from a linear congruential generator started at `seed`.
pub fn blob_scan(path: &Path, rows: usize, cols: usize, j: usize, seed: u64) {
    let mut state = seed;
    let mut data = Vec::with_capacity(rows * cols * j * j);
    for i in 0..rows * cols * j * j {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let blob = i / (j * j) == cols + 3 && i % 2 == 0;
        data.push(500 + (state >> 33) as u16 % 300 + if blob { 6000 } else { 0 });
    }
    dmap::npy::write_scan_u16(
        path,
        rows,
        cols,
        cvm_reference::Geometry::new(j, j).unwrap(),
        &data,
    )
    .unwrap();
}

/// `out` failed with one line on standard error that contains `needle`,
/// and no panic.
pub fn one_line_error(out: &Output, needle: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "expected failure: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
    assert!(err.contains(needle), "{err:?} lacks {needle:?}");
    assert!(!err.contains("panicked"));
}

/// Defect-free maps: a flat field with a little noise (`beams` maps of
/// `cells` samples).
pub fn flat_samples(beams: usize, cells: usize, seed: u64) -> Vec<u16> {
    let mut state = seed;
    (0..beams * cells)
        .map(|_| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            600 + (state >> 33) as u16 % 8
        })
        .collect()
}

/// A scan in the chip model's own format (`CVMTWIN1`, then rows, cols, J1
/// and J2 as u32 and the samples as u16, little-endian), as `dmap twin`
/// writes it for `python3 -m h743twin --scan`.
pub fn write_twin_scan(path: &Path, rows: usize, cols: usize, j: usize, data: &[u16]) {
    let mut file = b"CVMTWIN1".to_vec();
    for v in [rows, cols, j, j] {
        file.extend_from_slice(&(v as u32).to_le_bytes());
    }
    for v in data {
        file.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(path, file).unwrap();
}

/// The demo scan in `dir` (`demo.npy`, its truth in `truth.npy`): dmap
/// simulate's prototype lens, 39 x 39 beams of 9x9 maps with two defects,
/// as `scripts/demo.sh` makes it.
pub fn demo_scan(dir: &Path) -> PathBuf {
    let scan = dir.join("demo.npy");
    dmap_ok(&[
        "simulate",
        "--preset",
        "prototype",
        "--seed",
        "1",
        "-o",
        s(&scan),
        "--truth",
        s(&dir.join("truth.npy")),
    ]);
    scan
}

/// The repository's conformance vectors (docs/protocol/vectors).
pub fn vectors_dir() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../docs/protocol/vectors"
    ))
}

/// The entries of the conformance vectors' `index.json`.
pub fn vectors_index() -> Vec<serde_json::Value> {
    let path = vectors_dir().join("index.json");
    let index: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    index.as_array().unwrap().clone()
}

/// A vector of `index.json` that changes one field of its base stream
/// (its `changes`, `TYPE.name`).
pub struct OneField {
    pub name: String,
    pub base: String,
    /// The line type's letter, `TYPE`.
    pub kind: String,
    pub field: String,
}

/// Every one-field vector of the index, in its order.
pub fn one_field_vectors() -> Vec<OneField> {
    vectors_index()
        .iter()
        .filter_map(|e| {
            let (kind, field) = e["changes"].as_str()?.split_once('.').unwrap();
            Some(OneField {
                name: e["name"].as_str().unwrap().to_string(),
                base: e["base"].as_str().unwrap().to_string(),
                kind: kind.to_string(),
                field: field.to_string(),
            })
        })
        .collect()
}
