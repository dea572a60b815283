//! The scoring side's loop, board-independent: [`Runtime::step`] takes
//! the next beam from the board's acquisition log, applies settings the
//! command channel changed when no scan is open (to the pipeline, then to
//! READY and REJECT, in the same step), scores the beam, moves the outputs
//! and, at a scan's end, reports it to the command channel and finishes a
//! calibration. The board lends its parts: the log and frame buffers
//! ([`BeamSource`]), the line queues ([`CountingSink`], [`LineSink`]) and
//! the pins ([`Pins`]); it keeps what needs its clock (waiting for queue
//! room, the watchdog, yielding, the idle end of a scan).
//!
//! A setting rests in two places: pending in the [`Control`] (its one flag
//! says it changed), and in effect in the pipeline.

use core::cell::RefCell;

use cvm_core::calibration::Progress as Calibration;
use cvm_core::command::Refusal;
use cvm_core::protocol::{LineSink, Priority};
use cvm_core::settings::Outputs;
use cvm_core::verdict::Ahead;

use crate::control::Control;
use crate::driver::{CountingSink, ScanDriver};
use crate::frames::BeamSource;
use crate::outputs::{Asserted, Change, OutputLogic};

/// READY and REJECT on the board: it writes the levels the runtime
/// decides and times REJECT's pulses.
pub trait Pins {
    /// False for a board without the outputs (the emulated one): the
    /// runtime then leaves their logic out.
    const WIRED: bool = true;
    /// The outputs' asserted states now, and REJECT pulses to start.
    fn change(&mut self, change: Change);
    /// The outputs' settings from the scan starting now on; `now`: the
    /// asserted states, which the pins take at once.
    fn configure(&mut self, settings: &Outputs, now: Asserted);
}

/// A board without READY and REJECT.
pub struct NoPins;

impl Pins for NoPins {
    const WIRED: bool = false;
    fn change(&mut self, _change: Change) {}
    fn configure(&mut self, _settings: &Outputs, _now: Asserted) {}
}

/// Replies of a board without a command channel: none are made.
pub struct NoReplies;

impl LineSink for NoReplies {
    fn line(&mut self, _line: &[u8], _priority: Priority) {}
}

/// The scoring side: the scan driver (sequencer and pipeline), the
/// outputs' logic and pins, and the command channel's control, if the
/// board has one.
pub struct Runtime<'r, 'a, const MAX_COLS: usize, P: Pins> {
    driver: &'r mut ScanDriver<'a, MAX_COLS>,
    outputs: OutputLogic,
    pins: P,
    control: Option<&'r RefCell<Control>>,
}

impl<'r, 'a, const MAX_COLS: usize, P: Pins> Runtime<'r, 'a, MAX_COLS, P> {
    /// `outputs` started at the levels `pins` were set up with. With a
    /// command channel, its start (what the settings store gave included)
    /// is the one the headers state.
    pub fn new(
        driver: &'r mut ScanDriver<'a, MAX_COLS>,
        outputs: OutputLogic,
        pins: P,
        control: Option<&'r RefCell<Control>>,
    ) -> Self {
        if let Some(c) = control.and_then(|c| c.try_borrow().ok()) {
            driver.set_boot(c.boot());
        }
        Runtime {
            driver,
            outputs,
            pins,
            control,
        }
    }

    pub fn driver(&self) -> &ScanDriver<'a, MAX_COLS> {
        self.driver
    }

    /// One beam: the next of the record being expanded, else of the log's
    /// next record. `None` when there was none; else whether a scan
    /// finished. Lines go to `lines`, a calibration's result to `replies`.
    pub fn step<B: BeamSource, S: CountingSink, R: LineSink>(
        &mut self,
        beams: &mut B,
        lines: &mut S,
        replies: &mut R,
    ) -> Option<bool> {
        let rec = if self.driver.busy() {
            None
        } else {
            beams.next()
        };
        if rec.is_none() && !self.driver.busy() {
            return None;
        }
        let applied = self.take_control();
        let mut sink = AheadSink {
            lines,
            outputs: &mut self.outputs,
            pins: &mut self.pins,
        };
        let finished = self.driver.step(rec, beams, &mut sink);
        if P::WIRED && applied {
            let o = self.driver.settings().outputs;
            self.outputs.configure(o);
            self.pins.configure(&o, self.outputs.asserted());
        }
        self.stepped(finished, replies);
        Some(finished)
    }

    /// The data stopped: brings the open scan to its end, a bounded
    /// amount of output per call. Returns (more to do, a scan finished).
    pub fn end_of_data<B: BeamSource, S: CountingSink, R: LineSink>(
        &mut self,
        beams: &mut B,
        lines: &mut S,
        replies: &mut R,
    ) -> (bool, bool) {
        let mut sink = AheadSink {
            lines,
            outputs: &mut self.outputs,
            pins: &mut self.pins,
        };
        let (more, finished) = self.driver.end_of_data(beams, &mut sink);
        self.stepped(finished, replies);
        (more, finished)
    }

    /// The command channel's news: a calibration to arm (it starts with
    /// the next scan), and, when no scan is open, the settings it changed,
    /// applied to the pipeline. True when settings were applied.
    fn take_control(&mut self) -> bool {
        let Some(control) = self.control else {
            return false;
        };
        let Ok(mut c) = control.try_borrow_mut() else {
            return false;
        };
        if let Some(n) = c.calibration_to_arm()
            && let Some(cal) = self.driver.calibrator_mut()
        {
            cal.arm(n);
        }
        if !self.driver.between_scans() {
            return false;
        }
        match c.take_changed() {
            Some(s) => self.driver.apply(s),
            None => false,
        }
    }

    /// After a step: the outputs follow the scans (the closures were told
    /// ahead of their lines), and a finished scan goes to the command
    /// channel.
    fn stepped<R: LineSink>(&mut self, finished: bool, replies: &mut R) {
        if P::WIRED {
            let _ = self.driver.take_closed();
            if let Some(change) = self.outputs.step(self.driver.progress(), 0) {
                self.pins.change(change);
            }
        }
        if finished {
            self.scan_ended(replies);
        }
    }

    /// A scan ended: the command channel's last-scan report, and the end
    /// of a calibration whose last scan it was (its reply goes out, its
    /// thresholds are pending for the next scan).
    fn scan_ended<R: LineSink>(&mut self, replies: &mut R) {
        let Some(control) = self.control else {
            return;
        };
        let Ok(mut c) = control.try_borrow_mut() else {
            return;
        };
        if let Some((t, _)) = self.driver.last_scan() {
            c.scan_ended(&t, self.driver.progress().verdict);
        }
        if let Some(cal) = self.driver.calibrator_mut()
            && let Calibration::Done { .. } = cal.progress()
        {
            match cal.finish(&c.calibration_rule()) {
                Ok(result) => c.calibrated(&result, replies),
                Err(_) => c.calibration_failed(Refusal::NoResult, replies),
            }
            cal.disarm();
        }
    }
}

/// The pipeline's sink: lines to the board's queue, and the news ahead of
/// them to READY and REJECT, so that the pins move before the lines that
/// report the same verdict are encoded.
struct AheadSink<'s, S, P> {
    lines: &'s mut S,
    outputs: &'s mut OutputLogic,
    pins: &'s mut P,
}

impl<S: CountingSink, P: Pins> LineSink for AheadSink<'_, S, P> {
    fn line(&mut self, line: &[u8], priority: Priority) {
        self.lines.line(line, priority);
    }

    fn ahead(&mut self, news: Ahead) {
        if P::WIRED
            && let Some(change) = self.outputs.ahead(news)
        {
            self.pins.change(change);
        }
    }
}

impl<S: CountingSink, P: Pins> CountingSink for AheadSink<'_, S, P> {
    fn dropped(&self) -> u32 {
        self.lines.dropped()
    }
}
