//! What the engine reports: a position, its score and flags, a finished
//! row, the scan's totals. Plain data, shared by the engine, the object
//! labeller, the line encoder and the host's decoder.

use crate::channels::flags;

/// Scan position of a beam: `row = m2 - 1`, `col = m1 - 1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Position {
    pub row: u32,
    pub col: u32,
}

/// The result of one position, in the scorer's `Q(q)` score format.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PositionScore {
    /// Horizontal component `d(a(m1-1), a(m1+1))`.
    pub g0: u32,
    /// Vertical component `d(a(m2-1), a(m2+1))`.
    pub g1: u32,
    /// `floor(sqrt(g0² + g1²))`.
    pub mag: u32,
    /// How far the position's strongest channel reaches past its
    /// threshold: `floor(2^16 score / threshold)` of each channel that
    /// fired (threshold 0 taken as 1), the larger one, saturating; at least
    /// `2^16` for a defect, 0 for any other position.
    pub strength: u32,
    /// Horizontal power contrast of the neighbours, `Q15` ([`crate::channels::power`]).
    pub p0: u16,
    /// Vertical power contrast, `Q15`.
    pub p1: u16,
    /// `floor(sqrt(p0² + p1²))`, `Q15`.
    pub pmag: u16,
    /// Horizontal spread difference of the neighbours, `|q(+) - q(-)|`,
    /// `Q16` ([`crate::channels::spread`]).
    pub s0: u16,
    /// Vertical spread difference, `Q16`.
    pub s1: u16,
    /// `floor(sqrt(s0² + s1²))`, `Q16`, at most
    /// [`crate::channels::spread::SPREAD_MAX`].
    pub smag: u32,
    /// [`flags`] bits, the decisions ([`flags::CVM_DEFECT`],
    /// [`flags::POWER_DEFECT`], [`flags::SPREAD_DEFECT`]) included.
    pub flags: u8,
}

impl PositionScore {
    /// Whether any channel reached its threshold.
    pub const fn is_defect(&self) -> bool {
        self.flags & flags::DEFECT != 0
    }
}

/// `floor(2^16 s / thr)`, saturating. A threshold of 0 (every position
/// with data fires) gives `u32::MAX`: a defect's strength is at least
/// `2^16` whatever the threshold.
pub fn strength(s: u32, thr: u32) -> u32 {
    let q = (u64::from(s) << 16).checked_div(u64::from(thr));
    q.map_or(u32::MAX, |v| v.min(u32::MAX as u64) as u32)
}

/// Decisions for one finished row.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RowSummary {
    pub row: u32,
    /// Largest magnitude among positions with data (0 if none).
    pub max: u32,
    /// Column of the first position reaching `max` (None if no data).
    pub argmax: Option<u32>,
    /// Largest power magnitude among positions with data (0 if none).
    pub pmax: u32,
    /// Column of the first position reaching `pmax` (None if no data).
    pub pargmax: Option<u32>,
    /// Positions where a channel reaches its threshold.
    pub defects: u32,
    pub no_data: u32,
    pub dark: u32,
    pub saturated: u32,
}

/// A finished row: its summary and every position's score.
pub struct RowView<'s> {
    pub summary: RowSummary,
    pub scores: &'s [PositionScore],
    pub threshold: u32,
    pub power_threshold: u32,
}

/// Counters of one scan, reported in the end-of-scan line.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Totals {
    /// Rows emitted.
    pub rows: u32,
    /// Frames scored.
    pub frames: u32,
    /// Positions without data.
    pub missing: u32,
    pub dark: u32,
    pub saturated: u32,
    /// Positions where a channel reaches its threshold.
    pub defects: u32,
    /// Defect objects reported (see [`crate::objects`]).
    pub objects: u32,
    /// Defective positions left out of every object because the object
    /// table or a row's run table was full.
    pub unobjected: u32,
    /// Frames for a position already passed (repeat, out of order) or too
    /// far ahead to be plausible.
    pub rejected: u32,
    /// Frames beyond the last column.
    pub extra: u32,
    /// Frames of the wrong length.
    pub bad: u32,
    /// Scores that hit the top of their range.
    pub clipped: u32,
    /// Frames the caller placed at a wrong position and found out too late
    /// to move (see [`Engine::count_misplaced`]); the engine itself never
    /// misplaces a frame.
    pub misplaced: u32,
}
