//! Numbering beams into scan positions.
//!
//! Every DRDY edge is one beam, whether its frame was read or lost, so the
//! beam count is what places beams; LINE_SYNC (sampled at the DRDY edge)
//! marks the first beam of a row and is checked against the count. When the
//! two disagree, one of them is wrong, and the count is trusted until the
//! LINE_SYNC line has proved it wrong.
//!
//! Rules, in the order they are applied to a beam:
//!
//! 1. **Inside a row** (fewer than `cols` beams so far), a beam takes the
//!    next column. If it carries LINE_SYNC while the row has already
//!    started, that LINE_SYNC is a *suspect*: either a glitch on the line,
//!    or the start of the next row after a row whose last beams raised no
//!    DRDY (a *short row*). The two cannot be told apart yet, so the beam
//!    is placed by the count and the suspect remembered.
//! 2. **After a full row**, the next beam settles any suspect:
//!    - with LINE_SYNC, the count was right: the beam starts the next row
//!      and the row's suspects were glitches (counted `sync_extra`). With
//!      a glitch, no position is lost or moved.
//!    - without LINE_SYNC, when the row had a suspect at column `s` (the
//!      last one if there were several): the count was wrong, the suspect
//!      began the next row, and this beam is
//!      that row's column `cols - s`. The count re-anchors there. The
//!      `cols - s` beams after the suspect were placed at the end of the
//!      short row but belonged to the head of the next row; their scores
//!      are out, so they are counted as *misplaced* (in the scan's end line)
//!      and the head of the next row is reported without data.
//!    - without LINE_SYNC and without a suspect, the beam is ambiguous:
//!      either the row's LINE_SYNC was lost, or it is an extra beam (a
//!      spurious DRDY). It is *held* until the next beam decides: if that
//!      one carries LINE_SYNC the held beam was extra (it is discarded and
//!      counted), otherwise the held beam was the first of the next row (a
//!      missing LINE_SYNC, counted) and both are placed.
//! 3. **Scans**: after `rows` full rows the scan ends at once (the end line
//!    goes out without waiting for another beam), unless its last row has a
//!    suspect: then the next beam settles it first, so that misplaced beams
//!    are counted in the scan they were placed in. The next beam begins a
//!    new scan under the same rules (one without LINE_SYNC is held as
//!    above).
//! 4. A beam whose frame was lost (overrun, SPI error) still takes its
//!    position, which is reported missing.
//!
//! So a LINE_SYNC glitch costs nothing, a missing LINE_SYNC or an extra
//! beam after a row costs nothing, and a short row of `cols - s` beams
//! costs the `cols - s` positions of the next row's head (reported missing)
//! plus as many misplaced maps in its own tail (counted). Whatever the
//! faults, the count re-locks onto LINE_SYNC within a row of clean beams.
//! Nothing here can tell rows apart, though: a whole row without any DRDY
//! shifts the row numbers until the data stops long enough for the board
//! to end the scan (`end_of_data`).
//!
//! Only the LINE_SYNC-less beam after a full row without suspect is ever
//! held, so normal operation never delays a frame; the held frame keeps its
//! buffer, which the acquisition side accounts for like any frame being
//! scored.

use cvm_core::stream::Position;

/// What a beam carries: a frame (any handle the caller uses to find it) or
/// nothing, when the frame was lost.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Payload<H> {
    Frame(H),
    Lost,
}

/// What the caller must do, in this order, for the beams seen so far.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action<H> {
    /// A scan begins (emit its header).
    Begin,
    /// Score this frame at this position, then free it.
    Place(Position, H),
    /// This position's frame was lost.
    Missing(Position),
    /// An extra frame: free it without scoring.
    Discard(H),
    /// This many frames already placed in the open scan belonged to other
    /// positions (a short row): count them.
    Misplaced(u32),
    /// The scan is over (flush and emit its end line).
    Finish,
}

/// Sequencing counters since start-up.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SequenceCounts {
    pub beams: u32,
    /// Frames handed out for scoring.
    pub placed: u32,
    /// Positions whose beam arrived but whose frame was lost.
    pub lost: u32,
    /// Rows that LINE_SYNC proved short (rule 2).
    pub short_rows: u32,
    /// Frames placed at the end of a short row that belonged to the next
    /// row's head; as many positions of that head are reported without
    /// data.
    pub misplaced: u32,
    /// LINE_SYNCs inside a row that the beam count proved spurious.
    pub sync_extra: u32,
    /// Beams after a full row that turned out to be extra.
    pub extra: u32,
    /// Rows whose first beam came without LINE_SYNC.
    pub sync_missing: u32,
    /// Scans begun and finished.
    pub scans_begun: u32,
    pub scans_finished: u32,
    /// Positions left without any beam when the data stopped mid-scan.
    pub unfinished_positions: u32,
}

/// LINE_SYNCs inside the open row that the count has not settled yet
/// (rule 1): the last one's column and how many there were. The last one
/// is taken because after any burst of faults the newest LINE_SYNC is the
/// one the clean beams that follow agree with, which is what re-locks the
/// count within a row.
#[derive(Clone, Copy, Debug)]
struct Suspect {
    col: u32,
    count: u32,
}

#[derive(Clone, Copy, Debug)]
enum State<H> {
    /// No scan open: the next beam begins one.
    Between,
    /// A scan is open; `col` beams of `row` placed so far (`col <= cols`).
    Open {
        row: u32,
        col: u32,
        suspect: Option<Suspect>,
    },
    /// A LINE_SYNC-less beam after full row `next_row - 1` (or, when
    /// `!begun`, between scans) awaits the next beam's verdict.
    Hold {
        next_row: u32,
        begun: bool,
        held: Payload<H>,
    },
}

/// The beam numbering state machine for a `cols` x `rows` scan.
#[derive(Clone, Debug)]
pub struct Sequencer<H> {
    cols: u32,
    rows: u32,
    state: State<H>,
    counts: SequenceCounts,
}

impl<H: Copy> Sequencer<H> {
    /// `cols` and `rows` are clamped to at least 1.
    pub fn new(cols: u32, rows: u32) -> Self {
        Sequencer {
            cols: cols.max(1),
            rows: rows.max(1),
            state: State::Between,
            counts: SequenceCounts::default(),
        }
    }

    pub fn counts(&self) -> &SequenceCounts {
        &self.counts
    }

    /// Numbers the next scan as `cols` x `rows` (each at least 1). Only
    /// between scans, with no beam held: false, and nothing changed, while
    /// a scan is open or a beam awaits its verdict.
    pub fn set_geometry(&mut self, cols: u32, rows: u32) -> bool {
        if !matches!(self.state, State::Between) {
            return false;
        }
        self.cols = cols.max(1);
        self.rows = rows.max(1);
        true
    }

    /// True when no scan is open and no beam awaits its verdict: the
    /// geometry may change ([`Sequencer::set_geometry`]).
    pub fn between(&self) -> bool {
        matches!(self.state, State::Between)
    }

    /// True while a frame is held back (rule 2): the caller must not reuse
    /// its buffer yet.
    pub fn holding(&self) -> bool {
        matches!(
            self.state,
            State::Hold {
                held: Payload::Frame(_),
                ..
            }
        )
    }

    /// One beam, in DRDY order. `act` receives the resulting actions.
    pub fn beam(&mut self, sync: bool, payload: Payload<H>, act: &mut impl FnMut(Action<H>)) {
        self.counts.beams = self.counts.beams.wrapping_add(1);
        self.step(sync, payload, act);
    }

    fn step(&mut self, sync: bool, payload: Payload<H>, act: &mut impl FnMut(Action<H>)) {
        match self.state {
            State::Between => {
                if sync {
                    self.begin(act);
                    self.open(0, 0);
                    self.place(payload, act);
                } else {
                    self.state = State::Hold {
                        next_row: 0,
                        begun: false,
                        held: payload,
                    };
                }
            }
            State::Open { row, col, suspect } if col < self.cols => {
                let suspect = match suspect {
                    Some(s) if sync => Some(Suspect {
                        col,
                        count: s.count.saturating_add(1),
                    }),
                    None if sync && col > 0 => Some(Suspect { col, count: 1 }),
                    s => s,
                };
                self.state = State::Open { row, col, suspect };
                self.place(payload, act);
            }
            State::Open { row, suspect, .. } => {
                // A full row: the scan's last only while a suspect is open.
                let last = row + 1 >= self.rows;
                match (sync, suspect) {
                    (true, suspect) => {
                        if let Some(s) = suspect {
                            self.counts.sync_extra = self.counts.sync_extra.wrapping_add(s.count);
                        }
                        self.next_row(row, 0, act);
                        self.place(payload, act);
                    }
                    (false, Some(s)) => {
                        // The suspect began a row: this beam is its column
                        // `cols - s.col` (`s.col` is in 1..cols).
                        let head = self.cols - s.col;
                        let c = &mut self.counts;
                        c.short_rows = c.short_rows.wrapping_add(1);
                        c.misplaced = c.misplaced.wrapping_add(head);
                        c.sync_extra = c.sync_extra.wrapping_add(s.count - 1);
                        act(Action::Misplaced(head));
                        self.next_row(row, head, act);
                        self.place(payload, act);
                    }
                    (false, None) if last => {
                        // Not reached: such a row finished the scan at once.
                        self.finish(act);
                        self.step(sync, payload, act);
                    }
                    (false, None) => {
                        self.state = State::Hold {
                            next_row: row + 1,
                            begun: true,
                            held: payload,
                        };
                    }
                }
            }
            State::Hold {
                next_row,
                begun,
                held,
            } => {
                if sync {
                    self.counts.extra += 1;
                    if let Payload::Frame(h) = held {
                        act(Action::Discard(h));
                    }
                    if !begun {
                        self.begin(act);
                    }
                    self.open(next_row, 0);
                    self.place(payload, act);
                } else {
                    self.counts.sync_missing += 1;
                    if !begun {
                        self.begin(act);
                    }
                    self.open(next_row, 0);
                    self.place(held, act);
                    // The current beam now follows the normal rules
                    // (it may complete a one-column row or the scan).
                    self.step(false, payload, act);
                }
            }
        }
    }

    /// The data stopped (end of input, or no beam for a long time): the
    /// open scan is brought to its end. A held beam between scans is extra;
    /// one after a full row is taken as that row's successor; a suspect
    /// LINE_SYNC stays unsettled. Positions no beam reached are reported
    /// missing, one row per call so that the caller can check its output
    /// room in between: call again while it returns true.
    pub fn end_of_data(&mut self, act: &mut impl FnMut(Action<H>)) -> bool {
        match self.state {
            State::Between => false,
            State::Hold {
                begun: false, held, ..
            } => {
                self.counts.extra += 1;
                if let Payload::Frame(h) = held {
                    act(Action::Discard(h));
                }
                self.state = State::Between;
                false
            }
            State::Hold {
                next_row,
                begun: true,
                held,
            } => {
                self.counts.sync_missing += 1;
                self.open(next_row, 0);
                self.place(held, act);
                !matches!(self.state, State::Between)
            }
            State::Open { row, col, .. } if col < self.cols => {
                self.counts.unfinished_positions += self.cols - col;
                // The engine reports every position it was not given as
                // missing, up to the last one it hears of.
                act(Action::Missing(Position {
                    row,
                    col: self.cols - 1,
                }));
                if row + 1 >= self.rows {
                    self.finish(act);
                    false
                } else {
                    self.open(row, self.cols);
                    true
                }
            }
            State::Open { row, .. } => {
                if row + 1 >= self.rows {
                    self.finish(act);
                    false
                } else {
                    self.open(row + 1, 0);
                    true
                }
            }
        }
    }

    fn begin(&mut self, act: &mut impl FnMut(Action<H>)) {
        self.counts.scans_begun += 1;
        act(Action::Begin);
    }

    fn finish(&mut self, act: &mut impl FnMut(Action<H>)) {
        self.counts.scans_finished += 1;
        self.state = State::Between;
        act(Action::Finish);
    }

    fn open(&mut self, row: u32, col: u32) {
        self.state = State::Open {
            row,
            col,
            suspect: None,
        };
    }

    /// After full row `row`: opens the next row at `col`, or, after the
    /// scan's last row, ends the scan and opens the next one there.
    fn next_row(&mut self, row: u32, col: u32, act: &mut impl FnMut(Action<H>)) {
        if row + 1 >= self.rows {
            self.finish(act);
            self.begin(act);
            self.open(0, col);
        } else {
            self.open(row + 1, col);
        }
    }

    /// Places `payload` at the next column of the open row (which has room).
    fn place(&mut self, payload: Payload<H>, act: &mut impl FnMut(Action<H>)) {
        let State::Open { row, col, suspect } = self.state else {
            return;
        };
        let pos = Position { row, col };
        match payload {
            Payload::Frame(h) => {
                self.counts.placed += 1;
                act(Action::Place(pos, h));
            }
            Payload::Lost => {
                self.counts.lost += 1;
                act(Action::Missing(pos));
            }
        }
        let col = col + 1;
        if col == self.cols && row + 1 >= self.rows && suspect.is_none() {
            self.finish(act);
        } else {
            self.state = State::Open { row, col, suspect };
        }
    }
}
