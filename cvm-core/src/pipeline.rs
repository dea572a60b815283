//! Engine, object labeller and line encoder: frames in, protocol lines
//! out. The host's
//! `dmap stream` and both firmware boards drive exactly this type, which is
//! what makes their output byte-identical.

use crate::calibration::{Calibrator, Progress};
use crate::channels::spread::{SPREAD_MAX, SPREAD_OFF};
use crate::objects::{MAX_OBJECTS, Object, Objects};
use crate::protocol::{HeaderInfo, LineSink, encode_end, encode_header, encode_object, encode_row};
use crate::scorer::Scorer;
pub use crate::settings::{Boot, Outputs, Settings};
use crate::stream::{Engine, EngineError, Position, PushOutcome, RowView, Totals};
use crate::verdict::{self, Ahead, Verdict};

/// What the objects' closures decide so far in a scan: the objects that
/// count towards the verdict, and those that rows closed since a board
/// last took them (row-mode REJECT pulses).
#[derive(Clone, Copy, Debug, Default)]
struct Closures {
    counted: u32,
    untaken: u32,
    /// Rows put out in this scan.
    rows: u32,
}

impl Closures {
    fn close(&mut self, o: &Object, outputs: &Outputs) {
        if verdict::counts(o, outputs) {
            self.counted = self.counted.saturating_add(1);
            self.untaken = self.untaken.saturating_add(1);
        }
    }
}

/// Objects closed and not yet encoded: the labeller runs ahead of the
/// lines, so that the sink hears of closures and of the verdict before
/// the rows that make them are encoded ([`Ahead`]). One row closes at
/// most the [`MAX_OBJECTS`] objects open before it; the scan's end runs
/// two rows and the final closing ahead, hence three times that.
const CLOSED_CAP: usize = 3 * MAX_OBJECTS;

struct Closed {
    list: [Object; CLOSED_CAP],
    len: usize,
}

impl Closed {
    const fn new() -> Self {
        const NONE: Object = Object::EMPTY;
        Closed {
            list: [NONE; CLOSED_CAP],
            len: 0,
        }
    }

    /// Keeps `o`, or returns it when full (which the bound above rules out).
    fn keep(&mut self, o: &Object) -> Option<Object> {
        match self.list.get_mut(self.len) {
            Some(slot) => {
                *slot = *o;
                self.len += 1;
                None
            }
            None => Some(*o),
        }
    }

    fn get(&self, from: usize, to: usize) -> &[Object] {
        self.list.get(from..to.min(self.len)).unwrap_or(&[])
    }
}

pub struct Pipeline<'a, const MAX_COLS: usize> {
    engine: Engine<'a, MAX_COLS>,
    objects: Objects,
    settings: Settings,
    boot: Boot,
    closures: Closures,
    closed: Closed,
    verdict: Option<Verdict>,
    /// Takes every finished row while a calibration runs (see
    /// [`Pipeline::attach_calibrator`]).
    calibrator: Option<&'a mut Calibrator>,
}

/// The spread threshold the engine scans with for a setting of `t`: a
/// setting above [`SPREAD_MAX`] is off, and the engine then measures
/// nothing ([`SPREAD_OFF`]), unless the scan is taken by a calibration
/// (`calibrating`), which needs the spread magnitudes whatever the
/// setting: the engine then measures them against a threshold no
/// magnitude reaches (`SPREAD_OFF - 1`), so that the scan's defects,
/// objects and verdict stay those of the channel off.
const fn engine_spread(t: u32, calibrating: bool) -> u32 {
    if t <= SPREAD_MAX {
        t
    } else if calibrating {
        SPREAD_OFF - 1
    } else {
        SPREAD_OFF
    }
}

impl<'a, const MAX_COLS: usize> Pipeline<'a, MAX_COLS> {
    pub fn new(
        scorer: &'a Scorer,
        settings: Settings,
        row_a: &'a mut [i32],
        row_b: &'a mut [i32],
    ) -> Result<Self, EngineError> {
        Self::with_near(scorer, settings, row_a, row_b, &mut [])
    }

    /// [`Pipeline::new`] with a buffer for the current row's last three
    /// maps (see [`Engine::with_near`]).
    #[inline(always)]
    pub fn with_near(
        scorer: &'a Scorer,
        settings: Settings,
        row_a: &'a mut [i32],
        row_b: &'a mut [i32],
        near: &'a mut [i32],
    ) -> Result<Self, EngineError> {
        let (cols, threshold) = (settings.cols, settings.threshold);
        let mut engine = Engine::with_near(scorer, cols, threshold, row_a, row_b, near)?;
        engine.set_power_threshold(settings.power_threshold);
        engine.set_spread_threshold(engine_spread(settings.spread_threshold, false));
        engine.set_rows(settings.rows);
        Ok(Pipeline {
            engine,
            objects: Objects::new(),
            settings,
            boot: Boot::power_on(crate::VERSION),
            closures: Closures::default(),
            closed: Closed::new(),
            verdict: None,
            calibrator: None,
        })
    }

    /// Hands the pipeline a calibrator's storage (about 24 KB: a board
    /// places it in the RAM bank it chooses). From then on every scan's
    /// begin, finished rows and end go to it, and it takes them while
    /// armed ([`Calibrator::arm`]): from the begin of the next scan,
    /// for as many scans as armed. Not armed, it costs one test per row.
    /// A scan forgotten before its end ([`Pipeline::configure`] in the
    /// middle of one) would leave its rows taken but the scan not counted:
    /// settings change between scans.
    pub fn attach_calibrator(&mut self, calibrator: &'a mut Calibrator) {
        self.calibrator = Some(calibrator);
    }

    /// The attached calibrator: its [`Calibrator::progress`] after each
    /// scan, its [`Calibrator::finish`] once done.
    pub fn calibrator(&self) -> Option<&Calibrator> {
        self.calibrator.as_deref()
    }

    /// The attached calibrator, to arm or disarm it.
    pub fn calibrator_mut(&mut self) -> Option<&mut Calibrator> {
        self.calibrator.as_deref_mut()
    }

    /// The verdict's rules (and the board's outputs) from now on.
    pub fn set_outputs(&mut self, outputs: Outputs) {
        self.settings.outputs = outputs;
    }

    pub fn outputs(&self) -> &Outputs {
        &self.settings.outputs
    }

    /// The settings the next header states and the next scan uses.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// The board's start as every header states it (a power-on start of
    /// this crate's version until told).
    pub fn boot(&self) -> &Boot {
        &self.boot
    }

    /// Tells the pipeline how the board started, once, at start-up.
    pub fn set_boot(&mut self, boot: Boot) {
        self.boot = boot;
    }

    /// Scans from the next [`Pipeline::begin`] on with `settings`: meant
    /// for between scans (a scan in progress is forgotten). Refused, and
    /// nothing changed, when the engine cannot hold its columns.
    pub fn configure(&mut self, settings: Settings) -> Result<(), EngineError> {
        self.engine.reconfigure(settings.cols, settings.threshold)?;
        self.engine.set_power_threshold(settings.power_threshold);
        self.engine
            .set_spread_threshold(engine_spread(settings.spread_threshold, false));
        self.engine.set_rows(settings.rows);
        self.settings = settings;
        Ok(())
    }

    /// The verdict of the last finished scan (`None` before the first).
    pub fn verdict(&self) -> Option<Verdict> {
        self.verdict
    }

    /// Objects that count towards the verdict closed since the last call
    /// (row-mode REJECT: the rows just emitted closed them).
    pub fn take_closed(&mut self) -> u32 {
        core::mem::take(&mut self.closures.untaken)
    }

    /// Starts a scan: the header line. A scan an attached calibrator
    /// takes has its spread measured even with the channel off (the
    /// calibration sets the spread threshold too); its decisions stay
    /// those of the channel off.
    pub fn begin(&mut self, sink: &mut impl LineSink) {
        self.closures = Closures::default();
        self.closed.len = 0;
        let mut taking = false;
        if let Some(c) = self.calibrator.as_deref_mut() {
            c.scan_begins();
            taking = matches!(c.progress(), Progress::Running { .. });
        }
        self.engine
            .set_spread_threshold(engine_spread(self.settings.spread_threshold, taking));
        let h = HeaderInfo::new(self.engine.scorer(), &self.settings, &self.boot);
        encode_header(&h, sink);
    }

    pub fn push(&mut self, pos: Position, frame: &[u16], sink: &mut impl LineSink) -> PushOutcome {
        let Pipeline {
            engine,
            objects,
            settings,
            closures,
            closed,
            calibrator,
            ..
        } = self;
        let mut lines = Emit {
            settings,
            closures,
            closed,
            calibrator: calibrator.as_deref_mut(),
            sink,
        };
        engine.push(pos, frame, &mut |row| lines.row(row, objects))
    }

    /// Records that `pos` receives no frame (detector overrun, SPI error).
    pub fn mark_missing(&mut self, pos: Position, sink: &mut impl LineSink) -> PushOutcome {
        let Pipeline {
            engine,
            objects,
            settings,
            closures,
            closed,
            calibrator,
            ..
        } = self;
        let mut lines = Emit {
            settings,
            closures,
            closed,
            calibrator: calibrator.as_deref_mut(),
            sink,
        };
        engine.mark_missing(pos, &mut |row| lines.row(row, objects))
    }

    /// See [`Engine::count_misplaced`].
    pub fn count_misplaced(&mut self, n: u32) {
        self.engine.count_misplaced(n);
    }

    /// Ends the scan: remaining rows, the objects still open, then the end
    /// line with `lines_dropped` (score lines the output could not carry)
    /// and the part's verdict ([`Pipeline::verdict`]). Returns the scan's
    /// totals. The verdict is decided, and told to the sink
    /// ([`Ahead::End`]), before the last rows' lines are encoded.
    pub fn finish(&mut self, lines_dropped: u32, sink: &mut impl LineSink) -> Totals {
        let Pipeline {
            engine,
            objects,
            settings,
            closures,
            closed,
            verdict,
            calibrator,
            ..
        } = self;
        engine.close();
        let mut lines = Emit {
            settings,
            closures,
            closed,
            calibrator: calibrator.as_deref_mut(),
            sink,
        };
        // Ahead of the lines: the verdict when the totals decide it, the
        // last rows' objects, then the scan's end.
        let mut defects = engine.totals().defects;
        engine.unsent(&mut |row| defects = defects.saturating_add(row.summary.defects));
        let outputs = &lines.settings.outputs;
        let early = Verdict::without_objects(
            engine.totals(),
            defects,
            lines.closures.counted,
            objects.any_open(|o| verdict::counts(o, outputs)),
            outputs,
        );
        if let Some(v) = early {
            lines.sink.ahead(Ahead::Verdict(v));
        }
        let mut marks = [0usize; 2];
        let mut k = 0;
        engine.unsent(&mut |row| {
            let n = lines.objects_of(row, objects);
            lines.sink.ahead(Ahead::Row {
                rows: lines.closures.rows,
                closed: n,
            });
            if let Some(m) = marks.get_mut(k) {
                *m = lines.closed.len;
            }
            k += 1;
        });
        let before = lines.closures.counted;
        let mut ends = *engine.totals();
        objects.finish_with(&mut |o| lines.keep(o), &mut ends);
        let v = Verdict::of(&ends, lines.closures.counted, &lines.settings.outputs);
        if early.is_none() {
            lines.sink.ahead(Ahead::Verdict(v));
        }
        lines.sink.ahead(Ahead::End {
            closed: lines.closures.counted.saturating_sub(before),
            verdict: v,
        });
        // The lines, in the order of a scan without lookahead.
        let mut from = 0;
        let mut k = 0;
        let mut totals = engine.finish(&mut |row| {
            let to = marks.get(k).copied().unwrap_or(from);
            lines.lines(row, from, to);
            from = to;
            k += 1;
        });
        if let Some(c) = lines.calibrator.as_deref_mut() {
            c.scan_ends();
        }
        lines.objects(from);
        totals.objects = ends.objects;
        totals.unobjected = ends.unobjected;
        *verdict = Some(v);
        encode_end(&totals, lines_dropped, v, sink);
        totals
    }

    pub fn totals(&self) -> &Totals {
        self.engine.totals()
    }
}

/// Where a scan's row and object lines go, and what their closures count.
struct Emit<'p, S> {
    settings: &'p Settings,
    closures: &'p mut Closures,
    closed: &'p mut Closed,
    calibrator: Option<&'p mut Calibrator>,
    sink: &'p mut S,
}

impl<S: LineSink> Emit<'_, S> {
    /// A finished row: the objects it closes are found first and told to
    /// the sink ([`Ahead::Row`]), then the row's lines and the objects'
    /// lines are encoded. Out of line: one copy per sink type instead of
    /// one in each of the closures that call it (about 16 KB of flash
    /// each on the target).
    #[inline(never)]
    fn row(&mut self, row: &RowView, objects: &mut Objects) {
        let from = self.closed.len;
        let closed = self.objects_of(row, objects);
        self.sink.ahead(Ahead::Row {
            rows: self.closures.rows,
            closed,
        });
        let to = self.closed.len;
        self.lines(row, from, to);
        self.closed.len = from;
    }

    /// Runs the labeller on `row`, keeping the objects it closes; counts
    /// the row as out. Returns how many of them count.
    fn objects_of(&mut self, row: &RowView, objects: &mut Objects) -> u32 {
        let before = self.closures.counted;
        objects.push_row(row, &mut |o| self.keep(o));
        self.closures.rows = self.closures.rows.saturating_add(1);
        self.closures.counted.saturating_sub(before)
    }

    fn keep(&mut self, o: &Object) {
        self.closures.close(o, &self.settings.outputs);
        if let Some(o) = self.closed.keep(o) {
            // No room (ruled out by `CLOSED_CAP`): out now, never lost.
            encode_object(&o, self.sink);
        }
    }

    /// A row's lines, then those of the objects kept from `from` to `to`.
    fn lines(&mut self, row: &RowView, from: usize, to: usize) {
        if let Some(c) = self.calibrator.as_deref_mut() {
            c.scan_row(row.scores);
        }
        encode_row(
            row,
            self.settings.max_defect_lines_per_row,
            self.settings.scores,
            self.sink,
        );
        for o in self.closed.get(from, to) {
            encode_object(o, self.sink);
        }
    }

    /// The lines of the objects kept from `from` on; the list is emptied.
    fn objects(&mut self, from: usize) {
        for o in self.closed.get(from, self.closed.len) {
            encode_object(o, self.sink);
        }
        self.closed.len = 0;
    }
}
