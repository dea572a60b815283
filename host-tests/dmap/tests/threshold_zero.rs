//! A threshold of 0 on either channel: every position with data is a defect
//! of that channel with strength `u32::MAX`, `dmap listen` accepts the
//! stream as undamaged, and the emulated firmware and the H743 release
//! firmware on the chip model write the same bytes as the host pipeline.
//! (Before, positions of magnitude 0 were reported with strength 0, and
//! `dmap listen` rejected the firmware's own lines.)

use crate::common;

use common::{ok, tmp_in};
use cvm_reference::Geometry;
use dmap::listen::Decoder;
use dmap::npy::write_scan_u16;

fn dmap(args: &[&str]) -> Vec<u8> {
    let out = common::dmap(args);
    ok(&out);
    out.stdout
}

/// A flat scan (every map the same: every CVM and power magnitude is 0)
/// with one brighter map, so that both zero and non-zero magnitudes occur.
fn write_flat_scan(path: &std::path::Path, rows: usize, cols: usize) {
    let cells = 9 * 9;
    let mut data = Vec::with_capacity(rows * cols * cells);
    for r in 0..rows {
        for c in 0..cols {
            for k in 0..cells {
                let bright = (r, c) == (rows / 2, cols / 2) && k % 3 == 0;
                data.push(if bright { 4000 } else { 700 + (k % 5) as u16 });
            }
        }
    }
    write_scan_u16(path, rows, cols, Geometry::new(9, 9).unwrap(), &data).unwrap();
}

fn field(line: &str, i: usize) -> u64 {
    line.split(['*', ','])
        .nth(i)
        .and_then(|f| f.parse().ok())
        .unwrap_or_else(|| panic!("field {i} of {line}"))
}

#[test]
fn threshold_zero_defects_have_full_strength_and_decode_cleanly() {
    let scan = tmp_in("thr0", "flat.npy");
    let (rows, cols) = (5, 7);
    write_flat_scan(&scan, rows, cols);
    let scan = scan.to_str().unwrap();
    for channel in [["--threshold", "0"], ["--power-threshold", "0"]] {
        // 16 defect lines a row: the H743 build's largest (this scan's
        // rows have 7 positions).
        let mut args = vec![scan, "--scores", "--max-defect-lines", "16"];
        args.extend_from_slice(&channel);
        let host = dmap(&[&["stream"], &args[..]].concat());
        let text = String::from_utf8(host.clone()).unwrap();

        // Every position is a defect (this scan has no dark or saturated
        // map), and each D line's strength is u32::MAX.
        let d_lines: Vec<&str> = text.lines().filter(|l| l.starts_with("D,")).collect();
        assert_eq!(d_lines.len(), rows * cols, "{channel:?}: {text}");
        let zero_mag = d_lines
            .iter()
            .filter(|l| field(l, if channel[0] == "--threshold" { 3 } else { 4 }) == 0)
            .count();
        assert!(
            zero_mag > 0,
            "the flat scan must have magnitude-0 positions"
        );
        for l in &d_lines {
            assert_eq!(field(l, 6), u32::MAX as u64, "{channel:?}: {l}");
        }
        for l in text.lines().filter(|l| l.starts_with("O,")) {
            assert!(l.contains(&format!(",{},", u32::MAX)), "object peak: {l}");
        }

        let mut d = Decoder::new();
        for line in host.split_inclusive(|&b| b == b'\n') {
            d.feed(line);
        }
        d.finish();
        assert_eq!(d.damage(), Vec::<String>::new(), "{channel:?}");

        let target = dmap(&[&["emulate"], &args[..]].concat());
        assert!(
            host == target,
            "emulated firmware and host differ at {channel:?}:\n{text}\n---\n{}",
            String::from_utf8_lossy(&target)
        );
        // The chip model for the distance channel (one more build; the
        // power channel's strength is the same function).
        if channel[0] == "--threshold" {
            // Its firmware boots with the run's settings saved in flash,
            // and its header says so.
            let host = dmap(&[&["stream", "--from-flash"], &args[..]].concat());
            let chip = dmap(&[&["twin"], &args[..]].concat());
            assert!(
                host == chip,
                "the H743 firmware and host differ at {channel:?}:\n{text}\n---\n{}",
                String::from_utf8_lossy(&chip)
            );
        }
    }
    let _ = std::fs::remove_file(scan);
}
