//! The buffer sizes both boards share: how many defect lines a row lists,
//! how many beam records acquisition and scoring pass between them, and
//! how much of the output queue stays free for the lines that are never
//! dropped.

use crate::queue::LineQueue;
use cvm_core::protocol::{MAX_LINE, MAX_ROW_LINE, SCORES_PER_LINE};

/// Defect (`D`) lines listed per row at most; the row line carries the
/// full count.
pub const MAX_DEFECT_LINES_PER_ROW: u16 = 16;

/// Beam records between acquisition and scoring (see
/// `cvm_fw_app::acquire`): at least two more than the frame buffers.
pub const BEAM_LOG: usize = 128;

/// Queue bytes kept free for keep lines, for scans of up to `max_cols`
/// columns: the most one scoring step can produce is a scan's end (two
/// rows, their score lines promoted to keep lines, and the end line), the
/// next scan's header, and two more rows (a held beam placed with its
/// successor); a row is one `R` line and at most
/// [`MAX_DEFECT_LINES_PER_ROW`] `D` lines, and every open object can close
/// in that burst (one `O` line each).
pub const fn keep_reserve(max_cols: usize) -> usize {
    let row = 1 + MAX_DEFECT_LINES_PER_ROW as usize;
    let score_lines = max_cols.div_ceil(SCORES_PER_LINE);
    // Each object closes once: at most every open one in such a burst.
    let objects = cvm_core::objects::MAX_OBJECTS;
    // The header and the end line are the only lines longer than a row's.
    (4 * row + 2 * score_lines + objects) * LineQueue::<1>::cost(MAX_ROW_LINE)
        + 2 * LineQueue::<1>::cost(MAX_LINE)
}

/// A queue must leave room for score lines besides the keep reserve.
pub const fn queue_fits(bytes: usize, max_cols: usize) -> bool {
    bytes > 2 * keep_reserve(max_cols)
}
