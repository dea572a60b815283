//! `score` and `stream` hold a band of rows, not the scan: their peak
//! resident memory on an 81 MB scan (600 x 600 positions of 15 x 15
//! `uint8` samples) stays a fraction of a byte per sample. Alone in its
//! test binary, so that the peak of the children waited for is theirs.

mod common;

use std::io::Write;
use std::path::Path;
use std::process::Command;

/// Largest resident set among the children waited for so far, in bytes.
fn children_peak_rss() -> u64 {
    // SAFETY: getrusage only fills the struct it is given.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    assert_eq!(
        unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage) },
        0
    );
    usage.ru_maxrss as u64 * 1024
}

#[test]
fn score_and_stream_peak_memory_is_a_fraction_of_the_scan() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("score_memory");
    std::fs::create_dir_all(&dir).unwrap();
    let (rows, cols, j) = (600usize, 600usize, 15usize);
    let samples = rows * cols * j * j;
    // A pattern that moves with the column, so that the maps differ;
    // written a row at a time, so that this process stays small (the peak
    // of a child counts its start, a copy of this process).
    let scan = dir.join("scan.npy");
    let mut file = std::io::BufWriter::new(std::fs::File::create(&scan).unwrap());
    file.write_all(&common::raw_npy("|u1", false, &[rows, cols, j, j], &[]))
        .unwrap();
    let mut row = Vec::with_capacity(cols * j * j);
    for _ in 0..rows {
        row.clear();
        for c in 0..cols {
            for k in 0..j * j {
                row.push(((k * 7 + c * 3) % 200) as u8);
            }
        }
        file.write_all(&row).unwrap();
    }
    file.flush().unwrap();
    drop(file);
    let out = dir.join("grad.npy");
    // Whole-scan processing held about 16 bytes per sample (1.3 GB here).
    let limit = samples as u64 / 2;
    for args in [
        vec!["score", "--distance", "cvm"],
        vec!["score", "--distance", "cvm-fixed"],
        vec!["stream", "--scores"],
    ] {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_dmap"));
        cmd.args(&args).arg(&scan);
        if args[0] == "score" {
            cmd.arg("-o").arg(&out);
        }
        let run = cmd.output().unwrap();
        assert!(
            run.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&run.stderr)
        );
        let peak = children_peak_rss();
        // The figure (cargo test -- --nocapture shows it).
        eprintln!(
            "{args:?}: peak resident {peak} bytes, {:.3} per sample (so far in this run)",
            peak as f64 / samples as f64
        );
        assert!(
            peak < limit,
            "{args:?}: peak {peak} bytes for {samples} samples ({:.3} per sample)",
            peak as f64 / samples as f64
        );
        if args[0] == "score" {
            let g = dmap::npy::read_gradient(&out).unwrap();
            assert_eq!((g.rows, g.cols), (rows, cols));
        } else {
            let text = String::from_utf8_lossy(&run.stdout);
            assert_eq!(text.lines().filter(|l| l.starts_with("R,")).count(), rows);
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
