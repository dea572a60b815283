//! The firmware's acquisition and output logic against the core pipeline
//! fed the clean scan directly.

use cvm_core::protocol::{Line, Priority, parse};
use cvm_core::stream::Position;
use cvm_fw_app::acquire::{Acquisition, BeamRecord, LostCause};
use cvm_fw_app::emufile::{HeaderError, ScanHeader};
use cvm_fw_app::queue::LineQueue;
use cvm_fw_app::sequence::{Action, Payload, Sequencer};
use cvm_fw_app_tests::{Board, Scan, reference, reference_placed};

const BIG: usize = 1 << 16;

fn end_field(lines: &[String], key: &str) -> u32 {
    let e = lines
        .iter()
        .find(|l| l.starts_with("E,"))
        .expect("end line");
    let body = e.split('*').next().unwrap();
    body.split(',')
        .find_map(|kv| kv.strip_prefix(&format!("{key}=")))
        .unwrap_or_else(|| panic!("no {key} in {e}"))
        .parse()
        .unwrap()
}

/// Lines of rows `>= from` (R, D and S lines carry the row as first field).
fn rows_from(lines: &[String], from: u32) -> Vec<String> {
    lines
        .iter()
        .filter(|l| {
            let mut f = l.split(',');
            let t = f.next().unwrap();
            matches!(t, "R" | "D" | "S") && f.next().unwrap().parse::<u32>().unwrap() >= from
        })
        .cloned()
        .collect()
}

#[test]
fn clean_scan_through_the_board_equals_the_pipeline() {
    let scan = Scan::generate(5, 5, 12, 6, 1, (3, 4));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    let mut board = Board::<BIG>::new(&scan, &scorer, true, (&mut a, &mut b), 4096);
    for beam in 0..scan.frames.len() {
        assert!(board.drdy(scan.pos(beam).col == 0, scan.frame(beam), true));
        board.score(usize::MAX);
        board.uart.send(usize::MAX);
    }
    board.end();
    assert_consistent(&board);
    let want = reference(&scan, true, &[], 0);
    // The gradient peaks next to the planted blob at (3, 4).
    assert!(
        want.iter().any(|l| l.starts_with("D,2,4,")),
        "the planted defect is found"
    );
    assert!(
        want.iter().all(|l| !l.starts_with("D,0,")),
        "no defect far from it"
    );
    assert_eq!(board.uart.sent, want);
    assert_eq!(board.driver.sequence_counts().scans_finished, 1);
}

#[test]
fn drdy_storm_overruns_are_counted_and_reported_missing_in_place() {
    let scan = Scan::generate(4, 4, 10, 8, 2, (6, 2));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    let mut board = Board::<BIG>::new(&scan, &scorer, true, (&mut a, &mut b), 4096);
    let mut lost = vec![];
    for beam in 0..scan.frames.len() {
        let storm = (25..37).contains(&beam);
        if !board.drdy(scan.pos(beam).col == 0, scan.frame(beam), true) {
            lost.push(scan.pos(beam));
        }
        // During the storm scoring falls behind: it takes one beam every
        // third edge, so both buffers fill and further frames overrun.
        if !storm || beam % 3 == 0 {
            board.score(1);
        }
        board.uart.send(usize::MAX);
    }
    board.end();
    assert_consistent(&board);
    assert!(lost.len() >= 5, "the storm must overrun ({lost:?})");
    assert_eq!(board.acq.counts().overruns as usize, lost.len());
    assert_eq!(board.driver.sequence_counts().lost as usize, lost.len());
    let want = reference(&scan, true, &lost, 0);
    assert_eq!(board.uart.sent, want);
    assert_eq!(end_field(&board.uart.sent, "missing") as usize, lost.len());
    // Rows two below the last loss are untouched by it.
    let last = lost.iter().map(|p| p.row).max().unwrap();
    assert_eq!(
        rows_from(&board.uart.sent, last + 2),
        rows_from(&reference(&scan, true, &[], 0), last + 2)
    );
}

#[test]
fn missing_line_sync_keeps_every_position() {
    let scan = Scan::generate(3, 4, 7, 6, 3, (4, 3));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    let mut board = Board::<BIG>::new(&scan, &scorer, true, (&mut a, &mut b), 4096);
    for beam in 0..scan.frames.len() {
        let pos = scan.pos(beam);
        // LINE_SYNC lost on the first beam of rows 2 and 3.
        let sync = pos.col == 0 && pos.row != 2 && pos.row != 3;
        board.drdy(sync, scan.frame(beam), true);
        board.score(usize::MAX);
    }
    board.end();
    assert_consistent(&board);
    assert_eq!(board.uart.sent, reference(&scan, true, &[], 0));
    assert_eq!(board.driver.sequence_counts().sync_missing, 2);
    assert_eq!(board.driver.sequence_counts().extra, 0);
}

#[test]
fn extra_frame_after_a_row_is_discarded_and_counted() {
    let scan = Scan::generate(3, 3, 6, 5, 4, (2, 2));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    let mut board = Board::<BIG>::new(&scan, &scorer, true, (&mut a, &mut b), 4096);
    for beam in 0..scan.frames.len() {
        let pos = scan.pos(beam);
        board.drdy(pos.col == 0, scan.frame(beam), true);
        if pos == (Position { row: 1, col: 5 }) {
            // A spurious DRDY with garbage data after row 1.
            board.drdy(false, &[60000; 9], true);
        }
        board.score(usize::MAX);
    }
    board.end();
    assert_consistent(&board);
    assert_eq!(board.uart.sent, reference(&scan, true, &[], 0));
    assert_eq!(board.driver.sequence_counts().extra, 1);
}

#[test]
fn short_row_costs_the_next_rows_head_and_counts_the_misplaced_maps() {
    let scan = Scan::generate(4, 3, 8, 6, 5, (4, 6));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    let mut board = Board::<BIG>::new(&scan, &scorer, true, (&mut a, &mut b), 4096);
    let p = |row, col| Position { row, col };
    let gone = [p(1, 6), p(1, 7)];
    for beam in 0..scan.frames.len() {
        let pos = scan.pos(beam);
        if gone.contains(&pos) {
            continue; // no DRDY at all for these beams
        }
        board.drdy(pos.col == 0, scan.frame(beam), true);
        board.score(usize::MAX);
    }
    board.end();
    assert_consistent(&board);
    // By hand, from the rules: the LINE_SYNC of (2,0) arrives at column 6
    // of row 1 and is a suspect, so (2,0) and (2,1) land in (1,6) and
    // (1,7); the next beam, (2,2), comes without LINE_SYNC after the full
    // row, which proves row 1 short: it goes to (2,2), and (2,0), (2,1)
    // have no data.
    let placements: Vec<_> = (0..scan.frames.len())
        .filter(|&beam| !gone.contains(&scan.pos(beam)))
        .map(|beam| match scan.pos(beam) {
            Position { row: 2, col } if col < 2 => (p(1, 6 + col), Some(beam)),
            pos => (pos, Some(beam)),
        })
        .collect();
    assert_eq!(
        board.uart.sent,
        reference_placed(&scan, true, &placements, 2)
    );
    let c = board.driver.sequence_counts();
    assert_eq!((c.short_rows, c.misplaced), (1, 2));
    assert_eq!((c.sync_extra, c.sync_missing, c.extra), (0, 0, 0));
    assert_eq!(end_field(&board.uart.sent, "missing"), 2);
    assert_eq!(end_field(&board.uart.sent, "misplaced"), 2);
    // Rows 4 on are exactly the clean scan's (row 3's vertical component
    // needs row 2's head).
    assert_eq!(
        rows_from(&board.uart.sent, 4),
        rows_from(&reference(&scan, true, &gone, 0), 4)
    );
}

#[test]
fn short_last_row_is_settled_before_the_scan_ends() {
    let scan = Scan::generate(3, 3, 6, 3, 15, (1, 2));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    let mut board = Board::<BIG>::new(&scan, &scorer, true, (&mut a, &mut b), 4096);
    let n = scan.frames.len();
    let p = |row, col| Position { row, col };
    // Two scans back to back; the first one's last row loses its last two
    // beams (no DRDY).
    let gone = [4 + 2 * 6, 5 + 2 * 6];
    for beam in (0..2 * n).filter(|b| !gone.contains(b)) {
        board.drdy(scan.pos(beam).col == 0, scan.frame(beam), true);
        board.score(usize::MAX);
    }
    board.end();
    assert_consistent(&board);
    // The second scan's first two beams are placed at the end of the first
    // scan (and counted there); the second scan starts at (0,2).
    let first: Vec<_> = (0..n)
        .filter(|b| !gone.contains(b))
        .map(|b| (scan.pos(b), Some(b)))
        .chain([(p(2, 4), Some(n)), (p(2, 5), Some(n + 1))])
        .collect();
    let second: Vec<_> = (n + 2..2 * n).map(|b| (scan.pos(b), Some(b))).collect();
    let mut want = reference_placed(&scan, true, &first, 2);
    want.extend(reference_placed(&scan, true, &second, 0));
    assert_eq!(board.uart.sent, want);
    let c = board.driver.sequence_counts();
    assert_eq!((c.scans_finished, c.short_rows, c.misplaced), (2, 1, 2));
}
#[test]
fn spi_errors_become_missing_positions() {
    let scan = Scan::generate(5, 5, 9, 5, 6, (1, 1));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    let mut board = Board::<BIG>::new(&scan, &scorer, false, (&mut a, &mut b), 4096);
    let bad = [Position { row: 2, col: 0 }, Position { row: 3, col: 5 }];
    for beam in 0..scan.frames.len() {
        let pos = scan.pos(beam);
        board.drdy(pos.col == 0, scan.frame(beam), !bad.contains(&pos));
        board.score(usize::MAX);
    }
    board.end();
    assert_consistent(&board);
    assert_eq!(board.acq.counts().spi_errors, 2);
    assert_eq!(board.uart.sent, reference(&scan, false, &bad, 0));
}

#[test]
fn stalled_uart_drops_only_score_lines_and_loses_no_position_silently() {
    let scan = Scan::generate(4, 4, 40, 12, 7, (9, 20));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    // Room for a few rows of score lines; the reserve holds a row's keep lines.
    const CAP: usize = 3000;
    let reserve = 2700;
    let mut board = Board::<CAP>::new(&scan, &scorer, true, (&mut a, &mut b), reserve);
    let mut lost = vec![];
    for beam in 0..scan.frames.len() {
        if !board.drdy(scan.pos(beam).col == 0, scan.frame(beam), true) {
            lost.push(scan.pos(beam));
        }
        board.score(usize::MAX);
        // The UART is stalled for rows 2..9, then sends 4 lines per beam.
        let row = scan.pos(beam).row;
        if !(2..9).contains(&row) {
            board.uart.send(4);
        }
    }
    board.end();
    assert_consistent(&board);
    let q = *board.uart.queue.counts();
    assert!(q.dropped_scores > 0, "the stall must drop score lines");
    assert_eq!(q.dropped_keep, 0);
    assert!(
        !lost.is_empty(),
        "scoring waits for keep room, so the stall overruns"
    );
    assert_eq!(board.acq.counts().overruns as usize, lost.len());
    let sent = &board.uart.sent;
    let want = reference(&scan, true, &lost, q.dropped_scores);
    let keep = |v: &[String]| {
        v.iter()
            .filter(|l| !l.starts_with("S,"))
            .cloned()
            .collect::<Vec<_>>()
    };
    // Every keep line arrives, in order, with the faults in place.
    assert_eq!(keep(sent), keep(&want));
    assert_eq!(end_field(sent, "dropped"), q.dropped_scores);
    assert_eq!(end_field(sent, "missing") as usize, lost.len());
    // Score lines that did arrive are the right ones, in order.
    let scores: Vec<&String> = sent.iter().filter(|l| l.starts_with("S,")).collect();
    let mut it = want.iter().filter(|l| l.starts_with("S,"));
    for s in &scores {
        assert!(it.any(|w| w == *s), "score line {s} out of place");
    }
    assert_eq!(
        scores.len() + q.dropped_scores as usize,
        want.iter().filter(|l| l.starts_with("S,")).count()
    );
}

#[test]
fn queue_keeps_its_reserve_for_keep_lines_and_order() {
    let mut q: LineQueue<100> = LineQueue::new(40);
    // 20-byte lines cost 22: two droppables fit under the 60 usable bytes.
    assert!(q.push(&[b'a'; 20], Priority::Droppable));
    assert!(q.push(&[b'b'; 20], Priority::Droppable));
    assert!(!q.push(&[b'c'; 20], Priority::Droppable));
    assert!(q.push(&[b'K'; 30], Priority::Keep));
    assert!(!q.keep_room());
    assert!(
        !q.push(&[b'L'; 30], Priority::Keep),
        "beyond the capacity even keep lines cannot go"
    );
    assert_eq!(
        (
            q.counts().dropped_scores,
            q.counts().dropped_keep,
            q.dropped()
        ),
        (1, 1, 2)
    );
    let mut out = [0u8; 64];
    assert_eq!(q.pop_into(&mut out), Some(20));
    assert_eq!(out[0], b'a');
    assert_eq!(q.pop_into(&mut out), Some(20));
    assert_eq!(out[0], b'b');
    assert_eq!(q.pop_into(&mut out), Some(30));
    assert_eq!(out[0], b'K');
    assert_eq!(q.pop_into(&mut out), None);
    // Wrap-around keeps bytes intact.
    for k in 0..50u8 {
        let line = [k; 17];
        assert!(q.push(&line, Priority::Keep));
        assert_eq!(q.pop_into(&mut out), Some(17));
        assert_eq!(&out[..17], &line);
    }
}

#[test]
fn full_beam_log_folds_lost_beams_into_a_run() {
    let mut acq: Acquisition<2, 4> = Acquisition::new();
    let b0 = acq.drdy(true).unwrap();
    acq.read_done(b0, true);
    let b1 = acq.drdy(false).unwrap();
    acq.read_done(b1, true);
    // Both buffers busy: 5 more edges, log of 4 has 2 slots left.
    for k in 0..5 {
        assert_eq!(acq.drdy(k == 3), None);
    }
    assert_eq!(acq.counts().overruns, 5);
    assert_eq!(acq.counts().sync_folded, 1);
    assert_eq!(
        acq.take_next(),
        Some(BeamRecord::Frame {
            sync: true,
            buf: b0
        })
    );
    assert_eq!(
        acq.take_next(),
        Some(BeamRecord::Frame {
            sync: false,
            buf: b1
        })
    );
    assert_eq!(
        acq.take_next(),
        Some(BeamRecord::Lost {
            sync: false,
            cause: LostCause::Overrun,
            run: 1
        })
    );
    assert_eq!(
        acq.take_next(),
        Some(BeamRecord::Lost {
            sync: false,
            cause: LostCause::Overrun,
            run: 4
        })
    );
    assert_eq!(acq.take_next(), None);
}

/// Many buffers released out of order: a DRDY gets a free buffer whichever
/// it is (the search starts after the last one handed out and goes round
/// the end), never a busy one, and none while a read is still running.
#[test]
fn any_free_buffer_is_used_and_one_read_runs_at_a_time() {
    let mut acq = Acquisition::<4, 16>::new();
    let mut held = vec![];
    for _ in 0..4 {
        let b = acq.drdy(false).expect("a free buffer");
        assert!(!held.contains(&b), "buffer {b} handed out twice");
        acq.read_done(b, true);
        held.push(b);
    }
    assert_eq!(acq.drdy(false), None, "every buffer busy: overrun");
    for _ in 0..4 {
        assert!(matches!(acq.take_next(), Some(BeamRecord::Frame { .. })));
    }
    assert!(matches!(
        acq.take_next(),
        Some(BeamRecord::Lost { run: 1, .. })
    ));
    // Release the second buffer only: it is the one a DRDY gets.
    acq.release(held[1]);
    assert_eq!(acq.drdy(false), Some(held[1]));
    // A read runs: the next DRDY is lost even with free buffers.
    acq.release(held[0]);
    acq.release(held[2]);
    assert_eq!(acq.drdy(true), None, "the SPI is still reading");
    acq.read_done(held[1], true);
    let b = acq.drdy(false).expect("two buffers free");
    assert!(b == held[0] || b == held[2], "got busy buffer {b}");
    // A failed read frees its buffer for the next DRDY.
    acq.read_done(b, false);
    let c = acq.drdy(false).expect("two buffers free");
    assert!(c == held[0] || c == held[2], "got busy buffer {c}");
    acq.read_done(c, true);
    let counts = *acq.counts();
    assert_eq!(
        (
            counts.drdy,
            counts.frames_read,
            counts.overruns,
            counts.spi_errors
        ),
        (9, 6, 2, 1)
    );
    assert_eq!(
        acq.take_next(),
        Some(BeamRecord::Frame {
            sync: false,
            buf: held[1]
        })
    );
    assert_eq!(
        acq.take_next(),
        Some(BeamRecord::Lost {
            sync: true,
            cause: LostCause::Overrun,
            run: 1
        })
    );
    assert_eq!(
        acq.take_next(),
        Some(BeamRecord::Lost {
            sync: false,
            cause: LostCause::SpiError,
            run: 1
        })
    );
    assert_eq!(
        acq.take_next(),
        Some(BeamRecord::Frame {
            sync: false,
            buf: c
        })
    );
    assert_eq!(acq.take_next(), None);
}

/// The only free buffer comes after busy ones, on either side of where
/// the search starts: it is the one a DRDY gets.
#[test]
fn the_only_free_buffer_is_found_past_busy_ones() {
    let mut acq = Acquisition::<4, 16>::new();
    for k in 0..4 {
        assert_eq!(acq.drdy(false), Some(k));
        acq.read_done(k, true);
        assert!(matches!(acq.take_next(), Some(BeamRecord::Frame { buf, .. }) if buf == k));
    }
    acq.release(0);
    assert_eq!(acq.drdy(false), Some(0), "round the end");
    acq.read_done(0, true);
    acq.release(2);
    assert_eq!(acq.drdy(false), Some(2), "past busy buffer 1");
    acq.read_done(2, true);
    assert_eq!(acq.drdy(false), None, "all busy again");
}

fn run(seq: &mut Sequencer<u32>, beams: &[(bool, Payload<u32>)]) -> Vec<Action<u32>> {
    let mut acts = vec![];
    for &(sync, p) in beams {
        seq.beam(sync, p, &mut |a| acts.push(a));
    }
    acts
}

#[test]
fn sequencer_ends_scans_after_the_configured_rows() {
    let mut seq = Sequencer::new(2, 2);
    let f = |k| Payload::Frame(k);
    let acts = run(
        &mut seq,
        &[
            (true, f(0)),
            (false, f(1)),
            (true, f(2)),
            (false, Payload::Lost),
            (true, f(4)),
        ],
    );
    let p = |row, col| Position { row, col };
    assert_eq!(
        acts,
        vec![
            Action::Begin,
            Action::Place(p(0, 0), 0),
            Action::Place(p(0, 1), 1),
            Action::Place(p(1, 0), 2),
            Action::Missing(p(1, 1)),
            Action::Finish,
            Action::Begin,
            Action::Place(p(0, 0), 4),
        ]
    );
    let mut tail = vec![];
    while seq.end_of_data(&mut |a| tail.push(a)) {}
    assert_eq!(
        tail,
        vec![
            Action::Missing(p(0, 1)),
            Action::Missing(p(1, 1)),
            Action::Finish
        ]
    );
    assert_eq!(seq.counts().unfinished_positions, 3);
}

#[test]
fn sequencer_lone_beam_between_scans_is_extra() {
    let mut seq = Sequencer::new(3, 1);
    let acts = run(
        &mut seq,
        &[(false, Payload::Frame(9)), (true, Payload::Frame(1))],
    );
    assert_eq!(acts[0], Action::Discard(9));
    assert_eq!(acts[1], Action::Begin);
    assert_eq!(seq.counts().extra, 1);
}

#[test]
fn scan_file_header_round_trips_and_rejects_garbage() {
    let scan = Scan::generate(9, 7, 5, 5, 8, (0, 0));
    let h = ScanHeader {
        config: cvm_core::Config {
            kernels: cvm_core::Kernels::Square { kmax: 4 },
            weights: cvm_core::Weights::Separable {
                w1: [0.5; 16],
                w2: [0.25; 16],
            },
            ..cvm_core::Config::paper(cvm_core::Geometry::new(scan.j1, scan.j2).unwrap())
        },
        cols: 300,
        rows: 17,
        threshold_units: 0.125,
        power_threshold_units: 0.0625,
        spread_threshold_units: 0.1875,
        scores: true,
        max_defect_lines_per_row: 16,
        version_len: 4,
        version: *b"host\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0",
    };
    let bytes = h.encode();
    assert_eq!(ScanHeader::parse(&bytes), Ok(h));
    assert_eq!(ScanHeader::parse(&bytes).unwrap().version(), Some("host"));
    let mut bad = bytes;
    bad[0] = b'X';
    assert_eq!(ScanHeader::parse(&bad), Err(HeaderError::Magic));
    // Version 2 held the frames in bus order (most significant byte
    // first): read as native samples they would be byte-swapped, so its
    // files are refused, not misread.
    let mut v2 = bytes;
    v2[..8].copy_from_slice(b"CVMSCAN2");
    assert_eq!(ScanHeader::parse(&v2), Err(HeaderError::Magic));
    assert!(HeaderError::Magic.message().contains("CVMSCAN3"));
    let mut bad = bytes;
    bad[10] = 17;
    assert_eq!(ScanHeader::parse(&bad), Err(HeaderError::Geometry));
    let mut bad = bytes;
    bad[20..24].copy_from_slice(&0u32.to_le_bytes());
    assert_eq!(ScanHeader::parse(&bad), Err(HeaderError::Columns));
    assert_eq!(ScanHeader::parse(&bytes[..100]), Err(HeaderError::Short));
    // The spread threshold at bytes 328..336 (the table in emufile.rs).
    assert_eq!(bytes[328..336], 0.1875f64.to_le_bytes());
    // A header of the length before the spread threshold (328) is refused,
    // not read with its first frame's samples as the threshold.
    let mut old = bytes;
    old[8..10].copy_from_slice(&328u16.to_le_bytes());
    assert_eq!(ScanHeader::parse(&old), Err(HeaderError::Length));
}

/// What every fault must leave intact: each DRDY edge became one beam, each
/// beam was placed, reported lost or counted extra, every scan that began
/// ended, no record is left behind and no keep line was dropped.
fn assert_consistent<const CAP: usize>(board: &Board<'_, CAP>) {
    let a = *board.acq.counts();
    let c = *board.driver.sequence_counts();
    assert_eq!(board.acq.pending(), 0, "beam records left unscored");
    assert_eq!(a.drdy, a.frames_read + a.overruns + a.spi_errors);
    assert_eq!(c.beams, a.drdy, "every DRDY edge is one beam");
    assert_eq!(c.beams, c.placed + c.lost + c.extra, "{c:?}");
    assert_eq!(c.scans_begun, c.scans_finished);
    assert_eq!(
        board.finished, c.scans_finished,
        "the driver reports each scan it ends"
    );
    assert_eq!(board.uart.queue.counts().dropped_keep, 0);
    assert!(board.uart.queue.is_empty());
    // What the driver keeps of the last scan (the H743 logs it) is what
    // that scan's end line says.
    let end = board.uart.sent.iter().rev().find(|l| l.starts_with("E,"));
    match (end, board.driver.last_scan()) {
        (Some(line), Some((totals, dropped))) => {
            let Ok(Line::End(e)) = parse(line.trim_end().as_bytes()) else {
                panic!("end line {line:?} does not parse");
            };
            assert_eq!((e.totals, e.dropped), (totals, dropped), "{line}");
        }
        (None, None) => {}
        (end, last) => panic!("end line {end:?} but last scan {last:?}"),
    }
}

#[test]
fn drdy_faster_than_the_spi_loses_the_frames_it_cannot_read_in_place() {
    let scan = Scan::generate(4, 4, 10, 8, 9, (5, 3));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    let mut board = Board::<BIG>::new(&scan, &scorer, true, (&mut a, &mut b), 4096);
    let mut reading: Option<usize> = None;
    let mut lost = vec![];
    for beam in 0..scan.frames.len() {
        let pos = scan.pos(beam);
        // Beams 23..47: each DRDY edge comes while the SPI is still clocking
        // out the previous frame (the read completes one edge late).
        let storm = (23..47).contains(&beam);
        if !storm && let Some(buf) = reading.take() {
            board.acq.read_done(buf, true);
        }
        match board.acq.drdy(pos.col == 0) {
            Some(buf) => {
                board.frames.bufs[buf].copy_from_slice(scan.frame(beam));
                if storm {
                    if let Some(prev) = reading.replace(buf) {
                        board.acq.read_done(prev, true);
                    }
                } else {
                    board.acq.read_done(buf, true);
                }
            }
            None => lost.push(pos),
        }
        // An odd beam's read completes only at the next edge, so every even
        // beam of the storm finds the SPI busy.
        if storm
            && beam % 2 == 0
            && let Some(buf) = reading.take()
        {
            board.acq.read_done(buf, true);
        }
        board.score(usize::MAX);
        board.uart.send(usize::MAX);
    }
    if let Some(buf) = reading.take() {
        board.acq.read_done(buf, true);
    }
    board.end();
    assert_consistent(&board);
    assert_eq!(lost.len(), 12, "every even beam of the storm ({lost:?})");
    assert!(
        lost.iter()
            .all(|p| (23..47).contains(&(p.row * 10 + p.col)))
    );
    assert_eq!(board.acq.counts().overruns as usize, lost.len());
    // Every other position keeps its frame, every lost one is reported missing
    // where it was, and the end line counts them.
    assert_eq!(board.uart.sent, reference(&scan, true, &lost, 0));
    assert_eq!(end_field(&board.uart.sent, "missing") as usize, lost.len());
    assert_eq!(
        end_field(&board.uart.sent, "frames") as usize,
        80 - lost.len()
    );
}

#[test]
fn drdy_stuck_ends_the_scan_with_every_position_accounted_then_recovers() {
    let scan = Scan::generate(4, 4, 9, 6, 10, (4, 4));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    let mut board = Board::<BIG>::new(&scan, &scorer, true, (&mut a, &mut b), 4096);
    // DRDY stops after 3 rows and 4 beams: the firmware's idle timeout ends
    // the scan (end of data) with the positions no beam reached.
    let delivered = 3 * 9 + 4;
    for beam in 0..delivered {
        board.drdy(scan.pos(beam).col == 0, scan.frame(beam), true);
        board.score(usize::MAX);
    }
    board.end();
    let unreached: Vec<Position> = (delivered..54).map(|k| scan.pos(k)).collect();
    let first = board.uart.sent.clone();
    assert_eq!(first, reference(&scan, true, &unreached, 0));
    assert_eq!(end_field(&first, "rows"), 6);
    assert_eq!(end_field(&first, "frames") as usize, delivered);
    assert_eq!(end_field(&first, "missing") as usize, unreached.len());
    assert_eq!(
        board.driver.sequence_counts().unfinished_positions as usize,
        unreached.len()
    );
    assert_consistent(&board);

    // DRDY comes back: the next scan is complete and in place.
    board.uart.sent.clear();
    for beam in 0..scan.frames.len() {
        board.drdy(scan.pos(beam).col == 0, scan.frame(beam), true);
        board.score(usize::MAX);
    }
    board.end();
    assert_eq!(board.uart.sent, reference(&scan, true, &[], 0));
    assert_consistent(&board);
}

#[test]
fn uart_stalled_for_seconds_drops_only_counted_score_lines() {
    // 40 x 100 beams; at 1000 beams/s the UART is stalled for 3 s (3000
    // beams), long enough to fill the queue, the frame buffers and the
    // beam log, whose lost beams are then folded into runs.
    let scan = Scan::generate(3, 3, 40, 100, 11, (80, 20));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    const CAP: usize = 4096;
    let mut board = Board::<CAP>::new(&scan, &scorer, true, (&mut a, &mut b), 2700);
    let mut lost = vec![];
    for beam in 0..scan.frames.len() {
        if !board.drdy(scan.pos(beam).col == 0, scan.frame(beam), true) {
            lost.push(scan.pos(beam));
        }
        board.score(usize::MAX);
        if !(500..3500).contains(&beam) {
            board.uart.send(8);
        }
    }
    board.end();
    assert_consistent(&board);
    let q = *board.uart.queue.counts();
    assert!(lost.len() > 2500, "the stall must overrun ({})", lost.len());
    assert!(
        board.acq.counts().sync_folded > 0,
        "runs must fold LINE_SYNCs"
    );
    let sent = &board.uart.sent;
    let want = reference(&scan, true, &lost, q.dropped_scores);
    let keep = |v: &[String]| {
        v.iter()
            .filter(|l| !l.starts_with("S,"))
            .cloned()
            .collect::<Vec<_>>()
    };
    assert_eq!(
        keep(sent),
        keep(&want),
        "keep lines, in order, faults in place"
    );
    assert_eq!(end_field(sent, "missing") as usize, lost.len());
    assert_eq!(end_field(sent, "dropped"), q.dropped_scores);
    let s_sent = sent.iter().filter(|l| l.starts_with("S,")).count();
    let s_want = want.iter().filter(|l| l.starts_with("S,")).count();
    assert_eq!(s_sent + q.dropped_scores as usize, s_want);
    // After the stall (with a row of margin) every line is the reference's.
    let last = lost.iter().map(|p| p.row).max().unwrap();
    assert_eq!(rows_from(sent, last + 2), rows_from(&want, last + 2));
}

#[test]
fn extra_line_sync_mid_row_keeps_every_position() {
    let scan = Scan::generate(3, 3, 6, 5, 4, (2, 2));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    let mut board = Board::<BIG>::new(&scan, &scorer, true, (&mut a, &mut b), 4096);
    // Glitches in rows 1 and 4 (the scan's last, whose end then waits for
    // the next beam), two in row 3, and one on a lost beam in row 2; then a
    // second, clean scan.
    let glitch =
        |pos: Position| [(1, 3), (2, 4), (3, 1), (3, 5), (4, 2)].contains(&(pos.row, pos.col));
    let n = scan.frames.len();
    for beam in 0..2 * n {
        let pos = scan.pos(beam);
        let sync = pos.col == 0 || (beam < n && glitch(pos));
        let lost = beam < n && pos == (Position { row: 2, col: 4 });
        board.drdy(sync, scan.frame(beam), !lost);
        board.score(usize::MAX);
    }
    board.end();
    assert_consistent(&board);
    let lost = [Position { row: 2, col: 4 }];
    let mut want = reference(&scan, true, &lost, 0);
    want.extend(reference(&scan, true, &[], 0));
    assert_eq!(board.uart.sent, want);
    let c = board.driver.sequence_counts();
    assert_eq!((c.sync_extra, c.short_rows, c.misplaced), (5, 0, 0));
    assert_eq!(c.scans_finished, 2);
}

#[test]
fn sequencer_settles_a_suspect_line_sync_by_the_next_rows_start() {
    let p = |row, col| Position { row, col };
    let f = Payload::Frame;
    // 4 columns, 2 rows. Glitch: LINE_SYNC on beam 2 of row 0, row 1 on time.
    let mut seq = Sequencer::new(4, 2);
    let acts = run(
        &mut seq,
        &[
            (true, f(0)),
            (false, f(1)),
            (true, f(2)),
            (false, f(3)),
            (true, f(4)),
        ],
    );
    assert_eq!(
        acts,
        vec![
            Action::Begin,
            Action::Place(p(0, 0), 0),
            Action::Place(p(0, 1), 1),
            Action::Place(p(0, 2), 2),
            Action::Place(p(0, 3), 3),
            Action::Place(p(1, 0), 4),
        ]
    );
    assert_eq!((seq.counts().sync_extra, seq.counts().short_rows), (1, 0));
    // Short row: row 0 has two beams, row 1 starts with beam 2.
    let mut seq = Sequencer::new(4, 2);
    let acts = run(
        &mut seq,
        &[
            (true, f(0)),
            (false, f(1)),
            (true, f(2)),
            (false, f(3)),
            (false, f(4)),
            (false, f(5)),
        ],
    );
    assert_eq!(
        acts,
        vec![
            Action::Begin,
            Action::Place(p(0, 0), 0),
            Action::Place(p(0, 1), 1),
            Action::Place(p(0, 2), 2),
            Action::Place(p(0, 3), 3),
            Action::Misplaced(2),
            Action::Place(p(1, 2), 4),
            Action::Place(p(1, 3), 5),
            Action::Finish,
        ]
    );
    let c = seq.counts();
    assert_eq!((c.short_rows, c.misplaced), (1, 2));
    // Data stopping with a suspect open leaves it unsettled.
    let mut seq = Sequencer::new(4, 1);
    let acts = run(&mut seq, &[(true, f(0)), (false, f(1)), (true, f(2))]);
    assert_eq!(acts.len(), 4);
    let mut tail = vec![];
    while seq.end_of_data(&mut |a| tail.push(a)) {}
    assert_eq!(tail, vec![Action::Missing(p(0, 3)), Action::Finish]);
    assert_eq!((seq.counts().sync_extra, seq.counts().short_rows), (0, 0));
}

/// The column each beam of a scan gets: `Some(col)` per beam in order,
/// from the Place and Missing actions of a sequencer fed `beams`.
fn columns(seq: &mut Sequencer<u32>, beams: &[(bool, bool)]) -> Vec<Option<u32>> {
    let mut cols = vec![None; beams.len()];
    for (k, &(sync, read)) in beams.iter().enumerate() {
        let payload = if read {
            Payload::Frame(k as u32)
        } else {
            Payload::Lost
        };
        let mut lost_at = None;
        seq.beam(sync, payload, &mut |a| match a {
            Action::Place(pos, h) => cols[h as usize] = Some(pos.col),
            Action::Missing(pos) => lost_at = Some(pos.col),
            _ => {}
        });
        if !read {
            cols[k] = lost_at;
        }
    }
    cols
}

proptest::proptest! {
    /// Whatever the beams before (any LINE_SYNCs, lost frames, short and
    /// long rows), once clean rows start the count re-locks onto LINE_SYNC
    /// within one row: every beam from the second clean row on gets its
    /// true column.
    #[test]
    fn sequencer_relocks_within_a_row_of_clean_beams(
        cols in 1u32..9,
        rows in 1u32..5,
        garbage in proptest::collection::vec((proptest::bool::weighted(0.3), proptest::bool::weighted(0.8)), 0..60),
        clean_rows in 2usize..5,
    ) {
        let mut seq = Sequencer::new(cols, rows);
        let clean: Vec<_> = (0..clean_rows * cols as usize)
            .map(|k| (k % cols as usize == 0, true))
            .collect();
        let beams: Vec<_> = garbage.iter().copied().chain(clean).collect();
        let got = columns(&mut seq, &beams);
        let clean_got = &got[garbage.len()..];
        for (k, &col) in clean_got.iter().enumerate().skip(cols as usize) {
            let truth = (k % cols as usize) as u32;
            proptest::prop_assert_eq!(col, Some(truth), "clean beam {} of {:?}", k, beams);
        }
    }

    /// LINE_SYNC glitches (any number, anywhere but a row's first beam) and
    /// lost frames never move a position.
    #[test]
    fn line_sync_glitches_cost_nothing(
        cols in 2u32..9,
        rows in 1u32..5,
        faults in proptest::collection::vec((proptest::bool::weighted(0.2), proptest::bool::weighted(0.9)), 1..120),
    ) {
        let mut seq = Sequencer::new(cols, rows);
        let beams: Vec<_> = faults
            .iter()
            .enumerate()
            .map(|(k, &(glitch, read))| (k % cols as usize == 0 || glitch, read))
            .collect();
        let got = columns(&mut seq, &beams);
        for (k, col) in got.iter().enumerate() {
            proptest::prop_assert_eq!(*col, Some((k % cols as usize) as u32), "beam {}", k);
        }
        let c = seq.counts();
        let glitches = beams.iter().enumerate().filter(|&(k, b)| b.0 && k % cols as usize != 0).count();
        // The last row's suspects stay unsettled: no beam follows it.
        let last_row = (beams.len() - 1) / cols as usize * cols as usize;
        let unsettled = beams[last_row..].iter().skip(1).filter(|b| b.0).count();
        proptest::prop_assert_eq!(c.sync_extra as usize + unsettled, glitches);
        proptest::prop_assert_eq!((c.short_rows, c.misplaced), (0, 0));
    }
}

#[test]
fn beam_log_reads_a_frame_only_while_a_spare_slot_remains() {
    // A log of 5 records: a frame is read while its record and one spare
    // slot fit (at most 3 records waiting), so a lost beam always has a
    // slot or a lost record to extend.
    let mut acq = Acquisition::<8, 5>::new();
    for k in 0..4 {
        assert_eq!(acq.pending(), k);
        let buf = acq
            .drdy(k == 0)
            .unwrap_or_else(|| panic!("frame {k}: a buffer and two slots are free"));
        assert_eq!(acq.pending(), k + 1, "the record of frame {k} waits");
        acq.read_done(buf, true);
    }
    assert_eq!(acq.drdy(false), None, "one slot left: the beam is lost");
    assert_eq!(acq.drdy(true), None, "log full: folded into the run");
    assert_eq!(acq.pending(), 5);
    let c = *acq.counts();
    assert_eq!(
        (c.drdy, c.frames_read, c.overruns, c.sync_folded),
        (6, 4, 2, 1)
    );
    for k in 0..4 {
        assert_eq!(
            acq.take_next(),
            Some(BeamRecord::Frame {
                sync: k == 0,
                buf: k
            }),
            "frame {k}"
        );
        assert_eq!(acq.pending(), 4 - k);
    }
    assert_eq!(
        acq.take_next(),
        Some(BeamRecord::Lost {
            sync: false,
            cause: LostCause::Overrun,
            run: 2
        })
    );
    assert_eq!((acq.pending(), acq.take_next()), (0, None));
}
