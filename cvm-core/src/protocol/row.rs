//! A finished row's lines: its summary (`R`), its strongest defects (`D`)
//! and its scores (`S`).

use super::fields::{Fields, ParseError, parse_u32};
use super::frame::{LineBuf, LineSink, Priority};
use super::line::Line;
use super::score::{SCORE_CHARS, SCORES_PER_LINE, decode_score, encode_score};
use crate::stream::{PositionScore, RowSummary, RowView};

/// Encodes a finished row: the `R` summary, up to `max_defect_lines` `D`
/// lines (the strongest defects, strongest first; equal strengths by
/// column, leftmost first), and with `scores` its `S` lines.
pub fn encode_row(view: &RowView, max_defect_lines: u16, scores: bool, sink: &mut impl LineSink) {
    let s = &view.summary;
    let listed = s.defects.min(max_defect_lines as u32);
    let mut l = LineBuf::new(b'R');
    l.byte(b',');
    l.u64(s.row as u64);
    l.byte(b',');
    l.u64(s.max as u64);
    l.byte(b',');
    match s.argmax {
        Some(c) => l.u64(c as u64),
        None => l.byte(b'-'),
    }
    l.byte(b',');
    l.u64(s.pmax as u64);
    l.byte(b',');
    match s.pargmax {
        Some(c) => l.u64(c as u64),
        None => l.byte(b'-'),
    }
    for v in [s.defects, listed, s.no_data, s.dark, s.saturated] {
        l.byte(b',');
        l.u64(v as u64);
    }
    sink.line(l.finish(), Priority::Keep);

    let mut last = None;
    for _ in 0..listed {
        let Some((c, p)) = next_defect(view, last) else {
            break;
        };
        let mut l = LineBuf::new(b'D');
        for v in [
            s.row,
            c as u32,
            p.mag,
            p.pmag as u32,
            p.smag,
            p.strength,
            p.flags as u32,
        ] {
            l.byte(b',');
            l.u64(v as u64);
        }
        sink.line(l.finish(), Priority::Keep);
        last = Some((p.strength, c));
    }

    if scores {
        for (chunk_no, chunk) in view.scores.chunks(SCORES_PER_LINE).enumerate() {
            let mut l = LineBuf::new(b'S');
            l.byte(b',');
            l.u64(s.row as u64);
            l.byte(b',');
            l.u64((chunk_no * SCORES_PER_LINE) as u64);
            l.byte(b',');
            for p in chunk {
                l.bytes(&encode_score(p));
            }
            sink.line(l.finish(), Priority::Droppable);
        }
    }
}

/// The defect listed after `last` (strength, column): the strongest one
/// below it in the order of `D` lines (strength down, then column up).
/// One pass over the row per line: no buffer, and at most the cap passes.
fn next_defect(view: &RowView, last: Option<(u32, usize)>) -> Option<(usize, PositionScore)> {
    let mut best: Option<(usize, PositionScore)> = None;
    for (c, p) in view.scores.iter().enumerate() {
        let defect = p.flags & crate::channels::flags::NO_DATA == 0 && p.is_defect();
        let after = match last {
            None => true,
            Some((m, lc)) => p.strength < m || (p.strength == m && c > lc),
        };
        // Columns ascend: a tie keeps the leftmost.
        if defect && after && best.is_none_or(|(_, b)| p.strength > b.strength) {
            best = Some((c, *p));
        }
    }
    best
}

pub(super) fn parse_row<'s>(
    f: &mut Fields<'s, impl Iterator<Item = &'s [u8]>>,
) -> Result<Line<'s>, ParseError> {
    let row = f.u32()?;
    let max = f.u32()?;
    let argmax = match f.next()? {
        b"-" => None,
        v => Some(parse_u32(v).ok_or(ParseError::Format)?),
    };
    let pmax = f.u32()?;
    let pargmax = match f.next()? {
        b"-" => None,
        v => Some(parse_u32(v).ok_or(ParseError::Format)?),
    };
    let [defects, listed, no_data, dark, saturated] =
        [f.u32()?, f.u32()?, f.u32()?, f.u32()?, f.u32()?];
    Ok(Line::Row {
        summary: RowSummary {
            row,
            max,
            argmax,
            pmax,
            pargmax,
            defects,
            no_data,
            dark,
            saturated,
        },
        listed,
    })
}

pub(super) fn parse_defect<'s>(
    f: &mut Fields<'s, impl Iterator<Item = &'s [u8]>>,
) -> Result<Line<'s>, ParseError> {
    let [row, col, mag] = [f.u32()?, f.u32()?, f.u32()?];
    let pmag = u16::try_from(f.u32()?).map_err(|_| ParseError::Format)?;
    let smag = f.u32()?;
    let strength = f.u32()?;
    let flags = u8::try_from(f.u32()?).map_err(|_| ParseError::Format)?;
    Ok(Line::Defect {
        row,
        col,
        mag,
        pmag,
        smag,
        strength,
        flags,
    })
}

pub(super) fn parse_scores<'s>(
    f: &mut Fields<'s, impl Iterator<Item = &'s [u8]>>,
) -> Result<Line<'s>, ParseError> {
    let row = f.u32()?;
    let col0 = f.u32()?;
    let chars = f.next()?;
    if chars.is_empty()
        || chars.len() % SCORE_CHARS != 0
        || chars.chunks(SCORE_CHARS).any(|c| decode_score(c).is_none())
    {
        return Err(ParseError::Format);
    }
    Ok(Line::Scores { row, col0, chars })
}
