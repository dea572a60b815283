//! READY and REJECT, board-independent: which level each output should
//! have after each scoring step, decided from what the scan driver has
//! seen (scans begun and finished, the last verdict, a fault so far), so
//! that the pins follow the very verdict the end line carries. The board
//! writes the levels to its pins and times REJECT's pulses with a
//! hardware timer; nothing here waits.

use cvm_core::protocol::ResetCause;
use cvm_core::settings::{Outputs, RejectMode};
use cvm_core::verdict::{Ahead, Verdict};

/// What the scan driver reports after a step (see
/// [`crate::driver::ScanDriver::progress`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Progress {
    /// Scans begun since start-up.
    pub begun: u32,
    /// Scans finished since start-up.
    pub finished: u32,
    /// The verdict of the last finished scan.
    pub verdict: Option<Verdict>,
    /// The scan in progress is already faulty (its end line will say
    /// `fault-...`): READY need not wait for its end to drop.
    pub faulty: bool,
    /// Rows of the current (or last) scan whose lines have gone out.
    pub rows: u32,
}

/// The outputs' asserted states (not their pin levels: see [`level`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Asserted {
    pub ready: bool,
    pub reject: bool,
}

/// What the board does after a step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Change {
    pub now: Asserted,
    /// REJECT pulses to start (row mode: objects closed; part mode with a
    /// pulse width: 1 for a rejected part). The board's timer asserts and
    /// releases REJECT for each; `now.reject` then stays false.
    pub pulses: u32,
}

/// Row mode: closures waiting for their delay, at most this many rows
/// with closures at once; more are merged into the last (their pulses
/// come with its, a few rows early, never lost).
pub const DELAYED_ROWS: usize = 8;

/// The outputs' state across scans.
#[derive(Clone, Copy, Debug)]
pub struct OutputLogic {
    settings: Outputs,
    now: Asserted,
    seen: Progress,
    /// Row mode: (rows out when due, pulses), oldest first.
    delayed: [(u32, u32); DELAYED_ROWS],
    n_delayed: usize,
    /// The open scan's verdict was told ahead ([`Ahead::Verdict`]) and
    /// acted on: its end does not act again.
    told: bool,
}

impl OutputLogic {
    /// At start-up. After power-on the sensor is ready and no part is
    /// judged. After any other start a scan may have been cut short: its
    /// part was never judged, so REJECT is asserted in part mode, and
    /// READY stays dropped until a scan ends without a fault.
    pub fn start(settings: Outputs, cause: ResetCause) -> Self {
        let clean = cause == ResetCause::PowerOn;
        let part = settings.reject_mode == RejectMode::Part;
        OutputLogic {
            settings,
            now: Asserted {
                ready: clean,
                reject: !clean && part,
            },
            seen: Progress::default(),
            delayed: [(0, 0); DELAYED_ROWS],
            n_delayed: 0,
            told: false,
        }
    }

    /// Row mode: queues `closed` pulses for `row_delay` rows after the
    /// rows out now, and returns the pulses now due (all of them when the
    /// scan has ended: no more rows will come to count the delay).
    fn row_pulses(&mut self, p: Progress, closed: u32) -> u32 {
        if closed > 0 {
            let due = p.rows.saturating_add(self.settings.row_delay);
            match self.delayed.get_mut(self.n_delayed) {
                Some(slot) => {
                    *slot = (due, closed);
                    self.n_delayed += 1;
                }
                None => {
                    if let Some(last) = self.delayed.last_mut() {
                        last.1 = last.1.saturating_add(closed);
                    }
                }
            }
        }
        let ended = p.finished != self.seen.finished;
        let mut pulses = 0u32;
        let mut kept = 0;
        for k in 0..self.n_delayed.min(DELAYED_ROWS) {
            let Some(&(due, n)) = self.delayed.get(k) else {
                break;
            };
            if ended || due <= p.rows {
                pulses = pulses.saturating_add(n);
            } else if let Some(slot) = self.delayed.get_mut(kept) {
                *slot = (due, n);
                kept += 1;
            }
        }
        self.n_delayed = kept;
        pulses
    }

    pub fn asserted(&self) -> Asserted {
        self.now
    }

    /// New settings, between scans (the command channel's): pulses still
    /// delayed by the old row delay keep their rows.
    pub fn configure(&mut self, settings: Outputs) {
        if settings.reject_mode != self.settings.reject_mode {
            // What REJECT means changed: it starts released.
            self.now.reject = false;
            self.n_delayed = 0;
        }
        self.settings = settings;
    }

    /// After a scoring step: the new states and the pulses to start, or
    /// `None` when nothing changes. `closed`: objects that count, closed
    /// by the rows this step emitted (row mode's pulses).
    pub fn step(&mut self, p: Progress, closed: u32) -> Option<Change> {
        let before = self.now;
        let hold = self.settings.pulse_us == 0;
        let mut pulses = 0;
        match self.settings.reject_mode {
            RejectMode::Part => {
                if p.begun != self.seen.begun {
                    // A new part: the last part's REJECT is released.
                    self.now.reject = false;
                }
                if p.finished != self.seen.finished
                    && !self.told
                    && let Some(v) = p.verdict
                    && v.rejects()
                {
                    if hold {
                        self.now.reject = true;
                    } else {
                        pulses = 1;
                    }
                }
            }
            RejectMode::Row => pulses = self.row_pulses(p, closed),
        }
        if p.faulty {
            self.now.ready = false;
        }
        if p.finished != self.seen.finished
            && let Some(v) = p.verdict
        {
            self.now.ready = !v.is_fault();
            self.told = false;
        }
        self.seen = p;
        (self.now != before || pulses > 0).then_some(Change {
            now: self.now,
            pulses,
        })
    }
}

impl OutputLogic {
    /// What the pipeline tells ahead of a row's or the scan's lines
    /// ([`Ahead`]): the scan's verdict (READY, part mode's REJECT) and the
    /// pulses of the objects a row closes (row mode) are acted on before
    /// those lines are encoded.
    /// The [`OutputLogic::step`] after the scoring step then finds
    /// nothing new, so a board that takes this news must pass
    /// `closed = 0` there (the closures were told here).
    pub fn ahead(&mut self, news: Ahead) -> Option<Change> {
        let mut p = self.seen;
        let closed = match news {
            Ahead::Verdict(v) => return self.verdict_ahead(v),
            Ahead::Row { rows, closed } => {
                p.rows = rows;
                closed
            }
            Ahead::End { closed, verdict } => {
                p.finished = p.finished.wrapping_add(1);
                p.verdict = Some(verdict);
                closed
            }
        };
        self.step(p, closed)
    }

    /// The open scan's verdict, told before its end: READY, and part
    /// mode's REJECT, as at the end (row mode's pulses wait for the end's
    /// closures).
    fn verdict_ahead(&mut self, v: Verdict) -> Option<Change> {
        if self.told {
            return None;
        }
        self.told = true;
        let before = self.now;
        let mut pulses = 0;
        if self.settings.reject_mode == RejectMode::Part && v.rejects() {
            if self.settings.pulse_us == 0 {
                self.now.reject = true;
            } else {
                pulses = 1;
            }
        }
        self.now.ready = !v.is_fault();
        (self.now != before || pulses > 0).then_some(Change {
            now: self.now,
            pulses,
        })
    }
}

/// The pin level of an output: high when asserted with an active-high
/// output, or released with an active-low one.
pub const fn level(asserted: bool, active_high: bool) -> bool {
    asserted == active_high
}
