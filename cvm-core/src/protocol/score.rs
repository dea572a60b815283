//! The positions of a score (`S`) line: each one 54 bits as 9 characters
//! of URL-safe base64.

use crate::stream::PositionScore;

/// Positions per score (`S`) line.
pub const SCORES_PER_LINE: usize = 24;
/// Characters of one position in a score line.
pub const SCORE_CHARS: usize = 9;
/// Flag bits a score line carries.
const SCORE_FLAGS: u64 = 0x3F;

// Read for every character of a score line: in the fast section beside
// the CRC table, for the reason given in `frame`.
/// URL-safe base64 alphabet: no `,`, `*` or newline, so scores need no escaping.
#[cfg_attr(target_os = "none", unsafe(link_section = ".cvm_hot_rodata"))]
static B64: [u8; 64] = *b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";

/// One position in a score line: 54 bits as 9 base64 digits, most
/// significant first; bits 0-31 the magnitude, bits 32-47 the power
/// magnitude, bits 48-53 the flags.
pub fn encode_score(s: &PositionScore) -> [u8; SCORE_CHARS] {
    let v = ((s.flags as u64 & SCORE_FLAGS) << 48) | ((s.pmag as u64) << 32) | s.mag as u64;
    let mut out = [b'A'; SCORE_CHARS];
    for (i, o) in out.iter_mut().enumerate() {
        let shift = 6 * (SCORE_CHARS - 1 - i);
        *o = B64[((v >> shift) & 63) as usize];
    }
    out
}

/// One position of a score line, decoded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ScoreValue {
    pub mag: u32,
    pub pmag: u16,
    pub flags: u8,
}

/// Inverse of [`encode_score`]; `None` for a character outside the
/// alphabet or flag bits beyond bit 5.
pub fn decode_score(chars: &[u8]) -> Option<ScoreValue> {
    if chars.len() != SCORE_CHARS {
        return None;
    }
    let mut v: u64 = 0;
    for &c in chars {
        let d = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'-' => 62,
            b'_' => 63,
            _ => return None,
        };
        v = (v << 6) | d as u64;
    }
    if v >> 48 > SCORE_FLAGS {
        return None;
    }
    Some(ScoreValue {
        mag: v as u32,
        pmag: (v >> 32) as u16,
        flags: (v >> 48) as u8,
    })
}
