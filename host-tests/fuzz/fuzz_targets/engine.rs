//! The streaming engine and line encoder (`cvm_core::Pipeline`) fed
//! arbitrary beam sequences: positions out of order, gaps, repeats, jumps,
//! frames of the wrong length, dark, saturated and random frames, explicit
//! missing positions, and scans finished at any point, under any
//! configuration the scorer accepts.
//!
//! Checked against a model that knows only the documented rules (a frame is
//! accepted iff it lies after the last accepted position in raster order,
//! within `cols` and within `MAX_ROW_JUMP` rows):
//! - nothing panics, every emitted line parses with a valid CRC;
//! - rows are emitted in order `0, 1, 2, ...`, each as soon as the row below
//!   it is complete, each with exactly `cols` positions;
//! - every position is where it was sent: data where a frame was scored,
//!   `NO_DATA` everywhere else, dark and saturated flags from the frame;
//! - row lines agree with their score lines, the end line with everything.
#![no_main]

use cvm_core::RowSummary;
use cvm_core::config::{Config, Geometry, Kernels, Weights};
use cvm_core::flags;
use cvm_core::pipeline::{Pipeline, Settings};
use cvm_core::protocol::{self, Line, LineSink, Priority};
use cvm_core::stream::{MAX_ROW_JUMP, Position, PushOutcome, Totals, row_words_for};
use libfuzzer_sys::arbitrary::{Result, Unstructured};
use libfuzzer_sys::fuzz_target;
use std::collections::HashMap;

const MAX_COLS: usize = 12;
/// Keeps an input's work bounded when it asks for many row jumps.
const MAX_ROWS: u32 = 4 * MAX_ROW_JUMP;

#[derive(Default)]
struct Lines(Vec<Vec<u8>>);

impl LineSink for Lines {
    fn line(&mut self, line: &[u8], priority: Priority) {
        let is_score = line.first() == Some(&b'S');
        assert_eq!(
            priority == Priority::Droppable,
            is_score,
            "priority of a line"
        );
        self.0.push(line.to_vec());
    }
}

/// What the model expects at a position.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Expect {
    /// A scored frame with these flags (`DARK`, `SATURATED`).
    Data(u8),
    NoData,
}

/// A row line and what has arrived since: scores by column, defect lines.
struct RowLines {
    summary: RowSummary,
    listed: u32,
    scores: Vec<Option<(u32, u16, u32, u8)>>,
    defect_lines: u32,
}

/// One scan as the model sees it.
#[derive(Default)]
struct Model {
    /// Last accepted position.
    last: Option<Position>,
    at: HashMap<(u32, u32), Expect>,
    /// Rows emitted so far (the next must be this one).
    emitted: u32,
    /// The row being assembled from its lines.
    row: Option<RowLines>,
    frames: u32,
    bad: u32,
    rejected: u32,
    extra: u32,
    dark: u32,
    saturated: u32,
    defects: u32,
    /// Object lines of the scan, and their defective positions.
    objects: u32,
    object_area: u64,
}

struct Run<'s> {
    cols: u32,
    threshold: u32,
    power_threshold: u32,
    spread_threshold: u32,
    scores: bool,
    max_defects: u32,
    full_scale: u16,
    cells: usize,
    jumped: bool,
    model: Model,
    pipeline: Pipeline<'s, MAX_COLS>,
}

impl Run<'_> {
    fn expected_row(&self) -> u32 {
        match self.model.last {
            None => 0,
            Some(l) if l.col + 1 == self.cols => l.row + 1,
            Some(l) => l.row,
        }
    }

    /// Whether the engine must accept a beam at `pos` (documented rules).
    fn accepts(&self, pos: Position) -> bool {
        let after = match self.model.last {
            None => true,
            Some(l) => (pos.row, pos.col) > (l.row, l.col),
        };
        pos.col < self.cols && after && pos.row - self.expected_row().min(pos.row) <= MAX_ROW_JUMP
    }

    fn position(&mut self, u: &mut Unstructured) -> Result<Position> {
        let next = match self.model.last {
            None => Position { row: 0, col: 0 },
            Some(l) if l.col + 1 == self.cols => Position {
                row: l.row + 1,
                col: 0,
            },
            Some(l) => Position {
                row: l.row,
                col: l.col + 1,
            },
        };
        let base = self.model.last.map_or(0, |l| l.row);
        Ok(match u.int_in_range(0..=15u8)? {
            // In order, the common case.
            0..=8 => next,
            // Anywhere near: gaps, repeats, out of order, one column too far.
            9..=12 => Position {
                row: u.int_in_range(base.saturating_sub(1)..=base + 2)?,
                col: u.int_in_range(0..=self.cols)?,
            },
            // A later row, at any column (a row start anywhere).
            13 => Position {
                row: base + u.int_in_range(1..=3)?,
                col: u.int_in_range(0..=self.cols - 1)?,
            },
            // Around the largest accepted jump (its empty rows are costly:
            // at most one per input).
            14 if !self.jumped && base + 2 * MAX_ROW_JUMP < MAX_ROWS => Position {
                row: {
                    self.jumped = true;
                    self.expected_row() + MAX_ROW_JUMP + u.int_in_range(0..=1)?
                },
                col: u.int_in_range(0..=self.cols - 1)?,
            },
            // Far away.
            _ => Position {
                row: u.arbitrary()?,
                col: u.arbitrary()?,
            },
        })
    }

    fn frame(&self, u: &mut Unstructured) -> Result<Vec<u16>> {
        let len = match u.int_in_range(0..=15u8)? {
            0 => self.cells - 1,
            1 => self.cells + 1,
            2 => u.int_in_range(0..=300)?,
            _ => self.cells,
        };
        Ok(match u.int_in_range(0..=4u8)? {
            0 => vec![0; len],
            1 => {
                let mut f: Vec<u16> = (0..len)
                    .map(|_| u.int_in_range(0..=2000))
                    .collect::<Result<_>>()?;
                if len > 0 {
                    let k = u.choose_index(len)?;
                    f[k] = *u.choose(&[self.full_scale, u16::MAX])?;
                }
                f
            }
            2 => vec![u.arbitrary()?; len],
            _ => (0..len).map(|_| u.arbitrary()).collect::<Result<_>>()?,
        })
    }

    /// Expected flags of a frame the scorer accepts.
    fn flags_of(&self, f: &[u16]) -> u8 {
        let mut fl = 0;
        if f.iter().all(|&a| a == 0) {
            fl |= flags::DARK;
        }
        if f.iter().any(|&a| a >= self.full_scale) {
            fl |= flags::SATURATED;
        }
        fl
    }

    fn place(&mut self, pos: Position, frame: Option<&[u16]>, lines: &mut Lines) {
        let accepts = self.accepts(pos);
        let outcome = match frame {
            Some(f) => self.pipeline.push(pos, f, lines),
            None => self.pipeline.mark_missing(pos, lines),
        };
        let want = if pos.col >= self.cols {
            PushOutcome::Extra
        } else if !accepts {
            PushOutcome::Rejected
        } else if frame.is_some_and(|f| f.len() != self.cells) {
            PushOutcome::Bad
        } else {
            PushOutcome::Scored
        };
        assert_eq!(
            outcome, want,
            "outcome of {pos:?} after {:?}",
            self.model.last
        );
        let m = &mut self.model;
        match outcome {
            PushOutcome::Extra => m.extra += 1,
            PushOutcome::Rejected => m.rejected += 1,
            PushOutcome::Bad => {
                m.bad += 1;
                m.at.insert((pos.row, pos.col), Expect::NoData);
            }
            PushOutcome::Scored => {
                let e = match frame {
                    Some(f) => {
                        m.frames += 1;
                        Expect::Data(self.flags_of(f))
                    }
                    None => Expect::NoData,
                };
                self.model.at.insert((pos.row, pos.col), e);
            }
        }
        if matches!(outcome, PushOutcome::Scored | PushOutcome::Bad) {
            self.model.last = Some(pos);
        }
        self.check_lines(lines, false);
        // A row is final, and out, once the row below it is complete.
        let done = match self.model.last {
            Some(l) if l.col + 1 == self.cols => l.row,
            Some(l) => l.row.saturating_sub(1),
            None => 0,
        };
        assert!(self.model.emitted >= done, "row {} held back", done - 1);
    }

    fn expect(&self, row: u32, col: u32) -> Expect {
        self.model
            .at
            .get(&(row, col))
            .copied()
            .unwrap_or(Expect::NoData)
    }

    fn has_data(&self, row: Option<u32>, col: Option<u32>) -> bool {
        match (row, col) {
            (Some(r), Some(c)) if c < self.cols => matches!(self.expect(r, c), Expect::Data(_)),
            _ => false,
        }
    }

    /// Checks the lines emitted since the last call.
    fn check_lines(&mut self, lines: &mut Lines, end: bool) {
        for l in std::mem::take(&mut lines.0) {
            let text = String::from_utf8_lossy(&l).into_owned();
            assert!(l.len() <= protocol::MAX_LINE, "line too long: {text}");
            let parsed = protocol::parse(&l).unwrap_or_else(|e| panic!("{e:?}: {text}"));
            match parsed {
                Line::Header(h) => {
                    assert_eq!(
                        (h.cols, h.threshold, h.scores),
                        (self.cols, self.threshold, self.scores)
                    );
                }
                Line::Row { summary, listed } => {
                    self.close_row();
                    assert_eq!(summary.row, self.model.emitted, "rows out of order");
                    assert!(
                        end || self.model.last.is_some_and(|l| l.row > summary.row),
                        "row {} emitted before it was final",
                        summary.row
                    );
                    assert_eq!(listed, summary.defects.min(self.max_defects));
                    self.model.emitted += 1;
                    self.model.row = Some(RowLines {
                        summary,
                        listed,
                        scores: vec![None; self.cols as usize],
                        defect_lines: 0,
                    });
                }
                Line::Defect {
                    row,
                    col,
                    mag,
                    pmag,
                    smag,
                    flags: fl,
                    ..
                } => {
                    let r = self.model.row.as_mut().expect("defect line outside a row");
                    assert_eq!(row, r.summary.row);
                    r.defect_lines += 1;
                    let fired = (
                        mag >= self.threshold,
                        u32::from(pmag) >= self.power_threshold,
                        smag >= self.spread_threshold,
                    );
                    assert!(
                        fired.0 || fired.1 || fired.2,
                        "a defect line below every threshold"
                    );
                    assert_eq!(fl & flags::CVM_DEFECT != 0, fired.0);
                    assert_eq!(fl & flags::POWER_DEFECT != 0, fired.1);
                    assert_eq!(fl & flags::SPREAD_DEFECT != 0, fired.2);
                    assert!(fl & flags::NO_DATA == 0);
                    assert!(matches!(self.expect(row, col), Expect::Data(_)));
                }
                Line::Scores { row, col0, chars } => {
                    assert!(self.scores);
                    let r = self.model.row.as_mut().expect("score line outside a row");
                    assert_eq!(row, r.summary.row);
                    for (k, c) in chars.chunks(protocol::SCORE_CHARS).enumerate() {
                        let slot = &mut r.scores[col0 as usize + k];
                        assert!(slot.is_none(), "position sent twice");
                        *slot = protocol::decode_score(c).map(|v| (v.mag, v.pmag, v.smag, v.flags));
                    }
                }
                Line::Object(o) => {
                    // After the lines of its last row, never before.
                    assert!(o.row1 < self.model.emitted, "object {o:?} before its rows");
                    assert!(
                        o.area as u64
                            <= (o.row1 - o.row0 + 1) as u64 * (o.col1 - o.col0 + 1) as u64
                    );
                    assert!(o.col1 < self.cols && o.channels != 0);
                    assert!((o.row0..=o.row1).contains(&o.peak_row));
                    assert!((o.col0..=o.col1).contains(&o.peak_col));
                    assert!(
                        o.peak >= 1 << 16
                            || self.threshold == 0
                            || self.power_threshold == 0
                            || self.spread_threshold == 0
                    );
                    self.model.objects += 1;
                    self.model.object_area += u64::from(o.area);
                }
                Line::End(e) => {
                    self.close_row();
                    let m = &self.model;
                    let t = e.totals;
                    // Every defective position is in exactly one object or counted.
                    assert_eq!(t.objects, m.objects);
                    assert_eq!(
                        m.object_area + u64::from(t.unobjected),
                        u64::from(t.defects)
                    );
                    assert_eq!(t.rows, m.emitted);
                    assert_eq!(t.frames, m.frames);
                    assert_eq!(
                        t.frames + t.missing,
                        m.emitted * self.cols,
                        "positions lost"
                    );
                    assert_eq!((t.bad, t.rejected, t.extra), (m.bad, m.rejected, m.extra));
                    assert_eq!(t.misplaced, 0, "the engine misplaced a frame");
                    if self.scores {
                        assert_eq!(
                            (t.dark, t.saturated, t.defects),
                            (m.dark, m.saturated, m.defects)
                        );
                    }
                    assert_eq!(t.clipped, 0);
                }
            }
        }
    }

    /// The row assembled so far is complete: check it against the model.
    fn close_row(&mut self) {
        let Some(RowLines {
            summary: s,
            listed,
            scores: got,
            defect_lines,
        }) = self.model.row.take()
        else {
            return;
        };
        let r = s.row;
        let mut no_data = 0;
        if !self.scores {
            for c in 0..self.cols {
                no_data += u32::from(self.expect(r, c) == Expect::NoData);
            }
            assert_eq!(s.no_data, no_data);
            return;
        }
        let (mut dark, mut sat, mut defects, mut max, mut argmax) = (0, 0, 0, 0, None);
        for (c, v) in got.iter().enumerate() {
            let c = c as u32;
            let (mag, pmag, smag, fl) = v.unwrap_or_else(|| panic!("row {r} col {c} has no score"));
            match self.expect(r, c) {
                Expect::NoData => {
                    assert_eq!(
                        fl & flags::NO_DATA,
                        flags::NO_DATA,
                        "({r}, {c}) must be empty"
                    );
                    assert_eq!((mag, pmag, smag, fl & flags::DEFECT), (0, 0, 0, 0));
                    no_data += 1;
                }
                Expect::Data(want) => {
                    assert_eq!(
                        fl & (flags::NO_DATA | flags::DARK | flags::SATURATED),
                        want,
                        "flags of ({r}, {c})"
                    );
                    let alone = !self.has_data(Some(r), c.checked_sub(1))
                        && !self.has_data(Some(r), Some(c + 1))
                        && !self.has_data(r.checked_sub(1), Some(c))
                        && !self.has_data(Some(r + 1), Some(c));
                    if alone {
                        assert_eq!(mag, 0, "a map without neighbours is its own neighbour");
                        assert_eq!(pmag, 0, "a map without neighbours is its own neighbour");
                        assert_eq!(smag, 0, "a map without neighbours is its own neighbour");
                    }
                    assert!(u32::from(pmag) <= cvm_core::power::POWER_MAX);
                    assert!(smag <= cvm_core::spread::SPREAD_MAX);
                    // A channel that is off measures nothing.
                    if self.spread_threshold == cvm_core::spread::SPREAD_OFF {
                        assert_eq!(smag, 0, "({r}, {c}): the spread channel is off");
                    }
                    let fired = (
                        mag >= self.threshold,
                        u32::from(pmag) >= self.power_threshold,
                        smag >= self.spread_threshold,
                    );
                    assert_eq!(fl & flags::CVM_DEFECT != 0, fired.0, "({r}, {c})");
                    assert_eq!(fl & flags::POWER_DEFECT != 0, fired.1, "({r}, {c})");
                    assert_eq!(fl & flags::SPREAD_DEFECT != 0, fired.2, "({r}, {c})");
                    dark += u32::from(fl & flags::DARK != 0);
                    sat += u32::from(fl & flags::SATURATED != 0);
                    defects += u32::from(fired.0 || fired.1 || fired.2);
                    if argmax.is_none() || mag > max {
                        (max, argmax) = (mag, Some(c));
                    }
                }
            }
        }
        assert_eq!(
            (s.no_data, s.dark, s.saturated, s.defects, s.max, s.argmax),
            (no_data, dark, sat, defects, max, argmax),
            "row line of row {r}"
        );
        assert_eq!(defect_lines, listed);
        self.model.dark += dark;
        self.model.saturated += sat;
        self.model.defects += defects;
    }

    fn finish(&mut self, dropped: u32, lines: &mut Lines) -> Totals {
        let t = self.pipeline.finish(dropped, lines);
        // Every row up to the last accepted one is emitted, no further.
        let last = self.model.last.map_or(0, |l| l.row + 1);
        self.check_lines(lines, true);
        assert_eq!(self.model.emitted, last);
        assert_eq!(t.rows, last);
        self.model = Model::default();
        t
    }
}

fn config(u: &mut Unstructured) -> Result<Config> {
    let big = u.ratio(1, 8)?;
    let top = if big { 16 } else { 5 };
    let g =
        Geometry::new(u.int_in_range(1..=top)?, u.int_in_range(1..=top)?).expect("axes in range");
    let kernels = if u.arbitrary()? {
        Kernels::Paper {
            bmax: u.int_in_range(0..=g.j1.max(g.j2))?,
        }
    } else {
        Kernels::Square {
            kmax: u.int_in_range(0..=g.j1.max(g.j2) - 1)?,
        }
    };
    Ok(Config {
        geometry: g,
        kernels,
        weights: *u.choose(&[Weights::Uniform, Weights::Unit])?,
        normalise: u.ratio(3, 4)?,
        // 1 at the least: the header's `fs` range, which every tool keeps.
        full_scale: *u.choose(&[u16::MAX, 4095, 1000, 1])?,
    })
}

fn step(run: &mut Run, u: &mut Unstructured, lines: &mut Lines) -> Result<()> {
    match u.int_in_range(0..=15u8)? {
        0..=11 => {
            let pos = run.position(u)?;
            let f = run.frame(u)?;
            run.place(pos, Some(&f), lines);
        }
        12..=13 => {
            let pos = run.position(u)?;
            run.place(pos, None, lines);
        }
        14 => {
            let dropped = u.arbitrary()?;
            let t = run.finish(dropped, lines);
            assert_eq!(*run.pipeline.totals(), Totals::default(), "{t:?} not reset");
            run.pipeline.begin(lines);
            run.check_lines(lines, false);
        }
        _ => assert_eq!(run.pipeline.totals().frames, run.model.frames),
    }
    Ok(())
}

fn run(u: &mut Unstructured) -> Result<()> {
    let cfg = config(u)?;
    let Ok(scorer) = dmap::fixed::scorer(&cfg) else {
        return Ok(());
    };
    let cols = u.int_in_range(1..=MAX_COLS as u32)?;
    let threshold = if u.arbitrary()? {
        u.arbitrary()?
    } else {
        u.int_in_range(0..=1 << 16)?
    };
    // Power thresholds across the channel's range, and off.
    let power_threshold = match u.int_in_range(0..=3)? {
        0 => cvm_core::power::POWER_OFF,
        1 => u.int_in_range(0..=64)?,
        _ => u.int_in_range(0..=cvm_core::power::POWER_MAX + 1)?,
    };
    // Spread thresholds across the channel's range, and off.
    let spread_threshold = match u.int_in_range(0..=3)? {
        0 => cvm_core::spread::SPREAD_OFF,
        1 => u.int_in_range(0..=64)?,
        _ => u.int_in_range(0..=cvm_core::spread::SPREAD_MAX + 1)?,
    };
    // Drawn in the order the corpus was made with.
    let scores = u.ratio(7, 8)?;
    let max_defect_lines_per_row = u.int_in_range(0..=4)?;
    let boot = cvm_core::Boot {
        firmware: "fuzz",
        reset_cause: cvm_core::protocol::ResetCause::ALL[u.int_in_range(0..=4)?],
        boots: u.int_in_range(1..=u32::MAX)?,
        store: cvm_core::settings::Store::Empty,
    };
    let settings = Settings {
        cols,
        threshold,
        power_threshold,
        spread_threshold,
        scores,
        max_defect_lines_per_row,
        rows: 1,
        outputs: cvm_core::settings::Outputs::DEFAULT,
        sources: [cvm_core::settings::Source::Default; cvm_core::settings::KEYS],
    };
    let cells = scorer.cells();
    let words = row_words_for(cols as usize, scorer.config());
    let (mut a, mut b) = (vec![0; words], vec![0; words]);
    let mut pipeline =
        Pipeline::<MAX_COLS>::new(&scorer, settings, &mut a, &mut b).expect("pipeline");
    pipeline.set_boot(boot);
    let mut run = Run {
        cols,
        threshold,
        power_threshold,
        spread_threshold,
        scores: settings.scores,
        max_defects: u32::from(settings.max_defect_lines_per_row),
        full_scale: cfg.full_scale,
        cells,
        jumped: false,
        model: Model::default(),
        pipeline,
    };
    let mut lines = Lines::default();
    run.pipeline.begin(&mut lines);
    run.check_lines(&mut lines, false);
    // Input running out ends the scan where it is: the final flush is checked too.
    for _ in 0..256 {
        if u.is_empty() || step(&mut run, u, &mut lines).is_err() {
            break;
        }
    }
    run.finish(0, &mut lines);
    Ok(())
}

fuzz_target!(|data: &[u8]| {
    let _ = run(&mut Unstructured::new(data));
});
