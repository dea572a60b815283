//! The end (`E`) line: the scan's totals, written last.

use super::fields::{Fields, ParseError};
use super::frame::{LineBuf, LineSink, Priority};
use crate::stream::Totals;
use crate::verdict::Verdict;

/// `E,rows=..,frames=..,missing=..,dark=..,sat=..,defects=..,obj=..,unobj=..,rejected=..,extra=..,bad=..,clipped=..,misplaced=..,dropped=..,verdict=..`
pub fn encode_end(t: &Totals, dropped: u32, verdict: Verdict, sink: &mut impl LineSink) {
    let mut l = LineBuf::new(b'E');
    let mut t = *t;
    for (key, field) in END_FIELDS {
        l.kv_u64(key.as_bytes(), *field(&mut t) as u64);
    }
    l.kv_u64(DROPPED.as_bytes(), dropped as u64);
    l.field(VERDICT.as_bytes());
    l.byte(b'=');
    l.bytes(verdict.as_str().as_bytes());
    sink.line(l.finish(), Priority::Keep);
}

/// The end line's keys and the [`Totals`] field each one carries, in the
/// order of the line; [`DROPPED`] follows them. The encoder, the parser and
/// `dmap listen` read this one list.
pub const END_FIELDS: [(&str, TotalsField); 13] = [
    ("rows", |t| &mut t.rows),
    ("frames", |t| &mut t.frames),
    ("missing", |t| &mut t.missing),
    ("dark", |t| &mut t.dark),
    ("sat", |t| &mut t.saturated),
    ("defects", |t| &mut t.defects),
    ("obj", |t| &mut t.objects),
    ("unobj", |t| &mut t.unobjected),
    ("rejected", |t| &mut t.rejected),
    ("extra", |t| &mut t.extra),
    ("bad", |t| &mut t.bad),
    ("clipped", |t| &mut t.clipped),
    ("misplaced", |t| &mut t.misplaced),
];

/// One field of [`Totals`], for reading and writing.
pub type TotalsField = fn(&mut Totals) -> &mut u32;

/// The end line's last key: score lines the link could not carry.
pub const DROPPED: &str = "dropped";

/// The key after [`DROPPED`], the last: the part's verdict.
pub const VERDICT: &str = "verdict";

/// Totals and verdict as the end line carries them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EndInfo {
    pub totals: Totals,
    pub dropped: u32,
    pub verdict: Verdict,
}

pub(super) fn parse_end<'s>(
    f: &mut Fields<'s, impl Iterator<Item = &'s [u8]>>,
) -> Result<EndInfo, ParseError> {
    let mut totals = Totals::default();
    for (key, field) in END_FIELDS {
        *field(&mut totals) = f.key_u32(key)?;
    }
    let dropped = f.key_u32(DROPPED)?;
    let verdict = Verdict::parse(f.key(VERDICT)?).ok_or(ParseError::Format)?;
    Ok(EndInfo {
        totals,
        dropped,
        verdict,
    })
}
