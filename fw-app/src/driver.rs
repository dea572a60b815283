//! The scoring side's loop body: beam records in, engine calls out.
//!
//! [`ScanDriver`] ties the [`Sequencer`] to the core's `Pipeline` (the very
//! type `dmap stream` uses, which is what keeps the boards' output
//! byte-identical to the host's). It consumes one beam per [`ScanDriver::step`]
//! so that the board can check the output queue's room between beams, even
//! inside a long run of lost beams.

use cvm_core::calibration::Calibrator;
use cvm_core::pipeline::{Pipeline, Settings};
use cvm_core::protocol::{LineSink, Priority};
use cvm_core::stream::Totals;
use cvm_core::verdict::Ahead;

use crate::acquire::BeamRecord;
use crate::outputs::Progress;
use crate::sequence::{Action, Payload, SequenceCounts, Sequencer};

/// Where the frames behind beam records live (buffer indices on a board).
pub trait FrameStore {
    /// The samples of buffer `buf`, or `None` if it cannot be read
    /// (its position is then reported missing).
    fn frame(&mut self, buf: usize) -> Option<&[u16]>;
    /// The buffer may be reused.
    fn release(&mut self, buf: usize);
}

/// A line sink that knows how many lines it had to drop.
pub trait CountingSink: LineSink {
    fn dropped(&self) -> u32;
}

/// A beam record being expanded into beams.
#[derive(Clone, Copy, Debug)]
struct Pending {
    rec: BeamRecord,
    /// Beams of a lost run still to hand out (1 for a frame).
    left: u32,
}

/// Sequencer and pipeline of the scoring side.
pub struct ScanDriver<'a, const MAX_COLS: usize> {
    pipeline: Pipeline<'a, MAX_COLS>,
    seq: Sequencer<usize>,
    pending: Option<Pending>,
    /// The sink's drop count when the current scan began.
    dropped_at_begin: u32,
    /// Totals and dropped lines of the last finished scan.
    last: Option<(Totals, u32)>,
    /// Scans begun and finished since start-up (the outputs' clock).
    scans: (u32, u32),
}

impl<'a, const MAX_COLS: usize> ScanDriver<'a, MAX_COLS> {
    #[inline(always)]
    pub fn new(pipeline: Pipeline<'a, MAX_COLS>, cols: u32, rows: u32) -> Self {
        ScanDriver {
            pipeline,
            seq: Sequencer::new(cols, rows),
            pending: None,
            dropped_at_begin: 0,
            last: None,
            scans: (0, 0),
        }
    }

    /// Lends `calibrator` to the pipeline (see
    /// `Pipeline::attach_calibrator`).
    pub fn attach_calibrator(&mut self, calibrator: &'a mut Calibrator) {
        self.pipeline.attach_calibrator(calibrator);
    }

    /// The pipeline's calibrator, if one is attached.
    pub fn calibrator(&self) -> Option<&Calibrator> {
        self.pipeline.calibrator()
    }

    /// The pipeline's calibrator, to arm it.
    pub fn calibrator_mut(&mut self) -> Option<&mut Calibrator> {
        self.pipeline.calibrator_mut()
    }

    /// How the board started, which every header states.
    pub fn set_boot(&mut self, boot: cvm_core::Boot) {
        self.pipeline.set_boot(boot);
    }

    /// The settings the last (or open) scan uses.
    pub fn settings(&self) -> &Settings {
        self.pipeline.settings()
    }

    /// True when new settings can take effect: no scan is open, no beam
    /// is held and no record is being expanded.
    pub fn between_scans(&self) -> bool {
        self.pending.is_none() && self.seq.between()
    }

    /// Scans from the next one on use `s`; only [`Self::between_scans`]
    /// (false, and nothing changed, otherwise). Settings the pipeline
    /// refuses (columns beyond its buffers: the command channel's ranges
    /// prevent it) are dropped, and the old ones stay: true either way,
    /// and [`Self::settings`] says which are in effect.
    pub fn apply(&mut self, s: Settings) -> bool {
        if self.pending.is_some() || !self.seq.set_geometry(s.cols, s.rows) {
            return false;
        }
        if self.pipeline.configure(s).is_err() {
            let old = self.pipeline.settings();
            self.seq.set_geometry(old.cols, old.rows);
        }
        true
    }

    /// Where the scans stand, for the READY and REJECT outputs.
    pub fn progress(&self) -> Progress {
        let (begun, finished) = self.scans;
        let faulty = begun != finished
            && cvm_core::Verdict::of(self.pipeline.totals(), 0, self.pipeline.outputs()).is_fault();
        Progress {
            begun,
            finished,
            verdict: self.pipeline.verdict(),
            faulty,
            rows: self.pipeline.totals().rows,
        }
    }

    /// Objects that count, closed by the rows emitted since the last call.
    pub fn take_closed(&mut self) -> u32 {
        self.pipeline.take_closed()
    }

    /// Totals and dropped lines of the last finished scan.
    pub fn last_scan(&self) -> Option<(Totals, u32)> {
        self.last
    }

    pub fn sequence_counts(&self) -> &SequenceCounts {
        self.seq.counts()
    }

    /// True when a record is still being expanded (call [`Self::step`] with
    /// `None` until this is false before taking the next one).
    pub fn busy(&self) -> bool {
        self.pending.is_some()
    }

    /// Hands one beam to the sequencer: the next beam of the record being
    /// expanded, else of `rec`. Returns true when a scan finished.
    pub fn step<F: FrameStore, S: CountingSink>(
        &mut self,
        rec: Option<BeamRecord>,
        frames: &mut F,
        sink: &mut S,
    ) -> bool {
        if self.pending.is_none() {
            self.pending = rec.map(|rec| Pending {
                rec,
                left: match rec {
                    BeamRecord::Frame { .. } => 1,
                    BeamRecord::Lost { run, .. } => run,
                },
            });
        }
        let Some(mut p) = self.pending else {
            return false;
        };
        let (sync, payload) = match p.rec {
            BeamRecord::Frame { sync, buf } => (sync, Payload::Frame(buf)),
            BeamRecord::Lost { sync, run, .. } => (sync && p.left == run, Payload::Lost),
        };
        p.left = p.left.saturating_sub(1);
        self.pending = if p.left > 0 { Some(p) } else { None };
        if let BeamRecord::Lost { run: 0, .. } = p.rec {
            return false;
        }
        let mut finished = false;
        let Self {
            pipeline,
            seq,
            dropped_at_begin,
            last,
            scans,
            ..
        } = self;
        seq.beam(sync, payload, &mut |a| {
            finished |= apply(pipeline, dropped_at_begin, last, scans, a, frames, sink);
        });
        finished
    }

    /// The data stopped: brings the open scan to its end, a bounded amount
    /// of output per call (see [`Sequencer::end_of_data`]). Call again while
    /// it returns true. Returns (more to do, a scan finished).
    pub fn end_of_data<F: FrameStore, S: CountingSink>(
        &mut self,
        frames: &mut F,
        sink: &mut S,
    ) -> (bool, bool) {
        if self.pending.is_some() {
            let finished = self.step(None, frames, sink);
            return (true, finished);
        }
        let mut finished = false;
        let Self {
            pipeline,
            seq,
            dropped_at_begin,
            last,
            scans,
            ..
        } = self;
        let more = seq.end_of_data(&mut |a| {
            finished |= apply(pipeline, dropped_at_begin, last, scans, a, frames, sink);
        });
        (more, finished)
    }
}

/// Forwards every line as [`Priority::Keep`].
struct Promote<'s, S>(&'s mut S);

impl<S: LineSink> LineSink for Promote<'_, S> {
    fn line(&mut self, line: &[u8], _priority: Priority) {
        self.0.line(line, Priority::Keep);
    }

    fn ahead(&mut self, news: Ahead) {
        self.0.ahead(news);
    }
}

fn apply<const MAX_COLS: usize, F: FrameStore, S: CountingSink>(
    pipeline: &mut Pipeline<'_, MAX_COLS>,
    dropped_at_begin: &mut u32,
    last: &mut Option<(Totals, u32)>,
    scans: &mut (u32, u32),
    action: Action<usize>,
    frames: &mut F,
    sink: &mut S,
) -> bool {
    match action {
        Action::Begin => {
            *dropped_at_begin = sink.dropped();
            scans.0 = scans.0.wrapping_add(1);
            pipeline.begin(sink);
        }
        Action::Place(pos, buf) => {
            // Rejected, extra and bad frames are counted in the totals.
            let _ = match frames.frame(buf) {
                Some(frame) => pipeline.push(pos, frame, sink),
                None => pipeline.mark_missing(pos, sink),
            };
            frames.release(buf);
        }
        Action::Missing(pos) => {
            let _ = pipeline.mark_missing(pos, sink);
        }
        Action::Discard(buf) => frames.release(buf),
        Action::Misplaced(n) => pipeline.count_misplaced(n),
        Action::Finish => {
            let dropped = sink.dropped().wrapping_sub(*dropped_at_begin);
            // The last rows' score lines go out as keep lines, so that no
            // line can be dropped after `dropped` was fixed for the end line.
            *last = Some((pipeline.finish(dropped, &mut Promote(sink)), dropped));
            scans.1 = scans.1.wrapping_add(1);
            return true;
        }
    }
    false
}
