//! The object (`O`) line: one defect object, when it closes.

use super::fields::{Fields, ParseError, parse_u64};
use super::frame::{LineBuf, LineSink, Priority};
use crate::objects::Object;

/// `O,id,row0,row1,col0,col1,area,peak,peak_row,peak_col,peak_mag,peak_power,peak_spread,centroid_row,centroid_col,channels`:
/// one defect object, when it closes.
pub fn encode_object(o: &Object, sink: &mut impl LineSink) {
    let mut l = LineBuf::new(b'O');
    for v in [
        o.id as u64,
        o.row0 as u64,
        o.row1 as u64,
        o.col0 as u64,
        o.col1 as u64,
        o.area as u64,
        o.peak as u64,
        o.peak_row as u64,
        o.peak_col as u64,
        o.peak_mag as u64,
        o.peak_power as u64,
        o.peak_spread as u64,
        o.centroid_row_q8,
        o.centroid_col_q8,
        o.channels as u64,
    ] {
        l.byte(b',');
        l.u64(v);
    }
    sink.line(l.finish(), Priority::Keep);
}

pub(super) fn parse_object<'s>(
    f: &mut Fields<'s, impl Iterator<Item = &'s [u8]>>,
) -> Result<Object, ParseError> {
    let e = ParseError::Format;
    let mut v = [0u32; 10];
    for x in &mut v {
        *x = f.u32()?;
    }
    let [
        id,
        row0,
        row1,
        col0,
        col1,
        area,
        peak,
        peak_row,
        peak_col,
        peak_mag,
    ] = v;
    let peak_power = u16::try_from(f.u32()?).map_err(|_| e)?;
    let peak_spread = f.u32()?;
    let centroid_row_q8 = parse_u64(f.next()?).ok_or(e)?;
    let centroid_col_q8 = parse_u64(f.next()?).ok_or(e)?;
    let channels = u8::try_from(f.u32()?).map_err(|_| e)?;
    if row0 > row1 || col0 > col1 || channels & !crate::channels::flags::DEFECT != 0 {
        return Err(e);
    }
    Ok(Object {
        id,
        row0,
        row1,
        col0,
        col1,
        area,
        peak,
        peak_row,
        peak_col,
        peak_mag,
        peak_power,
        peak_spread,
        channels,
        centroid_row_q8,
        centroid_col_q8,
    })
}
