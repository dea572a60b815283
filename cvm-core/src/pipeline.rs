//! Engine, object labeller and line encoder: frames in, protocol lines
//! out. The host's
//! `dmap stream` and both firmware boards drive exactly this type, which is
//! what makes their output byte-identical.

use crate::objects::Objects;
use crate::protocol::{HeaderInfo, LineSink, encode_end, encode_header, encode_object, encode_row};
use crate::scorer::Scorer;
pub use crate::settings::Settings;
use crate::stream::{Engine, EngineError, Position, PushOutcome, RowView, Totals};

pub struct Pipeline<'a, const MAX_COLS: usize> {
    engine: Engine<'a, MAX_COLS>,
    objects: Objects,
    settings: Settings,
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
        Ok(Pipeline {
            engine,
            objects: Objects::new(),
            settings,
        })
    }

    /// Starts a scan: the header line.
    pub fn begin(&mut self, sink: &mut impl LineSink) {
        let h = HeaderInfo::new(self.engine.scorer(), &self.settings);
        encode_header(&h, sink);
    }

    pub fn push(&mut self, pos: Position, frame: &[u16], sink: &mut impl LineSink) -> PushOutcome {
        let Pipeline {
            engine,
            objects,
            settings,
        } = self;
        engine.push(pos, frame, &mut |row| emit(row, settings, objects, sink))
    }

    /// Records that `pos` receives no frame (detector overrun, SPI error).
    pub fn mark_missing(&mut self, pos: Position, sink: &mut impl LineSink) -> PushOutcome {
        let Pipeline {
            engine,
            objects,
            settings,
        } = self;
        engine.mark_missing(pos, &mut |row| emit(row, settings, objects, sink))
    }

    /// See [`Engine::count_misplaced`].
    pub fn count_misplaced(&mut self, n: u32) {
        self.engine.count_misplaced(n);
    }

    /// Ends the scan: remaining rows, the objects still open, then the end
    /// line with `lines_dropped` (score lines the output could not carry).
    /// Returns the scan's totals.
    pub fn finish(&mut self, lines_dropped: u32, sink: &mut impl LineSink) -> Totals {
        let Pipeline {
            engine,
            objects,
            settings,
        } = self;
        let mut totals = engine.finish(&mut |row| emit(row, settings, objects, sink));
        objects.finish_with(&mut |o| encode_object(o, sink), &mut totals);
        encode_end(&totals, lines_dropped, sink);
        totals
    }

    pub fn totals(&self) -> &Totals {
        self.engine.totals()
    }
}

/// A finished row's lines, then the lines of the objects it closes. Out
/// of line: one copy per sink type instead of one in each of the three
/// closures that call it (about 16 KB of flash each on the target).
#[inline(never)]
fn emit(row: &RowView, settings: &Settings, objects: &mut Objects, sink: &mut impl LineSink) {
    encode_row(
        row,
        settings.max_defect_lines_per_row,
        settings.scores,
        sink,
    );
    objects.push_row(row, &mut |o| encode_object(o, &mut *sink));
}
