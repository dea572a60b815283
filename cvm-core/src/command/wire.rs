//! What requests and replies share: the framing check of a received line,
//! and reading its fields.

use crate::protocol::crc16;

/// Version of the protocol, carried in the `status` reply (`pv=`): the
/// result lines' (the command channel came with version 6), so that a
/// client knows which lines the board writes before it reads them.
pub const VERSION: u32 = crate::protocol::VERSION;
/// Longest request or reply line, its `\n` included. Shorter than the
/// result lines' `protocol::MAX_LINE` (whose end line grew with the part
/// verdict): every command line fits the 256 bytes a small gateway's
/// buffer is made for.
pub const MAX_LINE: usize = 256;
/// Type letter of a request line.
pub const REQUEST: u8 = b'C';
/// Type letter of a reply line.
pub const REPLY: u8 = b'A';
/// Most scans one `calibrate` may take.
pub const MAX_CALIBRATION_SCANS: u16 = 100;
/// Largest target rate a `calibrate` may ask for, in false positions per
/// million parts: one per part.
pub const MAX_CALIBRATION_RATE_PPM: u32 = 1_000_000;

/// Why a received line's frame is not accepted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum FrameError {
    /// No `*XXXX` trailer (truncated or garbled).
    NoChecksum,
    /// The trailer does not match the line.
    Checksum,
}

/// The body of a line (before its `*`), once its CRC has been checked.
/// One `\n`, then one `\r`, are stripped first, as for the result lines.
pub(super) fn checked_body(line: &[u8]) -> Result<&[u8], FrameError> {
    let line = line.strip_suffix(b"\n").unwrap_or(line);
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    let star = line
        .iter()
        .rposition(|&b| b == b'*')
        .ok_or(FrameError::NoChecksum)?;
    let (body, tail) = line.split_at(star);
    let hex = tail.get(1..).unwrap_or(&[]);
    if hex.len() != 4 {
        return Err(FrameError::NoChecksum);
    }
    let mut want: u16 = 0;
    for &c in hex {
        let d = match c {
            b'0'..=b'9' => c - b'0',
            b'A'..=b'F' => c - b'A' + 10,
            _ => return Err(FrameError::NoChecksum),
        };
        want = (want << 4) | d as u16;
    }
    if crc16(body) == want {
        Ok(body)
    } else {
        Err(FrameError::Checksum)
    }
}

/// A decimal number without sign: 1 to 10 digits that fit 32 bits.
pub(super) fn parse_u32(s: &[u8]) -> Option<u32> {
    // Leading zeros are allowed, however many: the value counts, not the
    // digits (docs/commands.md, "Framing").
    if s.is_empty() || !s.iter().all(u8::is_ascii_digit) {
        return None;
    }
    let first = s.iter().position(|&c| c != b'0').unwrap_or(s.len());
    let significant = s.get(first..)?;
    if significant.len() > 10 {
        return None;
    }
    let mut v: u64 = 0;
    for &c in significant {
        v = v * 10 + (c - b'0') as u64;
    }
    u32::try_from(v).ok()
}

/// `key=value`, checking the key.
pub(super) fn kv<'s>(field: &'s [u8], key: &[u8]) -> Option<&'s [u8]> {
    field.strip_prefix(key)?.strip_prefix(b"=")
}

/// Splits `s` at its first `sep`.
pub(super) fn split_once(s: &[u8], sep: u8) -> Option<(&[u8], &[u8])> {
    let i = s.iter().position(|&b| b == sep)?;
    Some((s.get(..i)?, s.get(i + 1..)?))
}
