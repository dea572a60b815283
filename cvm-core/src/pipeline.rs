//! Engine plus line encoder: frames in, protocol lines out. The host's
//! `dmap stream` and both firmware boards drive exactly this type, which is
//! what makes their output byte-identical.

use crate::protocol::{HeaderInfo, LineSink, ResetCause, encode_end, encode_header, encode_row};
use crate::scorer::Scorer;
use crate::stream::{Engine, EngineError, Position, PushOutcome, Totals};

/// What the pipeline reports besides the scores.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Settings {
    /// Columns (beams per row) of the scan.
    pub cols: u32,
    /// Integer magnitude at or above which a position is a defect.
    pub threshold: u32,
    /// Emit per-position score (`S`) lines.
    pub scores: bool,
    /// At most this many defect (`D`) lines per row, the strongest; the row
    /// line carries the full count, so a truncated list is visible, and the
    /// header the cap (`dcap`).
    pub max_defect_lines_per_row: u16,
    pub firmware_version: &'static str,
    /// Why the board last started (`rst`; [`ResetCause::PowerOn`] on the host).
    pub reset_cause: ResetCause,
    /// Starts since power-on, this one included (`boots`; 1 on the host).
    pub boots: u32,
}

pub struct Pipeline<'a, const MAX_COLS: usize> {
    engine: Engine<'a, MAX_COLS>,
    settings: Settings,
}

impl<'a, const MAX_COLS: usize> Pipeline<'a, MAX_COLS> {
    pub fn new(
        scorer: &'a Scorer,
        settings: Settings,
        row_a: &'a mut [i32],
        row_b: &'a mut [i32],
    ) -> Result<Self, EngineError> {
        let engine = Engine::new(scorer, settings.cols, settings.threshold, row_a, row_b)?;
        Ok(Pipeline { engine, settings })
    }

    /// Starts a scan: the header line.
    pub fn begin(&mut self, sink: &mut impl LineSink) {
        let h = HeaderInfo::new(self.engine.scorer(), &self.settings);
        encode_header(&h, sink);
    }

    pub fn push(&mut self, pos: Position, frame: &[u16], sink: &mut impl LineSink) -> PushOutcome {
        let (md, sc) = (self.settings.max_defect_lines_per_row, self.settings.scores);
        self.engine
            .push(pos, frame, &mut |row| encode_row(row, md, sc, sink))
    }

    /// Records that `pos` receives no frame (detector overrun, SPI error).
    pub fn mark_missing(&mut self, pos: Position, sink: &mut impl LineSink) -> PushOutcome {
        let (md, sc) = (self.settings.max_defect_lines_per_row, self.settings.scores);
        self.engine
            .mark_missing(pos, &mut |row| encode_row(row, md, sc, sink))
    }

    /// See [`Engine::count_misplaced`].
    pub fn count_misplaced(&mut self, n: u32) {
        self.engine.count_misplaced(n);
    }

    /// Ends the scan: remaining rows, then the end line with `lines_dropped`
    /// (score lines the output could not carry). Returns the scan's totals.
    pub fn finish(&mut self, lines_dropped: u32, sink: &mut impl LineSink) -> Totals {
        let (md, sc) = (self.settings.max_defect_lines_per_row, self.settings.scores);
        let totals = self.engine.finish(&mut |row| encode_row(row, md, sc, sink));
        encode_end(&totals, lines_dropped, sink);
        totals
    }

    pub fn totals(&self) -> &Totals {
        self.engine.totals()
    }
}
