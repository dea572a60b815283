//! The pipeline's output as a whole: a header with the settings, one row
//! line per row in order (with its score lines when they are on), and an
//! end line with the scan's totals, every line parsed back by the
//! protocol's own decoder and compared with the engine run alone over the
//! same beams (`run_engine_with`), not with the pipeline itself.

use cvm_core::Position;
use cvm_core::pipeline::{Pipeline, Settings};
use cvm_core::protocol::{self, Line, LineSink, Priority, ResetCause, decode_score, parse};
use cvm_core_tests::{random_scan, rng, run_engine_with};

#[derive(Default)]
struct Lines(Vec<Vec<u8>>);

impl LineSink for Lines {
    fn line(&mut self, line: &[u8], _priority: Priority) {
        self.0.push(line.to_vec());
    }
}

#[test]
fn header_rows_and_end_match_the_engine() {
    let mut r = rng(5);
    for (case, &(rows, cols, j, scores, missing)) in [
        (4usize, 6usize, 3usize, true, false),
        (5, 7, 4, false, false),
        (3, 5, 3, true, true),
        (1, 1, 2, true, false),
    ]
    .iter()
    .enumerate()
    {
        let scorer = dmap::options::ScoringArgs::default().scorer(j, j).unwrap();
        let threshold = scorer.threshold_from_units(0.02);
        let power_threshold = cvm_core::power::threshold_from_units(0.05);
        let settings = Settings {
            cols: cols as u32,
            threshold,
            power_threshold,
            spread_threshold: cvm_core::spread::SPREAD_OFF,
            scores,
            max_defect_lines_per_row: 3,
            rows: rows as u32,
            outputs: cvm_core::settings::Outputs::DEFAULT,
            sources: [cvm_core::settings::Source::Default; cvm_core::settings::KEYS],
        };
        let data = random_scan(&mut r, rows, cols, j, j);
        let n = j * j;
        // The beams: every position in order, one of them marked missing.
        let frames: Vec<(Position, Option<Vec<u16>>)> = data
            .chunks_exact(n)
            .enumerate()
            .map(|(i, f)| {
                let pos = Position {
                    row: (i / cols) as u32,
                    col: (i % cols) as u32,
                };
                let lost = missing && i == cols + 1;
                (pos, (!lost).then(|| f.to_vec()))
            })
            .collect();
        let (want_rows, want_totals) =
            run_engine_with(&scorer, cols, threshold, power_threshold, &frames);

        let words = cvm_core::stream::row_words_for(cols, scorer.config());
        let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
        let mut p = Box::new(Pipeline::<64>::new(&scorer, settings, &mut a, &mut b).unwrap());
        let boot = cvm_core::Boot {
            firmware: "pipeline-test",
            reset_cause: ResetCause::Watchdog,
            boots: 7,
            store: cvm_core::settings::Store::Empty,
        };
        p.set_boot(boot);
        let mut sink = Lines::default();
        p.begin(&mut sink);
        for (pos, f) in &frames {
            match f {
                Some(f) => p.push(*pos, f, &mut sink),
                None => p.mark_missing(*pos, &mut sink),
            };
        }
        p.count_misplaced(2);
        let totals = p.finish(9, &mut sink);

        let lines: Vec<Line> = sink
            .0
            .iter()
            .map(|l| parse(l).unwrap_or_else(|e| panic!("{e:?}: {}", String::from_utf8_lossy(l))))
            .collect();
        // The engine's totals, with the misplaced count handed in and the
        // objects the pipeline reported (its labeller's own count; the
        // objects themselves are tested in objects.rs).
        let objects = lines
            .iter()
            .filter(|l| matches!(l, Line::Object(_)))
            .count();
        let mut want_end = want_totals;
        want_end.misplaced = 2;
        want_end.objects = objects as u32;
        assert_eq!(totals, want_end, "case {case}");
        let Some(Line::Header(h)) = lines.first() else {
            panic!("case {case}: no header first: {:?}", lines.first());
        };
        assert_eq!(
            h,
            &cvm_core::protocol::HeaderInfo::new(&scorer, &settings, &boot)
        );
        assert_eq!(
            (
                h.cols,
                h.threshold,
                h.power_threshold,
                h.scores,
                h.boots,
                h.firmware
            ),
            (
                cols as u32,
                threshold,
                power_threshold,
                scores,
                7,
                "pipeline-test"
            )
        );
        assert_eq!(
            (h.j1, h.j2, h.q),
            (j as u8, j as u8, scorer.score_frac_bits())
        );
        let Some(Line::End(end)) = lines.last() else {
            panic!("case {case}: no end line last");
        };
        assert_eq!((end.totals, end.dropped), (want_end, 9), "case {case}");

        // Rows in order, each equal to the engine's summary; score lines
        // (when on) carry the engine's scores of that row.
        let mut row_lines = 0;
        let mut scored = vec![0usize; rows];
        for line in &lines[1..lines.len() - 1] {
            match *line {
                Line::Row { summary, .. } => {
                    assert_eq!(
                        summary, want_rows[row_lines].0,
                        "case {case} row {row_lines}"
                    );
                    row_lines += 1;
                }
                Line::Scores { row, col0, chars } => {
                    assert!(scores, "case {case}: score lines while off");
                    let want = &want_rows[row as usize].1;
                    for (k, c) in chars.chunks_exact(protocol::SCORE_CHARS).enumerate() {
                        let s = decode_score(c).unwrap();
                        let w = &want[col0 as usize + k];
                        assert_eq!(
                            (s.flags, s.mag, s.pmag, s.smag),
                            (w.flags, w.mag, w.pmag, w.smag)
                        );
                        scored[row as usize] += 1;
                    }
                }
                Line::Header(_) | Line::End(_) => panic!("case {case}: a second header or end"),
                Line::Defect { .. } | Line::Object(_) => {}
            }
        }
        assert_eq!(row_lines, rows, "case {case}");
        let want_scored = if scores { cols } else { 0 };
        assert!(
            scored.iter().all(|&s| s == want_scored),
            "case {case}: {scored:?}"
        );
    }
}
