//! The positions of a score (`S`) line: each one 72 bits as 12 characters
//! of URL-safe base64.

use crate::stream::PositionScore;

/// Positions per score (`S`) line.
pub const SCORES_PER_LINE: usize = 18;
/// Characters of one position in a score line.
pub const SCORE_CHARS: usize = 12;
/// Flag bits a score line carries.
const SCORE_FLAGS: u32 = 0x7F;
/// Bits of the spread magnitude (at most `SPREAD_MAX` = 92 680 < 2^17).
const SPREAD_BITS: u32 = 17;

// Read for every character of a score line: in the fast section beside
// the CRC table, for the reason given in `frame`.
/// URL-safe base64 alphabet: no `,`, `*` or newline, so scores need no escaping.
#[cfg_attr(target_os = "none", unsafe(link_section = ".cvm_hot_rodata"))]
static B64: [u8; 64] = *b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";

/// One position in a score line: 72 bits as 12 base64 digits, most
/// significant first; bits 0-31 the magnitude, bits 32-47 the power
/// magnitude, bits 48-64 the spread magnitude, bits 65-71 the flags. In
/// two words, so that the target needs no 128-bit arithmetic: the top 24
/// bits (flags and spread, 4 digits) and the low 48 (8 digits).
pub fn encode_score(s: &PositionScore) -> [u8; SCORE_CHARS] {
    let hi = ((s.flags as u32 & SCORE_FLAGS) << SPREAD_BITS) | (s.smag & ((1 << SPREAD_BITS) - 1));
    let lo = ((s.pmag as u64) << 32) | s.mag as u64;
    let mut out = [b'A'; SCORE_CHARS];
    let (top, low) = out.split_at_mut(4);
    for (i, o) in top.iter_mut().enumerate() {
        *o = B64[((hi >> (6 * (3 - i))) & 63) as usize];
    }
    for (i, o) in low.iter_mut().enumerate() {
        *o = B64[((lo >> (6 * (7 - i))) & 63) as usize];
    }
    out
}

/// One position of a score line, decoded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ScoreValue {
    pub mag: u32,
    pub pmag: u16,
    pub smag: u32,
    pub flags: u8,
}

/// Inverse of [`encode_score`]; `None` for a character outside the
/// alphabet. (Every 72-bit value decodes: the flags take the top 7 bits.)
pub fn decode_score(chars: &[u8]) -> Option<ScoreValue> {
    if chars.len() != SCORE_CHARS {
        return None;
    }
    let mut hi: u32 = 0;
    let mut lo: u64 = 0;
    for (i, &c) in chars.iter().enumerate() {
        let d = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'-' => 62,
            b'_' => 63,
            _ => return None,
        };
        if i < 4 {
            hi = (hi << 6) | d as u32;
        } else {
            lo = (lo << 6) | d as u64;
        }
    }
    Some(ScoreValue {
        mag: lo as u32,
        pmag: (lo >> 32) as u16,
        smag: hi & ((1 << SPREAD_BITS) - 1),
        flags: (hi >> SPREAD_BITS) as u8,
    })
}
