//! The range of every field, each field alone (docs/protocol.md gives it
//! in the field's table): a line with a field outside it is refused as a
//! whole, [`ParseError::Range`] naming the field, however right its CRC,
//! since no encoder writes it. What needs two fields, or other lines, is
//! the stream decoder's to check (`dmap listen`), which keeps the line.

use super::fields::ParseError;
use super::header::{HeaderInfo, MAX_FW};
use super::line::Line;
use super::score::{SCORE_CHARS, ScoreValue, decode_score};
use crate::channels::flags;
use crate::channels::power::POWER_MAX;
use crate::channels::spread::SPREAD_MAX;

/// Smallest and largest score format `q` a scorer can have.
pub const Q_MIN: i32 = -120;
pub const Q_MAX: i32 = 62;

/// Largest detector axis.
const MAX_AXIS: u8 = crate::config::MAX_J as u8;

/// Largest `K` of square kernels (`b` with `k=S`).
const MAX_SQUARE_K: u8 = MAX_AXIS - 1;

/// `Ok` when `ok`, else the range error naming `what`.
fn bad(ok: bool, what: &'static str) -> Result<(), ParseError> {
    if ok {
        Ok(())
    } else {
        Err(ParseError::Range(what))
    }
}

/// Checks every field of `line` against its range.
pub(super) fn check(line: &Line<'_>) -> Result<(), ParseError> {
    match *line {
        Line::Header(ref h) => header(h),
        Line::Row { summary, .. } => bad(summary.pmax <= POWER_MAX, "pmax: 0 to 46340"),
        Line::Defect {
            pmag,
            smag,
            strength,
            flags: fl,
            ..
        } => {
            bad(u32::from(pmag) <= POWER_MAX, "pmag: 0 to 46340")?;
            bad(smag <= SPREAD_MAX, "smag: 0 to 92680")?;
            bad(strength >= 1 << 16, "strength: at least 65536")?;
            bad(
                defect_flags(fl),
                "flags: bit 4, 5 or 6 set; bits 0 and 7 clear; DARK and SATURATED not both",
            )
        }
        Line::Object(o) => {
            bad(o.area >= 1, "area: at least 1")?;
            bad(o.peak >= 1 << 16, "peak: at least 65536")?;
            bad(
                u32::from(o.peak_power) <= POWER_MAX,
                "peak_power: 0 to 46340",
            )?;
            bad(o.peak_spread <= SPREAD_MAX, "peak_spread: 0 to 92680")?;
            bad(o.channels != 0, "channels: a sum of 16, 32 and 64")
        }
        Line::Scores { chars, .. } => {
            for c in chars.chunks(SCORE_CHARS) {
                bad(
                    decode_score(c).is_some_and(|v| position(&v)),
                    "a position of an S line: see the S line's rules",
                )?;
            }
            Ok(())
        }
        Line::End(_) => Ok(()),
    }
}

fn header(h: &HeaderInfo<'_>) -> Result<(), ParseError> {
    let axis = 1..=MAX_AXIS;
    bad(
        axis.contains(&h.j1) && axis.contains(&h.j2),
        "j: each axis 1 to 16",
    )?;
    bad(
        h.firmware.len() <= MAX_FW
            && h.firmware
                .bytes()
                .all(|b| b.is_ascii_graphic() && b != b',' && b != b'*'),
        "fw: at most 24 printable ASCII characters",
    )?;
    bad(h.cols >= 1, "cols: at least 1")?;
    bad(
        h.kernels == b'P' || h.kernel_size <= MAX_SQUARE_K,
        "b: 0 to 15 with square kernels",
    )?;
    bad(
        match h.kernels {
            b'S' => h.weights == "unit",
            _ => matches!(h.weights, "uniform" | "unit" | "separable"),
        },
        "w: uniform, unit or separable (unit with square kernels)",
    )?;
    bad(h.full_scale >= 1, "fs: 1 to 65535")?;
    bad((Q_MIN..=Q_MAX).contains(&h.q), "q: -120 to 62")?;
    bad(h.boots >= 1, "boots: at least 1")
}

/// A `D` line's flags: a defect (bit 4, 5 or 6) with data (bit 0 clear),
/// no bit beyond 6, and never both DARK and SATURATED (a dark map has no
/// sample at full scale, which is at least 1).
fn defect_flags(fl: u8) -> bool {
    fl & flags::DEFECT != 0 && fl & flags::NO_DATA == 0 && fl < 128 && !dark_and_saturated(fl)
}

fn dark_and_saturated(fl: u8) -> bool {
    fl & (flags::DARK | flags::SATURATED) == flags::DARK | flags::SATURATED
}

/// One position of an `S` line: without data, nothing else (flags
/// `NO_DATA` alone, the three magnitudes 0); with data, a power magnitude
/// of at most 46340, a spread magnitude of at most 92680, never DARK and
/// SATURATED together, and `CLIPPED` exactly
/// when the magnitude is at the top of its range (which is then a
/// distance defect whatever the threshold).
fn position(v: &ScoreValue) -> bool {
    if v.flags & flags::NO_DATA != 0 {
        return v.flags == flags::NO_DATA && v.mag == 0 && v.pmag == 0 && v.smag == 0;
    }
    let clipped = v.flags & flags::CLIPPED != 0;
    u32::from(v.pmag) <= POWER_MAX
        && v.smag <= SPREAD_MAX
        && !dark_and_saturated(v.flags)
        && clipped == (v.mag == u32::MAX)
        && (!clipped || v.flags & flags::CVM_DEFECT != 0)
}
