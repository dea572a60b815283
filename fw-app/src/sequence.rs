//! Numbering beams into scan positions.
//!
//! Every DRDY edge is one beam, whether its frame was read or lost, so the
//! beam count is what keeps positions from shifting; LINE_SYNC (sampled at
//! the DRDY edge) marks the first beam of a row and re-anchors the count.
//!
//! Rules, in the order they are applied to a beam:
//!
//! 1. **Inside a row** (fewer than `cols` beams so far): a beam without
//!    LINE_SYNC takes the next column. A beam *with* LINE_SYNC while the row
//!    has already started ends it early (a *short row*, its remaining
//!    positions reported without data by the engine) and starts the next
//!    row at column 0.
//! 2. **After a full row**, a beam with LINE_SYNC starts the next row. A beam
//!    *without* it is ambiguous: either the row's LINE_SYNC was lost, or it
//!    is an extra beam (a spurious DRDY). It is *held* until the next beam
//!    decides: if that one carries LINE_SYNC the held beam was extra (it is
//!    discarded and counted), otherwise the held beam was the first of the
//!    next row (a missing LINE_SYNC, counted) and both are placed.
//! 3. **Scans**: after `rows` full rows the scan ends at once (the end line
//!    goes out without waiting for another beam); the next beam begins a new
//!    scan under the same rules (one without LINE_SYNC is held as above).
//! 4. A beam whose frame was lost (overrun, SPI error) still takes its
//!    position, which is reported missing.
//!
//! Only the LINE_SYNC-less beam after a full row is ever held, so normal
//! operation never delays a frame; the held frame keeps its buffer, which
//! the acquisition side accounts for like any frame being scored.

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
    /// Rows ended early by LINE_SYNC, and the positions they left empty.
    pub short_rows: u32,
    pub short_positions: u32,
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

#[derive(Clone, Copy, Debug)]
enum State<H> {
    /// No scan open: the next beam begins one.
    Between,
    /// A scan is open; `col` beams of `row` placed so far (`col <= cols`).
    Open { row: u32, col: u32 },
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
                    self.state = State::Open { row: 0, col: 0 };
                    self.place(payload, act);
                } else {
                    self.state = State::Hold {
                        next_row: 0,
                        begun: false,
                        held: payload,
                    };
                }
            }
            State::Open { row, col } if col < self.cols => {
                if sync && col > 0 {
                    self.counts.short_rows += 1;
                    self.counts.short_positions += self.cols - col;
                    if row + 1 >= self.rows {
                        // The short row was the scan's last: the beam opens the next scan.
                        self.finish(act);
                        self.begin(act);
                        self.state = State::Open { row: 0, col: 0 };
                    } else {
                        self.state = State::Open {
                            row: row + 1,
                            col: 0,
                        };
                    }
                }
                self.place(payload, act);
            }
            State::Open { row, .. } => {
                // Full row, and not the scan's last (that one finishes at once).
                if sync {
                    self.state = State::Open {
                        row: row + 1,
                        col: 0,
                    };
                    self.place(payload, act);
                } else {
                    self.state = State::Hold {
                        next_row: row + 1,
                        begun: true,
                        held: payload,
                    };
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
                    self.state = State::Open {
                        row: next_row,
                        col: 0,
                    };
                    self.place(payload, act);
                } else {
                    self.counts.sync_missing += 1;
                    if !begun {
                        self.begin(act);
                    }
                    self.state = State::Open {
                        row: next_row,
                        col: 0,
                    };
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
    /// one after a full row is taken as that row's successor. Positions no
    /// beam reached are reported missing, one row per call so that the
    /// caller can check its output room in between: call again while it
    /// returns true.
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
                self.state = State::Open {
                    row: next_row,
                    col: 0,
                };
                self.place(held, act);
                !matches!(self.state, State::Between)
            }
            State::Open { row, col } if col < self.cols => {
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
                    self.state = State::Open {
                        row,
                        col: self.cols,
                    };
                    true
                }
            }
            State::Open { row, .. } => {
                self.state = State::Open {
                    row: row + 1,
                    col: 0,
                };
                true
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

    /// Places `payload` at the next column of the open row (which has room).
    fn place(&mut self, payload: Payload<H>, act: &mut impl FnMut(Action<H>)) {
        let State::Open { row, col } = self.state else {
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
        if col == self.cols && row + 1 >= self.rows {
            self.finish(act);
        } else {
            self.state = State::Open { row, col };
        }
    }
}
