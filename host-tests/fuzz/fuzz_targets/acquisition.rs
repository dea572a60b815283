//! The firmware's acquisition layer on arbitrary inputs:
//!
//! 1. The LINE_SYNC `Sequencer` on arbitrary beams (with or without
//!    LINE_SYNC, read or lost) and end-of-data at any point: scans open and
//!    close in turn, positions stay inside the scan and strictly increase in
//!    raster order, every frame is placed or discarded exactly once, the
//!    misplaced frames reported add up to the counter, and the beam counts
//!    add up.
//! 2. The whole board path (DRDY bookkeeping with two buffers and a small
//!    beam log, SPI completions and errors, the scoring driver, the output
//!    queue and a UART that stalls) on arbitrary event sequences: every line
//!    sent parses, no keep line is dropped, each scan has all its rows in
//!    order, and the end lines account for every beam, misplaced frame and
//!    dropped line.
#![no_main]

use cvm_core::protocol::{self, Line, SCORES_PER_LINE};
use cvm_core::stream::Position;
use cvm_fw_app::sequence::{Action, Payload, Sequencer};
use cvm_fw_app_tests::{Board, Scan};
use libfuzzer_sys::arbitrary::{Result, Unstructured};
use libfuzzer_sys::fuzz_target;
use std::collections::HashSet;

/// Checks the actions of a sequencer as they come.
struct SeqCheck {
    cols: u32,
    rows: u32,
    open: bool,
    last: Option<Position>,
    seen: HashSet<u32>,
    misplaced: u32,
}

impl SeqCheck {
    fn act(&mut self, a: Action<u32>) {
        match a {
            Action::Begin => {
                assert!(!self.open, "scan begun twice");
                self.open = true;
                self.last = None;
            }
            Action::Finish => {
                assert!(self.open, "scan finished twice");
                self.open = false;
            }
            Action::Place(p, _) | Action::Missing(p) => {
                assert!(self.open, "position outside a scan");
                assert!(
                    p.row < self.rows && p.col < self.cols,
                    "{p:?} outside the scan"
                );
                if let Some(l) = self.last {
                    assert!((p.row, p.col) > (l.row, l.col), "{p:?} after {l:?}");
                }
                self.last = Some(p);
            }
            Action::Discard(_) => {}
            Action::Misplaced(n) => {
                assert!(self.open, "misplaced frames outside a scan");
                assert!(
                    n > 0 && n < self.cols,
                    "{n} misplaced of {} columns",
                    self.cols
                );
                self.misplaced += n;
            }
        }
        if let Action::Place(_, h) | Action::Discard(h) = a {
            assert!(self.seen.insert(h), "frame {h} used twice");
        }
    }
}

fn sequencer(u: &mut Unstructured) -> Result<()> {
    let cols = u.int_in_range(0..=6)?;
    let rows = u.int_in_range(0..=4)?;
    let mut seq = Sequencer::<u32>::new(cols, rows);
    let mut check = SeqCheck {
        cols: cols.max(1),
        rows: rows.max(1),
        open: false,
        last: None,
        seen: HashSet::new(),
        misplaced: 0,
    };
    let mut handles = 0u32;
    let mut frames = HashSet::new();
    let end = |seq: &mut Sequencer<u32>, check: &mut SeqCheck| {
        let mut calls = 0;
        while seq.end_of_data(&mut |a| check.act(a)) {
            calls += 1;
            assert!(calls <= 2 * check.rows + 2, "end of data does not end");
        }
        assert!(!check.open, "end of data left the scan open");
        assert!(!seq.holding());
    };
    for _ in 0..200 {
        let Ok(op) = u.int_in_range(0..=15u8) else {
            break;
        };
        if op == 0 {
            end(&mut seq, &mut check);
            continue;
        }
        let sync = u.ratio(1, 4).unwrap_or(false);
        let payload = if op <= 2 {
            Payload::Lost
        } else {
            handles += 1;
            frames.insert(handles);
            Payload::Frame(handles)
        };
        seq.beam(sync, payload, &mut |a| check.act(a));
    }
    end(&mut seq, &mut check);
    let c = *seq.counts();
    assert_eq!(check.seen, frames, "a frame neither placed nor discarded");
    assert_eq!(
        c.beams,
        c.placed + c.lost + c.extra,
        "beams unaccounted: {c:?}"
    );
    assert_eq!(c.scans_begun, c.scans_finished);
    assert_eq!(c.misplaced, check.misplaced);
    Ok(())
}

fn board(u: &mut Unstructured) -> Result<()> {
    let cols = u.int_in_range(1..=12)?;
    let rows = u.int_in_range(1..=5)?;
    let (j1, j2) = (u.int_in_range(1..=4)?, u.int_in_range(1..=4)?);
    let scan = Scan::generate(j1, j2, cols, rows, u.arbitrary()?, (rows / 2, cols / 2));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    let reserve = u.int_in_range(1024..=2048)?;
    let mut board = Board::<2048>::new(&scan, &scorer, true, (&mut a, &mut b), reserve);
    let mut filling: Option<usize> = None;
    let mut beam = 0usize;
    for _ in 0..400 {
        let Ok(op) = u.int_in_range(0..=15u8) else {
            break;
        };
        match op {
            0..=5 => {
                // A DRDY edge: LINE_SYNC mostly where it belongs.
                let sync = if u.ratio(1, 8).unwrap_or(false) {
                    u.arbitrary().unwrap_or(false)
                } else {
                    scan.pos(beam).col == 0
                };
                if let Some(buf) = board.acq.drdy(sync) {
                    assert!(filling.is_none(), "two SPI reads at once");
                    board.frames.bufs[buf].copy_from_slice(scan.frame(beam));
                    filling = Some(buf);
                }
                beam += 1;
            }
            6..=8 => {
                if let Some(buf) = filling.take() {
                    board.acq.read_done(buf, u.ratio(7, 8).unwrap_or(true));
                }
            }
            9..=11 => board.score(u.int_in_range(0..=4).unwrap_or(1)),
            12..=14 => board.uart.send(u.int_in_range(0..=6).unwrap_or(1)),
            _ => {
                if let Some(buf) = filling.take() {
                    board.acq.read_done(buf, true);
                }
                board.end();
            }
        }
        let ac = *board.acq.counts();
        assert_eq!(
            ac.drdy,
            ac.frames_read + ac.overruns + ac.spi_errors + u32::from(filling.is_some()),
            "DRDY edges unaccounted: {ac:?}"
        );
    }
    if let Some(buf) = filling.take() {
        board.acq.read_done(buf, true);
    }
    board.end();

    let ac = *board.acq.counts();
    let sc = *board.driver.sequence_counts();
    assert_eq!(board.acq.pending(), 0);
    assert_eq!(
        sc.beams, ac.drdy,
        "beams lost between acquisition and sequencing"
    );
    assert_eq!(sc.beams, sc.placed + sc.lost + sc.extra);
    assert_eq!(sc.scans_begun, sc.scans_finished);
    let qc = *board.uart.queue.counts();
    assert_eq!(qc.dropped_keep, 0, "a keep line was dropped");
    assert!(board.uart.queue.is_empty());

    // Scan by scan, from what the UART sent.
    let score_lines = (cols as usize).div_ceil(SCORES_PER_LINE) as u32;
    let (mut open, mut next_row, mut s_lines, mut scans, mut frames) = (false, 0, 0, 0, 0);
    let mut misplaced = 0;
    for l in &board.uart.sent {
        match protocol::parse(l.as_bytes()).unwrap_or_else(|e| panic!("{e:?}: {l}")) {
            Line::Header(h) => {
                assert!(!open, "header inside a scan");
                assert_eq!(h.cols, cols);
                (open, next_row, s_lines) = (true, 0, 0);
            }
            Line::Row { summary, .. } => {
                assert!(open);
                assert_eq!(summary.row, next_row, "rows out of order");
                next_row += 1;
            }
            Line::Defect { row, .. } => assert!(open && row + 1 == next_row),
            // An object is reported after the lines of its last row.
            Line::Object(o) => assert!(open && o.row1 < next_row),
            Line::Scores { row, .. } => {
                assert!(open && row + 1 == next_row);
                s_lines += 1;
            }
            Line::End(e) => {
                assert!(open);
                let t = e.totals;
                assert_eq!(
                    (t.rows, next_row),
                    (rows, rows),
                    "scan without all its rows"
                );
                assert_eq!(t.frames + t.missing, rows * cols, "positions unaccounted");
                assert_eq!((t.rejected, t.extra, t.bad), (0, 0, 0));
                assert_eq!(
                    s_lines + e.dropped,
                    rows * score_lines,
                    "score lines unaccounted"
                );
                frames += t.frames;
                misplaced += t.misplaced;
                scans += 1;
                open = false;
            }
        }
    }
    assert!(!open, "scan without its end line");
    assert_eq!(scans, sc.scans_finished);
    assert_eq!(frames, sc.placed, "frames placed but not scored");
    assert_eq!(
        misplaced, sc.misplaced,
        "misplaced frames not in the end lines"
    );
    Ok(())
}

fuzz_target!(|data: &[u8]| {
    let mut u = Unstructured::new(data);
    // Selector 0 was the frame decoder's (gone: both boards receive
    // samples); it now runs the sequencer too, so that the committed seeds
    // of the other two keep their meaning.
    let _ = match u.int_in_range(0..=2u8) {
        Ok(0 | 1) => sequencer(&mut u),
        Ok(_) => board(&mut u),
        Err(e) => Err(e),
    };
});
