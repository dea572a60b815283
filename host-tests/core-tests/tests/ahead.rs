//! What the pipeline tells its sink ahead of the lines (`Ahead`): a board
//! drives REJECT from it before it encodes the lines, so it must say what
//! the lines then say. Checked against the lines themselves, parsed back:
//! each row's news comes before its row line and counts the objects that
//! count among the object lines after it; the scan's verdict and its end
//! come before the last two rows' lines and carry the end line's verdict,
//! the verdict before the labeller has run over those rows whenever the
//! totals decide it.

use cvm_core::Position;
use cvm_core::pipeline::{Pipeline, Settings};
use cvm_core::protocol::{Line, LineSink, Priority, parse};
use cvm_core::settings::Outputs;
use cvm_core::verdict::{Ahead, counts};
use cvm_core_tests::{random_scan, rng};

enum Rec {
    Line(Vec<u8>),
    Ahead(Ahead),
}

#[derive(Default)]
struct Recorder(Vec<Rec>);

impl LineSink for Recorder {
    fn line(&mut self, line: &[u8], _priority: Priority) {
        self.0.push(Rec::Line(line.to_vec()));
    }
    fn ahead(&mut self, news: Ahead) {
        self.0.push(Rec::Ahead(news));
    }
}

fn settings(rows: usize, cols: usize, thresholds: (u32, u32), outputs: Outputs) -> Settings {
    Settings {
        cols: cols as u32,
        threshold: thresholds.0,
        power_threshold: thresholds.1,
        spread_threshold: cvm_core::spread::SPREAD_OFF,
        scores: true,
        max_defect_lines_per_row: 4,
        rows: rows as u32,
        outputs,
        sources: [cvm_core::settings::Source::Default; cvm_core::settings::KEYS],
    }
}

/// One scan through the pipeline: what the sink got, in order.
fn run(s: Settings, j: usize, data: &[u16], lost: Option<usize>) -> Vec<Rec> {
    let scorer = dmap::options::ScoringArgs::default().scorer(j, j).unwrap();
    let cols = s.cols as usize;
    let words = cvm_core::stream::row_words_for(cols, scorer.config());
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let mut p = Box::new(Pipeline::<64>::new(&scorer, s, &mut a, &mut b).unwrap());
    let mut sink = Recorder::default();
    p.begin(&mut sink);
    for (i, f) in data.chunks_exact(j * j).enumerate() {
        let pos = Position {
            row: (i / cols) as u32,
            col: (i % cols) as u32,
        };
        if lost == Some(i) {
            p.mark_missing(pos, &mut sink);
        } else {
            p.push(pos, f, &mut sink);
        }
    }
    p.finish(0, &mut sink);
    sink.0
}

#[test]
fn news_ahead_of_the_lines_says_what_the_lines_say() {
    let mut r = rng(77);
    let mut objects_seen = 0;
    let mut rejects = 0;
    for case in 0..24 {
        let (rows, cols, j) = (2 + case % 7, 3 + case % 5, 3 + case % 2);
        let scorer = dmap::options::ScoringArgs::default().scorer(j, j).unwrap();
        // Thresholds low enough that most scans have objects of all
        // sizes, and one in four too high for any.
        let thresholds = match case % 4 {
            3 => (u32::MAX, cvm_core::power::POWER_OFF),
            k => (
                scorer.threshold_from_units(0.05 * (k + 1) as f64),
                cvm_core::power::threshold_from_units(0.05),
            ),
        };
        let outputs = Outputs {
            min_area: (case % 3) as u32,
            ..Outputs::DEFAULT
        };
        let data = random_scan(&mut r, rows, cols, j, j);
        let lost = (case % 5 == 0).then_some(case % (rows * cols));
        let recs = run(settings(rows, cols, thresholds, outputs), j, &data, lost);

        // Walk the records: news, then lines.
        let mut row_news: Vec<(u32, u32)> = Vec::new();
        let mut end_news = None;
        // The verdict's news: its value and how many row news came before.
        let mut verdict_news = Vec::new();
        let mut end_news_at_row = None;
        let mut row_lines = 0u32;
        // Counting objects after each row line (index: rows out so far).
        let mut counted_after = vec![0u32; rows + 1];
        let mut end_verdict = None;
        for rec in &recs {
            match rec {
                Rec::Ahead(Ahead::Verdict(v)) => {
                    assert!(end_news.is_none(), "case {case}: verdict after the end");
                    verdict_news.push((*v, row_news.len()));
                }
                Rec::Ahead(Ahead::Row { rows: n, closed }) => row_news.push((*n, *closed)),
                Rec::Ahead(Ahead::End { closed, verdict }) => {
                    end_news = Some((*closed, *verdict));
                    end_news_at_row = Some(row_lines);
                }
                Rec::Line(l) => match parse(l).unwrap() {
                    Line::Row { summary, .. } => {
                        assert_eq!(summary.row, row_lines, "case {case}");
                        // Its news came first.
                        assert!(row_news.len() > row_lines as usize, "case {case}");
                        row_lines += 1;
                    }
                    Line::Object(o) => {
                        if counts(&o, &outputs) {
                            counted_after[row_lines as usize] += 1;
                        }
                        objects_seen += 1;
                    }
                    Line::End(e) => end_verdict = Some(e.verdict),
                    _ => {}
                },
            }
        }
        assert_eq!(row_lines as usize, rows, "case {case}");
        // One news per row, numbered by the rows then out.
        let numbers: Vec<u32> = row_news.iter().map(|n| n.0).collect();
        assert_eq!(
            numbers,
            (1..=rows as u32).collect::<Vec<_>>(),
            "case {case}"
        );
        // Each row's closures are the counting objects after its lines
        // (the last row's lines are followed by the end's closures too).
        let (end_closed, verdict) = end_news.expect("no news of the scan's end");
        for (k, &(_, closed)) in row_news.iter().enumerate() {
            let extra = if k + 1 == rows { end_closed } else { 0 };
            assert_eq!(counted_after[k + 1], closed + extra, "case {case} row {k}");
        }
        assert_eq!(Some(verdict), end_verdict, "case {case}");
        // The verdict once, the same; before the labeller's news of the
        // last rows when the rules let every object count (area 0 or 1:
        // every object has one position, and the peak of a defect).
        assert_eq!(verdict_news.len(), 1, "case {case}");
        assert_eq!(verdict_news[0].0, verdict, "case {case}");
        let before_last_rows = rows - rows.min(2);
        if outputs.min_area <= 1 || verdict.is_fault() {
            assert_eq!(verdict_news[0].1, before_last_rows, "case {case}");
        } else {
            assert!(verdict_news[0].1 >= before_last_rows, "case {case}");
        }
        // The scan's news came before the last two rows' lines.
        assert_eq!(
            end_news_at_row,
            Some(rows.saturating_sub(2) as u32),
            "case {case}"
        );
        rejects += verdict.rejects() as u32;
    }
    // The cases covered both verdicts and had objects to count.
    assert!(
        objects_seen >= 10 && rejects > 0 && rejects < 24,
        "{objects_seen} {rejects}"
    );
}
