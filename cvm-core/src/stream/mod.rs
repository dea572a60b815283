//! The streaming engine: beams arrive one map at a time in raster order and
//! each position's gradient (Eq. 1) is emitted as soon as it is final.
//!
//! # Window
//!
//! The gradient of row `r` needs rows `r-1` and `r+1`. The engine keeps the
//! prepared state (embedding) of two rows in two buffers, row `r` in buffer
//! `r % 2`. When beam `(r+1, c)` arrives, slot `c` of its buffer still holds
//! `(r-1, c)`: the new map is embedded straight into that slot, and the
//! vertical component of `(r, c)`, the distance between the two, is summed
//! by the embedding's last pass word by word before it overwrites each word
//! ([`Scorer::prepare_map`]). The horizontal component of
//! `(r+1, c-1)` is computed next from slots `c-2` and `c`. So the window is
//! two rows of state and no map in flight, and row `r` is final (and
//! emitted) when row `r+1` is complete.
//!
//! # Decisions
//!
//! A position is decided (magnitudes, channels, strength, its row's
//! summary) as soon as it is final: `(r-1, c)` when beam `(r, c)` is in
//! (`decide.rs`). Told the scan's row count ([`Engine::set_rows`]), the
//! engine decides the last row as its beams arrive too, and holds the
//! last two rows back: once the last beam is in nothing is left to
//! compute, and the caller can act on the final rows ([`Engine::unsent`])
//! before their lines are encoded.
//!
//! # Gaps
//!
//! Frames carry their position. A position that receives no frame (a gap in
//! a row, a short row, a skipped row, an explicit [`Engine::mark_missing`])
//! is reported with [`flags::NO_DATA`] and counted; its neighbours treat it
//! like the scan border: the missing neighbour is replaced by the map itself
//! (docs/method.md §3). A frame for a position already passed (repeat, out of
//! order) is rejected and counted, one beyond the last column is counted as
//! extra; neither shifts any later position.

mod decide;
mod results;
mod window;

pub use results::{Position, PositionScore, RowSummary, RowView, Totals, strength};

use crate::channels::flags;
use crate::channels::power::POWER_OFF;
use crate::channels::spread::SPREAD_OFF;
use crate::scorer::{Scorer, Scratch};

/// Why an engine could not be set up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EngineError {
    /// `cols` is 0 or above the engine's compile-time capacity.
    Columns,
    /// A row buffer is shorter than [`row_words_for`], or the near buffer
    /// is not empty but shorter than [`near_words`].
    Buffer,
    /// A square-kernel scorer without its factor table
    /// ([`Scorer::with_factors`]): it could not prepare a single map.
    Factors,
}

impl core::fmt::Display for EngineError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            EngineError::Columns => "no columns, or more than the engine holds",
            EngineError::Buffer => "a row buffer or the near buffer is too short for the maps",
            EngineError::Factors => "square kernels without their factor table",
        })
    }
}

/// What happened to a pushed frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PushOutcome {
    Scored,
    /// Already passed, or implausibly far ahead: counted, not scored.
    Rejected,
    /// Beyond the last column: counted, not scored.
    Extra,
    /// Wrong length: its position is reported without data.
    Bad,
}

/// A frame more than this many rows ahead of the current one is rejected
/// rather than turning the gap into that many empty rows.
pub const MAX_ROW_JUMP: u32 = 1024;

/// `i32` words of one row buffer for paper kernels (`J1 J2` words per map).
pub const fn row_words(cols: usize, j1: usize, j2: usize) -> usize {
    cols * j1 * j2
}

/// `i32` words of one row buffer for any configuration
/// ([`crate::Config::state_words`] per map).
pub const fn row_words_for(cols: usize, config: &crate::Config) -> usize {
    cols * config.state_words()
}

/// Words of the buffer for the current row's last three maps
/// ([`Engine::with_near`]).
pub const fn near_words(config: &crate::Config) -> usize {
    3 * config.state_words()
}

/// Bytes of engine state for `cols` columns: the two row buffers plus the
/// per-column flags, powers and spreads and two rows of results.
pub const fn window_bytes(cols: usize, j1: usize, j2: usize) -> usize {
    2 * row_words(cols, j1, j2) * 4 + cols * (2 + 8 + 4 + 2 * core::mem::size_of::<PositionScore>())
}

/// The streaming engine, for at most `MAX_COLS` columns.
pub struct Engine<'a, const MAX_COLS: usize> {
    scorer: &'a Scorer,
    /// Samples per frame.
    cells: usize,
    /// Words per prepared map in a row buffer.
    words: usize,
    cols: usize,
    threshold: u32,
    power_threshold: u32,
    spread_threshold: u32,
    bufs: [&'a mut [i32]; 2],
    /// Empty, or three maps: the current row's last three, column `c` in
    /// map `c % 3`, each also copied to its row buffer. The horizontal
    /// distances read them here instead of from the row buffers (see
    /// [`Engine::with_near`]).
    near: &'a mut [i32],
    /// Flags of each slot of each buffer; `NO_DATA` where no state is held.
    meta: [[u8; MAX_COLS]; 2],
    /// Power (sample sum) of the map in each slot of each buffer.
    powers: [[u32; MAX_COLS]; 2],
    /// Spread `q` ([`crate::channels::spread`]) of the map in each slot of each buffer.
    spreads: [[u16; MAX_COLS]; 2],
    /// Results of two rows: `results[cur]` is the row being received (`g0`
    /// filled as beams arrive), the other one the previous row (`g0` final,
    /// `g1` filled as the current row arrives). A finished row changes
    /// their roles instead of copying `MAX_COLS` scores.
    results: [[PositionScore; MAX_COLS]; 2],
    /// Index (0 or 1) of the row being received in `results`.
    cur: usize,
    /// Each result buffer's row summary, built as its positions are decided.
    sums: [RowSummary; 2],
    /// Each result buffer's positions decided so far (the first ones).
    decided: [usize; 2],
    /// Rows of a scan, when known (0: not known; see [`Engine::set_rows`]).
    rows: u32,
    current: Option<u32>,
    next_col: usize,
    pending: Option<u32>,
    /// A final row not yet put out, in `results[cur]`: the scan's last
    /// row but one, held back when the last row is complete (see
    /// [`Engine::close`]).
    held: Option<u32>,
    totals: Totals,
    scratch: Scratch,
}

impl<'a, const MAX_COLS: usize> Engine<'a, MAX_COLS> {
    pub fn new(
        scorer: &'a Scorer,
        cols: u32,
        threshold: u32,
        row_a: &'a mut [i32],
        row_b: &'a mut [i32],
    ) -> Result<Self, EngineError> {
        Self::with_near(scorer, cols, threshold, row_a, row_b, &mut [])
    }

    /// [`Engine::new`] with a buffer for the current row's last three maps
    /// ([`near_words`] long; empty: none). Every map is then written to
    /// `near` and copied from there to its row buffer (eight words per
    /// `LDM`/`STM` pair on the Cortex-M), and the horizontal distance reads
    /// its two maps from `near`: on a board whose row buffers are in slow
    /// memory (the H743's AXI SRAM and SRAM1-3) and `near` in fast memory
    /// (DTCM), that trades a fast copy for two slow loads per word. The
    /// results are the same.
    #[inline(always)]
    pub fn with_near(
        scorer: &'a Scorer,
        cols: u32,
        threshold: u32,
        row_a: &'a mut [i32],
        row_b: &'a mut [i32],
        near: &'a mut [i32],
    ) -> Result<Self, EngineError> {
        let cols = cols as usize;
        if cols == 0 || cols > MAX_COLS {
            return Err(EngineError::Columns);
        }
        if scorer.needs_factors() {
            return Err(EngineError::Factors);
        }
        let cells = scorer.cells();
        let words = row_words_for(cols, scorer.config());
        if row_a.len() < words || row_b.len() < words {
            return Err(EngineError::Buffer);
        }
        if !near.is_empty() && near.len() < near_words(scorer.config()) {
            return Err(EngineError::Buffer);
        }
        Ok(Engine {
            scorer,
            cells,
            words: scorer.state_words(),
            cols,
            threshold,
            power_threshold: POWER_OFF,
            spread_threshold: SPREAD_OFF,
            bufs: [row_a, row_b],
            near,
            meta: [[flags::NO_DATA; MAX_COLS]; 2],
            powers: [[0; MAX_COLS]; 2],
            spreads: [[0; MAX_COLS]; 2],
            results: [[PositionScore::default(); MAX_COLS]; 2],
            cur: 0,
            sums: [RowSummary::default(); 2],
            decided: [0; 2],
            rows: 0,
            current: None,
            next_col: 0,
            pending: None,
            held: None,
            totals: Totals::default(),
            scratch: Scratch::new(),
        })
    }

    pub fn cols(&self) -> u32 {
        self.cols as u32
    }

    pub fn threshold(&self) -> u32 {
        self.threshold
    }

    /// Scores the next scan with `cols` columns and this threshold. Meant
    /// for between scans: the scan in progress, if any, is forgotten (as
    /// by [`Engine::reset`]). Refused, and nothing changed, when `cols` is
    /// 0, above the capacity, or more than the row buffers hold.
    pub fn reconfigure(&mut self, cols: u32, threshold: u32) -> Result<(), EngineError> {
        let c = cols as usize;
        if c == 0 || c > MAX_COLS {
            return Err(EngineError::Columns);
        }
        let words = row_words_for(c, self.scorer.config());
        if self.bufs.iter().any(|b| b.len() < words) {
            return Err(EngineError::Buffer);
        }
        self.reset();
        self.cols = c;
        self.threshold = threshold;
        Ok(())
    }

    /// Sets the power channel's threshold (`Q15`; [`POWER_OFF`], the
    /// default, never fires).
    pub fn set_power_threshold(&mut self, t: u32) {
        self.power_threshold = t;
    }

    pub fn power_threshold(&self) -> u32 {
        self.power_threshold
    }

    /// Sets the spread channel's threshold (`Q16`). [`SPREAD_OFF`], the
    /// default, turns the channel off: no map's spread is measured, and
    /// every position's `s0`, `s1` and `smag` are 0. Any other value
    /// measures it (a threshold above [`crate::channels::spread::SPREAD_MAX`]
    /// measures without ever firing). Meant for between scans, as
    /// [`Engine::reconfigure`]: the maps already held keep the spread they
    /// were measured with.
    pub fn set_spread_threshold(&mut self, t: u32) {
        self.spread_threshold = t;
    }

    pub fn spread_threshold(&self) -> u32 {
        self.spread_threshold
    }

    pub fn scorer(&self) -> &Scorer {
        self.scorer
    }

    pub fn totals(&self) -> &Totals {
        &self.totals
    }

    /// Scores the frame of `pos`; finished rows go to `out`.
    pub fn push(
        &mut self,
        pos: Position,
        frame: &[u16],
        out: &mut impl FnMut(&RowView),
    ) -> PushOutcome {
        self.place(pos, Some(frame), out)
    }

    /// Counts `n` frames already pushed that the caller has since found to
    /// belong to other positions (the firmware's beam sequencer, after a
    /// short row). Their scores are out, so they can only be reported: the
    /// end line carries the count.
    pub fn count_misplaced(&mut self, n: u32) {
        self.totals.misplaced = self.totals.misplaced.saturating_add(n);
    }

    /// Records that `pos` will receive no frame (e.g. a detector overrun).
    pub fn mark_missing(&mut self, pos: Position, out: &mut impl FnMut(&RowView)) -> PushOutcome {
        self.place(pos, None, out)
    }

    /// Rows of every scan from now on (0, the default: not known). Known,
    /// the last row is decided as its beams arrive, its vertical
    /// component by the border rule, instead of at [`Engine::finish`],
    /// and the row before it is held back with it: once the last beam is
    /// in, both rows are final and neither is out yet ([`Engine::unsent`]),
    /// so that a board can act on their decisions before it encodes their
    /// lines. The rows put out are the same either way for a scan of
    /// exactly `rows` rows. A beam of a row past `rows` finds row
    /// `rows - 1` decided already, with the border rule.
    pub fn set_rows(&mut self, rows: u32) {
        self.rows = rows;
    }

    /// Completes the scan's rows without putting any out: the row in
    /// flight is completed (its remaining positions without data) and the
    /// last row decided with the border rule. Then [`Engine::unsent`]
    /// shows what [`Engine::finish`] puts out.
    pub fn close(&mut self) {
        if self.current.is_some() {
            self.complete_row();
        }
        self.decide_last();
    }

    /// The rows that are final and not yet out, oldest first: after
    /// [`Engine::close`], the scan's last rows (one, or two when the
    /// row count is known).
    pub fn unsent(&self, f: &mut dyn FnMut(&RowView)) {
        if self.current.is_some() {
            return;
        }
        if self.held.is_some() {
            f(&self.view(self.cur & 1));
        }
        let rb = (self.cur ^ 1) & 1;
        if self.pending.is_some() && self.decided[rb] >= self.cols {
            f(&self.view(rb));
        }
    }

    /// Ends the scan: [`Engine::close`], then the rows not yet out are
    /// put out, and the engine is ready for the next scan. Returns the
    /// totals.
    pub fn finish(&mut self, out: &mut impl FnMut(&RowView)) -> Totals {
        self.close();
        self.put_out_held(&mut *out);
        if self.pending.is_some() {
            self.emit((self.cur ^ 1) & 1, &mut *out);
        }
        let totals = self.totals;
        self.reset();
        totals
    }

    /// Forgets the scan in progress without emitting anything.
    pub fn reset(&mut self) {
        self.meta = [[flags::NO_DATA; MAX_COLS]; 2];
        self.current = None;
        self.next_col = 0;
        self.pending = None;
        self.held = None;
        self.sums = [RowSummary::default(); 2];
        self.decided = [0; 2];
        self.totals = Totals::default();
    }

    /// Row `r` is the scan's last, by the row count given.
    fn is_last(&self, r: u32) -> bool {
        r.checked_add(1) == Some(self.rows)
    }

    fn place(
        &mut self,
        pos: Position,
        frame: Option<&[u16]>,
        out: &mut impl FnMut(&RowView),
    ) -> PushOutcome {
        let col = pos.col as usize;
        if col >= self.cols {
            self.totals.extra += 1;
            return PushOutcome::Extra;
        }
        // The row the next beam belongs to if nothing is skipped.
        let expected = match (self.current, self.pending) {
            (Some(r), _) => r,
            (None, Some(p)) => p + 1,
            (None, None) => 0,
        };
        let behind = pos.row < expected || (Some(pos.row) == self.current && col < self.next_col);
        if behind || pos.row - expected > MAX_ROW_JUMP {
            self.totals.rejected += 1;
            return PushOutcome::Rejected;
        }
        while self.current != Some(pos.row) {
            match self.current {
                Some(r) => self.end_row(r, out),
                None => {
                    // The row held back goes out before its buffer is reused.
                    self.put_out_held(&mut *out);
                    let r = self.pending.map_or(0, |p| p + 1);
                    self.current = Some(r);
                    self.next_col = 0;
                    let rb = self.cur & 1;
                    self.sums[rb] = RowSummary {
                        row: r,
                        ..RowSummary::default()
                    };
                    self.decided[rb] = 0;
                }
            }
        }
        while self.next_col < col {
            self.resolve(None);
        }
        let outcome = match frame {
            Some(f) if f.len() != self.cells => {
                self.totals.bad += 1;
                self.resolve(None);
                PushOutcome::Bad
            }
            f => {
                self.resolve(f);
                PushOutcome::Scored
            }
        };
        if self.next_col == self.cols
            && let Some(r) = self.current
        {
            self.end_row(r, out);
        }
        outcome
    }

    fn cur_row(&mut self) -> &mut [PositionScore; MAX_COLS] {
        &mut self.results[self.cur & 1]
    }

    fn slot(&self, buf: usize, col: usize) -> &[i32] {
        let start = col * self.words;
        self.bufs
            .get(buf)
            .and_then(|b| b.get(start..start + self.words))
            .unwrap_or(&[])
    }

    /// The map of column `col` of the current row (buffer `buf`): from
    /// `near` when there is one.
    fn recent(&self, buf: usize, col: usize) -> &[i32] {
        if self.near.is_empty() {
            return self.slot(buf, col);
        }
        let start = (col % 3) * self.words;
        self.near.get(start..start + self.words).unwrap_or(&[])
    }

    /// The current row ends: remaining positions have no data, the last
    /// position's horizontal component is final, and the row becomes
    /// pending. The previous row, decided while this one came in, is held
    /// back: it goes out at once ([`Engine::put_out_held`]) unless this row
    /// is the scan's last.
    fn complete_row(&mut self) {
        let Some(r) = self.current else { return };
        while self.next_col < self.cols {
            self.resolve(None);
        }
        let b = (r % 2) as usize;
        self.horizontal(b, self.cols - 1, None);
        if self.is_last(r) {
            self.decide_upto(self.cur, self.cols);
        }
        // Nothing is held here: a held row goes out before the next row
        // starts and right after every other row's end.
        self.held = self.pending;
        self.cur ^= 1;
        self.pending = Some(r);
        self.current = None;
        self.next_col = 0;
    }

    /// Row `r`, the one in flight, is complete: the row before it goes
    /// out, unless `r` is the scan's last (both then wait for
    /// [`Engine::finish`]).
    fn end_row(&mut self, r: u32, out: &mut impl FnMut(&RowView)) {
        self.complete_row();
        if !self.is_last(r) {
            self.put_out_held(out);
        }
    }

    fn put_out_held(&mut self, out: &mut impl FnMut(&RowView)) {
        if self.held.take().is_some() {
            self.emit(self.cur & 1, out);
        }
    }
}
