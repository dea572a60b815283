//! Decoding a received line: its CRC checked first, then its type, then
//! the fields by the parser beside that line's encoder. Nothing is
//! allocated and the record borrows from the line, so a gateway on another
//! microcontroller decodes with this very code.

use super::end::parse_end;
use super::fields::{Fields, ParseError};
use super::frame::checked_body;
use super::header::parse_header;
use super::line::Line;
use super::object::parse_object;
use super::ranges;
use super::row::{parse_defect, parse_row, parse_scores};

/// Parses one line (with or without its trailing `\r\n`/`\n`): its CRC,
/// its fields, and each field's range.
pub fn parse(line: &[u8]) -> Result<Line<'_>, ParseError> {
    let body = checked_body(line)?;
    let mut it = body.split(|&b| b == b',');
    let kind = it.next().ok_or(ParseError::Format)?;
    let mut f = Fields(it);
    let line = match kind {
        b"H" => Line::Header(parse_header(&mut f)?),
        b"R" => parse_row(&mut f)?,
        b"D" => parse_defect(&mut f)?,
        b"O" => Line::Object(parse_object(&mut f)?),
        b"S" => parse_scores(&mut f)?,
        b"E" => Line::End(parse_end(&mut f)?),
        _ => return Err(ParseError::Type),
    };
    f.end()?;
    ranges::check(&line)?;
    Ok(line)
}
