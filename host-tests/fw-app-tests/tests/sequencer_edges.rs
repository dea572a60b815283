//! Sequencer cases the board-level tests do not reach: which states hold a
//! frame back (`holding`), a held beam between scans when the data stops,
//! and beams that resume after `end_of_data` has opened the next row.
//! Expectations follow the rules in the `cvm_fw_app::sequence` module docs.

use cvm_core::stream::Position;
use cvm_fw_app::sequence::{Action, Payload, Sequencer};

use Action::{Begin, Discard, Finish, Place};
use Payload::{Frame, Lost};

fn at(row: u32, col: u32) -> Position {
    Position { row, col }
}

fn beam(seq: &mut Sequencer<u32>, sync: bool, p: Payload<u32>) -> Vec<Action<u32>> {
    let mut acts = vec![];
    seq.beam(sync, p, &mut |a| acts.push(a));
    acts
}

/// Only a frame held for the next beam's verdict (rule 2) is held back;
/// a held lost beam has no buffer, and placed frames are handed out.
#[test]
fn holding_is_true_exactly_while_a_frame_is_held() {
    let mut seq = Sequencer::<u32>::new(2, 3);
    assert!(!seq.holding());
    // Between scans, a beam without LINE_SYNC is held.
    assert_eq!(beam(&mut seq, false, Frame(1)), []);
    assert!(seq.holding());
    // LINE_SYNC next: the held frame was extra.
    assert_eq!(
        beam(&mut seq, true, Frame(2)),
        [Discard(1), Begin, Place(at(0, 0), 2)]
    );
    assert!(!seq.holding());
    assert_eq!(beam(&mut seq, false, Frame(3)), [Place(at(0, 1), 3)]);
    assert!(!seq.holding());
    // After a full row without suspect, a beam without LINE_SYNC is held.
    assert_eq!(beam(&mut seq, false, Frame(4)), []);
    assert!(seq.holding());
    // Without LINE_SYNC again: the held beam began row 1 (a lost sync).
    assert_eq!(
        beam(&mut seq, false, Frame(5)),
        [Place(at(1, 0), 4), Place(at(1, 1), 5)]
    );
    assert!(!seq.holding());
    // A held lost beam holds no buffer.
    assert_eq!(beam(&mut seq, false, Lost), []);
    assert!(!seq.holding());
    assert_eq!(seq.counts().sync_missing, 1);
    assert_eq!(seq.counts().extra, 1);
}

/// A beam held between scans when the data stops was extra: its frame is
/// freed, counted, and the next scan starts cleanly.
#[test]
fn held_beam_between_scans_is_extra_at_end_of_data() {
    let mut seq = Sequencer::<u32>::new(2, 1);
    assert_eq!(beam(&mut seq, false, Frame(7)), []);
    let mut acts = vec![];
    assert!(!seq.end_of_data(&mut |a| acts.push(a)));
    assert_eq!(acts, [Discard(7)]);
    assert_eq!(seq.counts().extra, 1);
    assert!(!seq.holding());
    assert_eq!(beam(&mut seq, true, Frame(8)), [Begin, Place(at(0, 0), 8)]);
    assert_eq!(
        beam(&mut seq, false, Frame(9)),
        [Place(at(0, 1), 9), Finish]
    );
    let c = seq.counts();
    assert_eq!((c.scans_begun, c.scans_finished, c.extra), (1, 1, 1));
    // A held lost beam is extra too, with nothing to free.
    assert_eq!(beam(&mut seq, false, Lost), []);
    let mut acts = vec![];
    assert!(!seq.end_of_data(&mut |a| acts.push(a)));
    assert_eq!(acts, []);
    assert_eq!(seq.counts().extra, 2);
}

/// `end_of_data` after a full row opens the next one; when beams resume,
/// the LINE_SYNC of that row's first beam starts it as usual and is no
/// suspect, so nothing is counted against the line.
#[test]
fn beams_resuming_after_end_of_data_start_the_opened_row() {
    let (cols, rows) = (3u32, 3u32);
    let mut seq = Sequencer::<u32>::new(cols, rows);
    let mut acts = vec![];
    for c in 0..cols {
        seq.beam(c == 0, Frame(c), &mut |a| acts.push(a));
    }
    assert!(seq.end_of_data(&mut |a| acts.push(a)));
    for b in cols..cols * rows {
        seq.beam(b % cols == 0, Frame(b), &mut |a| acts.push(a));
    }
    let mut want = vec![Begin];
    for b in 0..cols * rows {
        want.push(Place(at(b / cols, b % cols), b));
    }
    want.push(Finish);
    assert_eq!(acts, want);
    let c = seq.counts();
    assert_eq!((c.sync_extra, c.short_rows, c.misplaced), (0, 0, 0));
    assert_eq!((c.sync_missing, c.extra, c.unfinished_positions), (0, 0, 0));
}

fn end(seq: &mut Sequencer<u32>) -> (bool, Vec<Action<u32>>) {
    let mut acts = vec![];
    let more = seq.end_of_data(&mut |a| acts.push(a));
    (more, acts)
}

/// A beam held after a full row when the data stops is taken as the next
/// row's first (a lost LINE_SYNC, counted); `end_of_data` then reports
/// whether the scan still needs calls, one row of missing positions each.
#[test]
fn end_of_data_places_a_held_beam_as_the_next_rows_first() {
    use Action::Missing;
    let mut seq = Sequencer::<u32>::new(2, 3);
    let mut acts = vec![];
    for (b, sync) in [(0, true), (1, false), (2, false)] {
        seq.beam(sync, Frame(b), &mut |a| acts.push(a));
    }
    assert_eq!(acts, [Begin, Place(at(0, 0), 0), Place(at(0, 1), 1)]);
    assert!(seq.holding());
    assert_eq!(end(&mut seq), (true, vec![Place(at(1, 0), 2)]));
    assert_eq!(seq.counts().sync_missing, 1);
    assert_eq!(end(&mut seq), (true, vec![Missing(at(1, 1))]));
    assert_eq!(end(&mut seq), (true, vec![]));
    assert_eq!(end(&mut seq), (false, vec![Missing(at(2, 1)), Finish]));
    assert_eq!(end(&mut seq), (false, vec![]));
    let c = seq.counts();
    assert_eq!((c.sync_missing, c.unfinished_positions), (1, 3));
    assert_eq!((c.scans_begun, c.scans_finished), (1, 1));

    // When the held beam completes the scan, nothing is left to do.
    let mut seq = Sequencer::<u32>::new(1, 2);
    assert_eq!(beam(&mut seq, true, Frame(0)), [Begin, Place(at(0, 0), 0)]);
    assert_eq!(beam(&mut seq, false, Frame(1)), []);
    assert_eq!(end(&mut seq), (false, vec![Place(at(1, 0), 1), Finish]));
    assert_eq!(seq.counts().sync_missing, 1);
}

/// The scan's last row complete but with an unsettled suspect LINE_SYNC:
/// the scan stays open for the next beam (rule 3); when the data stops
/// instead, it ends at once, the suspect unsettled and nothing missing.
#[test]
fn end_of_data_ends_a_full_last_row_with_a_suspect() {
    let mut seq = Sequencer::<u32>::new(3, 1);
    let mut acts = vec![];
    for (b, sync) in [(0, true), (1, true), (2, false)] {
        seq.beam(sync, Frame(b), &mut |a| acts.push(a));
    }
    let placed: Vec<_> = (0..3).map(|c| Place(at(0, c), c)).collect();
    assert_eq!(acts[0], Begin);
    assert_eq!(acts[1..], placed[..]);
    assert_eq!(end(&mut seq), (false, vec![Finish]));
    assert_eq!(end(&mut seq), (false, vec![]));
    let c = seq.counts();
    assert_eq!(
        (c.unfinished_positions, c.sync_extra, c.short_rows),
        (0, 0, 0)
    );
    assert_eq!((c.scans_begun, c.scans_finished), (1, 1));
}
