//! One received line, decoded: the record [`super::parse`] returns,
//! borrowing from the line it was given.

use super::end::EndInfo;
use super::header::HeaderInfo;
use crate::objects::Object;
use crate::stream::RowSummary;

/// One decoded line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Line<'s> {
    Header(HeaderInfo<'s>),
    Row {
        summary: RowSummary,
        listed: u32,
    },
    Defect {
        row: u32,
        col: u32,
        mag: u32,
        pmag: u16,
        smag: u32,
        strength: u32,
        flags: u8,
    },
    Object(Object),
    /// Scores of `col0..col0 + chars.len() / 12`; decode with [`super::decode_score`].
    Scores {
        row: u32,
        col0: u32,
        chars: &'s [u8],
    },
    End(EndInfo),
}
