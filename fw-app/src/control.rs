//! The command channel's logic (docs/commands.md),
//! board-independent: what each request does to the settings the next
//! scan will use, what it answers, and what it asks the board to do
//! (write flash, calibrate, restart). The board feeds it request lines
//! and link errors and performs the effects; the runtime takes the
//! settings between scans. Nothing here waits or touches hardware, so the
//! whole protocol logic is tested on the host.
//!
//! Sources (`d`, `f`, `c`): at start-up every value is the flash record's
//! (`f`) when one was loaded, else compiled (`d`). `set` and a finished
//! calibration make the values they change `c`; `defaults` puts every
//! value back to its compiled one, `d` when flash holds no record, else
//! `c` (a restart would bring the record's back); `save` writes every
//! value, which makes them all `f`.

use cvm_core::calibration::rule::{DEFAULT_TAIL_PPM, Rule};
use cvm_core::command::{
    Calibration, Capacity, Key, LastScan, LinkError, Refusal, Reply, Request, Status, conflict,
    encode_reply, parse_request,
};
use cvm_core::protocol::LineSink;
use cvm_core::settings::{Boot, KEYS, Settings, Source, Store};
use cvm_core::stream::Totals;
use cvm_core::verdict::Verdict;

/// What the board must do after a request was handled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Effect {
    /// Nothing: the reply is out.
    None,
    /// Write these values to flash, then call [`Control::saved`].
    Save { id: u32, values: [u32; KEYS] },
    /// Restart once the reply has been sent.
    Reset,
}

/// A calibration asked for and not finished.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CalibrationRun {
    /// The request's id, which the result carries.
    pub id: u32,
    pub scans: u16,
    /// The target of the tail rule that sets the thresholds, false
    /// positions per million parts.
    pub rate_ppm: u32,
    /// The scan driver has armed it (it starts with the next scan).
    pub armed: bool,
}

/// Commands received since start-up.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CommandCounts {
    pub requests: u32,
    pub refused: u32,
    /// Link errors on bytes that never made a line (nothing to answer).
    pub lost: u32,
}

/// The settings a board scans with, as the command channel changes them.
pub struct Control {
    compiled: Settings,
    next: Settings,
    /// The start: fixed, reported by `status` and every header.
    boot: Boot,
    cap: Capacity,
    /// The detector's map size, `status` reports it.
    geometry: (u8, u8),
    /// Flash holds a record of this firmware (loaded at start-up or saved).
    record: bool,
    /// `next` differs from what the runtime last took: the one flag
    /// between the command channel and the scans.
    pending: bool,
    saving: bool,
    calibration: Option<CalibrationRun>,
    last: LastScan,
    counts: CommandCounts,
}

impl Control {
    /// At start-up: the compiled settings, the start (with what the
    /// settings store gave, `boot.store`) and the store's record. A record
    /// whose values do not fit this firmware (out of range, or in
    /// conflict) is ignored like an unreadable one: the compiled values
    /// are used, `bad`.
    pub fn new(
        compiled: Settings,
        mut boot: Boot,
        cap: Capacity,
        geometry: (u8, u8),
        record: Option<[u32; KEYS]>,
    ) -> Self {
        let mut next = compiled;
        next.sources = [Source::Default; KEYS];
        let mut loaded = false;
        if let (Store::Loaded, Some(values)) = (boot.store, record) {
            let mut s = next;
            let mut sources = [Source::Flash; KEYS];
            let fits = Key::ALL.into_iter().zip(values).all(|(k, v)| {
                let (lo, hi) = k.range(&cap);
                if v >= lo && v <= hi && k.set(&mut s, v) {
                    true
                } else if matches!(k, Key::ReadyLevel | Key::RejectLevel) {
                    // An output level of an earlier firmware that allowed
                    // both: the fail-safe level stays, the record's other
                    // values are kept.
                    sources[k.index()] = Source::Default;
                    true
                } else {
                    false
                }
            });
            if fits && !conflict(&s) {
                s.sources = sources;
                next = s;
                loaded = true;
            } else {
                boot.store = Store::Unreadable;
            }
        }
        Control {
            compiled,
            next,
            boot,
            cap,
            geometry,
            record: loaded,
            pending: true,
            saving: false,
            calibration: None,
            last: LastScan {
                scans: 0,
                defects: 0,
                objects: 0,
                verdict: None,
            },
            counts: CommandCounts::default(),
        }
    }

    /// The settings the next scan starts with.
    pub fn settings(&self) -> &Settings {
        &self.next
    }

    /// The start every header and `status` report.
    pub fn boot(&self) -> Boot {
        self.boot
    }

    pub fn counts(&self) -> &CommandCounts {
        &self.counts
    }

    /// The settings, when they changed since the last call: the runtime
    /// takes them when no scan is open and applies them at once.
    pub fn take_changed(&mut self) -> Option<Settings> {
        core::mem::take(&mut self.pending).then_some(self.next)
    }

    /// A calibration the scan driver has yet to arm: its scans.
    pub fn calibration_to_arm(&mut self) -> Option<u16> {
        let run = self.calibration.as_mut()?;
        if run.armed {
            return None;
        }
        run.armed = true;
        Some(run.scans)
    }

    /// The rule that sets the thresholds of the calibration under way:
    /// the tail rule with the request's target rate and the default tail
    /// share (`Rule::DEFAULT` when none runs).
    pub fn calibration_rule(&self) -> Rule {
        match self.calibration {
            Some(run) => Rule::Tail {
                rate_ppm: run.rate_ppm,
                tail_ppm: DEFAULT_TAIL_PPM,
            },
            None => Rule::DEFAULT,
        }
    }

    /// A received request line (without its `\n`): the reply goes to
    /// `sink`, what the board must do besides is returned.
    pub fn line(&mut self, line: &[u8], sink: &mut impl LineSink) -> Effect {
        self.counts.requests = self.counts.requests.wrapping_add(1);
        match parse_request(line, &self.cap) {
            Ok((id, r)) => self.request(id, r, sink),
            Err((id, why)) => {
                self.refuse(id, why, sink);
                Effect::None
            }
        }
    }

    /// A line that arrived damaged or too long: refused with the reason.
    pub fn damaged(&mut self, why: Refusal, sink: &mut impl LineSink) {
        self.counts.requests = self.counts.requests.wrapping_add(1);
        self.refuse(None, why, sink);
    }

    /// A link error on bytes that will never make a line (the receiver
    /// restarted, or nothing followed): counted only.
    pub fn lost(&mut self, _e: LinkError) {
        self.counts.lost = self.counts.lost.wrapping_add(1);
    }

    fn refuse(&mut self, id: Option<u32>, why: Refusal, sink: &mut impl LineSink) {
        self.counts.refused = self.counts.refused.wrapping_add(1);
        encode_reply(id, &Reply::Refused(why), sink);
    }

    fn value(&self, id: u32, key: Key, sink: &mut impl LineSink) {
        let reply = Reply::Value {
            key,
            value: key.get(&self.next),
            source: self.next.sources[key.index()],
        };
        encode_reply(Some(id), &reply, sink);
    }

    fn request(&mut self, id: u32, r: Request, sink: &mut impl LineSink) -> Effect {
        let busy = self.calibration.is_some() || self.saving;
        match r {
            Request::Status => {
                encode_reply(Some(id), &Reply::Status(self.status()), sink);
                for key in Key::ALL {
                    self.value(id, key, sink);
                }
            }
            Request::Get(key) => self.value(id, key, sink),
            Request::Set(..) | Request::Defaults | Request::Save | Request::Calibrate { .. }
                if busy =>
            {
                self.refuse(Some(id), Refusal::Busy, sink);
            }
            Request::Set(key, v) => {
                let mut s = self.next;
                if !key.set(&mut s, v) {
                    // `parse_request` checked the range: a value a field
                    // cannot hold is out of it.
                    let (min, max) = key.range(&self.cap);
                    self.refuse(Some(id), Refusal::OutOfRange { min, max }, sink);
                } else if conflict(&s) {
                    self.refuse(Some(id), Refusal::Conflict, sink);
                } else {
                    s.sources[key.index()] = Source::Changed;
                    self.change(s);
                    self.value(id, key, sink);
                }
            }
            Request::Defaults => {
                let mut s = self.compiled;
                let src = if self.record {
                    Source::Changed
                } else {
                    Source::Default
                };
                s.sources = [src; KEYS];
                self.change(s);
                encode_reply(Some(id), &Reply::Defaults, sink);
            }
            Request::Calibrate { scans, rate_ppm } => {
                self.calibration = Some(CalibrationRun {
                    id,
                    scans,
                    rate_ppm,
                    armed: false,
                });
                encode_reply(Some(id), &Reply::Calibrating(scans), sink);
            }
            Request::Save => {
                self.saving = true;
                let mut values = [0; KEYS];
                for (v, k) in values.iter_mut().zip(Key::ALL) {
                    *v = k.get(&self.next);
                }
                return Effect::Save { id, values };
            }
            Request::Reset if self.saving => {
                // A reset now would cut the erase or program under way:
                // the next start would find the store to repair, with
                // READY down for the whole erase (docs/commands.md).
                self.refuse(Some(id), Refusal::Busy, sink);
            }
            Request::Reset => {
                encode_reply(Some(id), &Reply::Resetting, sink);
                return Effect::Reset;
            }
        }
        Effect::None
    }

    fn change(&mut self, s: Settings) {
        self.next = s;
        self.pending = true;
    }

    /// The store finished the `save` of request `id`.
    pub fn saved(&mut self, id: u32, ok: bool, sink: &mut impl LineSink) {
        self.saving = false;
        if ok {
            self.record = true;
            self.next.sources = [Source::Flash; KEYS];
            self.pending = true;
            encode_reply(Some(id), &Reply::Saved, sink);
        } else {
            self.refuse(Some(id), Refusal::Storage, sink);
        }
    }

    /// A scan ended: `status` reports it.
    pub fn scan_ended(&mut self, t: &Totals, verdict: Option<Verdict>) {
        self.last = LastScan {
            scans: self.last.scans.wrapping_add(1),
            defects: t.defects,
            objects: t.objects,
            verdict,
        };
    }

    /// The calibration finished: its three thresholds are the next scan's
    /// (not saved), and the reply carries the `calibrate` request's id.
    pub fn calibrated(&mut self, c: &Calibration, sink: &mut impl LineSink) {
        let Some(run) = self.calibration.take() else {
            return;
        };
        let mut s = self.next;
        s.threshold = c.threshold;
        s.power_threshold = c.power_threshold;
        s.spread_threshold = c.spread_threshold;
        s.sources[Key::Threshold.index()] = Source::Changed;
        s.sources[Key::PowerThreshold.index()] = Source::Changed;
        s.sources[Key::SpreadThreshold.index()] = Source::Changed;
        self.change(s);
        encode_reply(Some(run.id), &Reply::Calibrated(*c), sink);
    }

    /// The calibration ended without a result (`why`): refused with the
    /// `calibrate` request's id; the thresholds stay.
    pub fn calibration_failed(&mut self, why: Refusal, sink: &mut impl LineSink) {
        if let Some(run) = self.calibration.take() {
            self.refuse(Some(run.id), why, sink);
        }
    }

    fn status(&self) -> Status {
        Status {
            firmware: self.boot.firmware,
            j1: self.geometry.0,
            j2: self.geometry.1,
            max_cols: self.cap.max_cols,
            max_rows: self.cap.max_rows,
            store: self.boot.store,
            reset_cause: self.boot.reset_cause,
            boots: self.boot.boots,
            last: self.last,
        }
    }
}
