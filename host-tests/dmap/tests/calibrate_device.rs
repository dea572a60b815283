//! The board's calibration and `dmap calibrate` give the same result: N
//! simulated defect-free scans streamed through one pipeline with a
//! calibrator attached and armed for N scans (what the board does on
//! `calibrate N`), against `dmap calibrate` of the same N scan files. The
//! board calibrates with its spread channel off (the compiled default) and
//! on: the same three thresholds, the spread one included.

use std::path::PathBuf;

use cvm_core::calibration::{Calibrator, Progress, Rule};
use cvm_core::command::Calibration;
use cvm_core::pipeline::{Pipeline, Settings};
use cvm_core::protocol::{LineSink, Priority};
use cvm_core::{Position, Scorer};

use crate::common;
use common::{calibration_of_file, dmap_ok, s};

fn tmp(name: &str) -> PathBuf {
    common::tmp_in("caldev", name)
}

#[derive(Default)]
struct Discard;

impl LineSink for Discard {
    fn line(&mut self, _line: &[u8], _priority: Priority) {}
}

/// A defect-free simulated part (`dmap simulate`), its samples and shape.
fn part(preset: &[&str], seed: u32) -> (PathBuf, Vec<u16>, usize, usize, usize) {
    let path = tmp(&format!("{}-s{seed}.npy", preset.join("-")));
    let mut args = vec!["simulate"];
    args.extend(preset);
    let seed = seed.to_string();
    args.extend(["--defect-free", "--seed", &seed, "-o", s(&path)]);
    dmap_ok(&args);
    let scan = dmap::npy::read_scan(&path).unwrap();
    let (rows, cols, j) = (scan.rows, scan.cols, scan.geometry.j1());
    (path, scan.to_u16().unwrap(), rows, cols, j)
}

/// The scans through one pipeline armed for all of them: the result the
/// board reports, checked to take exactly those scans.
fn on_the_board(
    scorer: &Scorer,
    (rows, cols): (usize, usize),
    spread_threshold: u32,
    scans: &[Vec<u16>],
) -> Calibration {
    let settings = Settings {
        cols: cols as u32,
        threshold: scorer.threshold_from_units(0.1),
        power_threshold: 3277,
        spread_threshold,
        scores: true,
        max_defect_lines_per_row: 4,
        rows: rows as u32,
        outputs: cvm_core::settings::Outputs::DEFAULT,
        sources: [cvm_core::settings::Source::Default; cvm_core::settings::KEYS],
    };
    let words = cvm_core::stream::row_words_for(cols, scorer.config());
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let mut cal = Box::new(Calibrator::new());
    let mut p = Box::new(
        Pipeline::<{ dmap::settings::MAX_COLS }>::new(scorer, settings, &mut a, &mut b).unwrap(),
    );
    p.attach_calibrator(&mut cal);
    let n = scans.len() as u16;
    p.calibrator_mut().unwrap().arm(n);
    let mut sink = Discard;
    for (i, data) in scans.iter().enumerate() {
        p.begin(&mut sink);
        for (k, frame) in data.chunks_exact(scorer.cells()).enumerate() {
            let pos = Position {
                row: (k / cols) as u32,
                col: (k % cols) as u32,
            };
            p.push(pos, frame, &mut sink);
        }
        p.finish(0, &mut sink);
        let taken = i as u16 + 1;
        let want = if taken == n {
            Progress::Done { taken }
        } else {
            Progress::Running { taken, target: n }
        };
        assert_eq!(p.calibrator().unwrap().progress(), want);
    }
    p.calibrator().unwrap().finish(&Rule::DEFAULT).unwrap()
}

#[test]
fn n_scans_on_the_board_and_dmap_calibrate_agree() {
    for (preset, n) in [
        (&["--preset", "prototype"][..], 5u32),
        (
            &[
                "--preset",
                "paper-sim",
                "--rows",
                "40",
                "--cols",
                "60",
                "--spot-um",
                "300",
            ][..],
            3,
        ),
    ] {
        let parts: Vec<_> = (0..n).map(|i| part(preset, 11 + i)).collect();
        let (_, _, rows, cols, j) = parts[0];
        let scorer = dmap::options::ScoringArgs::default().scorer(j, j).unwrap();
        let scans: Vec<Vec<u16>> = parts.iter().map(|p| p.1.clone()).collect();
        let off = cvm_core::spread::SPREAD_OFF;
        let board = on_the_board(&scorer, (rows, cols), off, &scans);
        assert_eq!(
            on_the_board(&scorer, (rows, cols), 3000, &scans),
            board,
            "{preset:?}: the spread channel on or off, the same calibration"
        );
        let cal = tmp(&format!("{}.json", preset.join("-")));
        let mut args = vec!["calibrate"];
        args.extend(parts.iter().map(|p| s(&p.0)));
        args.extend(["-o", s(&cal)]);
        dmap_ok(&args);
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&cal).unwrap()).unwrap();
        assert_eq!(calibration_of_file(&v), board, "{preset:?}");
        assert_eq!(board.scans, n as u16);
        assert_eq!(board.positions, n * (rows * cols) as u32);
        // Real thresholds: a power channel that is on, a CVM margin above
        // the references' maximum.
        assert!(board.power_threshold < cvm_core::power::POWER_MAX);
        assert!(board.mad > 0 && board.power_mad > 0, "{board:?}");
        // The spread measured though the board's channel was off.
        assert!(board.spread_mad > 0, "{board:?}");
        assert!(
            board.spread_threshold <= cvm_core::spread::SPREAD_MAX,
            "{board:?}"
        );
        let max = v["channels"]["cvm"]["integers"]["max"].as_u64().unwrap();
        assert!(u64::from(board.threshold) > max);
        // The file applied by dmap stream puts the board's integers in the
        // header.
        let out = dmap_ok(&["stream", s(&parts[0].0), "--calibration", s(&cal)]);
        let header = String::from_utf8_lossy(&out.stdout)
            .lines()
            .next()
            .unwrap()
            .to_string();
        assert!(
            header.contains(&format!(",thr={},", board.threshold))
                && header.contains(&format!(",pthr={},", board.power_threshold)),
            "{header}"
        );
    }
}
