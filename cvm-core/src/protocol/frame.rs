//! Framing: where lines go ([`LineSink`]), how one is built in a fixed
//! buffer ([`LineBuf`]) and sealed with its CRC, and how a received line's
//! CRC is checked before any field is read.

use super::fields::ParseError;
use crate::verdict::Ahead;

/// Upper bound on the length of any line, newline included: the end
/// line with every total at its widest and the longest verdict.
pub const MAX_LINE: usize = 280;

/// Upper bound on the length of every line but the header and the end
/// line (`R`, `D`, `S`, `O`), newline included: what a queue reserves per
/// line of a row.
pub const MAX_ROW_LINE: usize = 256;

/// Whether a line may be dropped when the link cannot keep up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Priority {
    /// Header, row, defect and end lines: never dropped.
    Keep,
    /// Per-position score lines: dropped first, and counted.
    Droppable,
}

/// Where encoded lines go (a UART queue, stdout, a test vector).
pub trait LineSink {
    /// `line` includes its trailing `\n`.
    fn line(&mut self, line: &[u8], priority: Priority);

    /// What the next lines will report, before they are encoded (a row's
    /// closed objects, the scan's verdict). Lines only: nothing to do.
    fn ahead(&mut self, _news: Ahead) {}
}

// The encoder's tables are read for every character of every line. On
// bare metal they go to their own section, `.cvm_hot_rodata`, so that a
// board's memory map can put them in memory without wait states (the H743
// keeps them in DTCM, loaded from flash at start-up; from flash each read
// waits for the bus); elsewhere they are ordinary read-only data. The
// base64 alphabet of the score lines (`score`) goes there too.

/// CRC-16/CCITT-FALSE, catalogued as CRC-16/IBM-3740; its table is built
/// at compile time.
#[cfg_attr(target_os = "none", unsafe(link_section = ".cvm_hot_rodata"))]
static CRC16: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740);

/// CRC-16/CCITT-FALSE of `data` (check value: `crc16(b"123456789") == 0x29B1`).
pub fn crc16(data: &[u8]) -> u16 {
    CRC16.checksum(data)
}

const HEX: &[u8; 16] = b"0123456789ABCDEF";

/// A line under construction in a fixed buffer. Writes past `MAX_LINE`
/// are dropped (they cannot happen for the lines this protocol writes; the
/// length bounds are tested).
pub struct LineBuf {
    buf: [u8; MAX_LINE],
    len: usize,
}

impl LineBuf {
    pub fn new(kind: u8) -> Self {
        let mut l = LineBuf {
            buf: [0; MAX_LINE],
            len: 0,
        };
        l.byte(kind);
        l
    }

    pub fn byte(&mut self, b: u8) {
        // Keep room for "*XXXX\n".
        if self.len + 6 < MAX_LINE
            && let Some(slot) = self.buf.get_mut(self.len)
        {
            *slot = b;
            self.len += 1;
        }
    }

    pub fn bytes(&mut self, s: &[u8]) {
        for &b in s {
            self.byte(b);
        }
    }

    /// `,` then the field.
    pub fn field(&mut self, s: &[u8]) {
        self.byte(b',');
        self.bytes(s);
    }

    // Out of line: a line has up to 15 numbers, and inlining each copy of
    // the digit loop costs far more flash than the call.
    #[inline(never)]
    pub fn u64(&mut self, v: u64) {
        // Nearly every value fits 32 bits, where dividing by 10 is a
        // multiply; a 64-bit division is a library call per digit.
        let mut digits = [0u8; 20];
        let mut n = 0;
        match u32::try_from(v) {
            Ok(mut v) => loop {
                if let Some(d) = digits.get_mut(n) {
                    *d = b'0' + (v % 10) as u8;
                }
                n += 1;
                v /= 10;
                if v == 0 || n >= digits.len() {
                    break;
                }
            },
            Err(_) => {
                let mut v = v;
                loop {
                    if let Some(d) = digits.get_mut(n) {
                        *d = b'0' + (v % 10) as u8;
                    }
                    n += 1;
                    v /= 10;
                    if v == 0 || n >= digits.len() {
                        break;
                    }
                }
            }
        }
        for i in (0..n).rev() {
            self.byte(digits.get(i).copied().unwrap_or(b'0'));
        }
    }

    pub fn i64(&mut self, v: i64) {
        if v < 0 {
            self.byte(b'-');
        }
        self.u64(v.unsigned_abs());
    }

    /// `,key=value`.
    pub fn kv_u64(&mut self, key: &[u8], v: u64) {
        self.byte(b',');
        self.bytes(key);
        self.byte(b'=');
        self.u64(v);
    }

    /// Appends `*XXXX\n` and returns the whole line.
    #[inline(never)]
    pub fn finish(&mut self) -> &[u8] {
        let crc = crc16(self.buf.get(..self.len).unwrap_or(&[]));
        let tail = [
            b'*',
            HEX[(crc >> 12) as usize & 15],
            HEX[(crc >> 8) as usize & 15],
            HEX[(crc >> 4) as usize & 15],
            HEX[crc as usize & 15],
            b'\n',
        ];
        for b in tail {
            if let Some(slot) = self.buf.get_mut(self.len) {
                *slot = b;
                self.len += 1;
            }
        }
        self.buf.get(..self.len).unwrap_or(&[])
    }
}

/// The body of a line (before its `*`), once its CRC has been checked.
pub(super) fn checked_body(line: &[u8]) -> Result<&[u8], ParseError> {
    let line = line.strip_suffix(b"\n").unwrap_or(line);
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    let star = line
        .iter()
        .rposition(|&b| b == b'*')
        .ok_or(ParseError::NoChecksum)?;
    let (body, tail) = line.split_at(star);
    let hex = tail.get(1..).ok_or(ParseError::NoChecksum)?;
    if hex.len() != 4 {
        return Err(ParseError::NoChecksum);
    }
    let mut want: u16 = 0;
    for &c in hex {
        let d = match c {
            b'0'..=b'9' => c - b'0',
            b'A'..=b'F' => c - b'A' + 10,
            _ => return Err(ParseError::NoChecksum),
        };
        want = (want << 4) | d as u16;
    }
    if crc16(body) != want {
        return Err(ParseError::Checksum);
    }
    Ok(body)
}
