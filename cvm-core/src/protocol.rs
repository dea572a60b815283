//! The result line protocol (docs/protocol.md): ASCII, one record per line,
//! every line `<type>,<fields>*XXXX\n` where `XXXX` is the CRC-16/CCITT-FALSE
//! (polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR) of
//! every byte before the `*`, in upper-case hex.
//!
//! The encoder writes into fixed buffers (no allocation); the parser borrows
//! from the line it is given, so both run on the target and on the host.

use crate::config::{Config, Kernels, Weights};
use crate::scorer::Scorer;
use crate::stream::{PositionScore, RowSummary, RowView, Totals};

/// Protocol version written in the header.
pub const VERSION: u32 = 2;
/// Upper bound on the length of any line, newline included.
pub const MAX_LINE: usize = 256;
/// Positions per score (`S`) line.
pub const SCORES_PER_LINE: usize = 32;
/// Characters of one position in a score line.
pub const SCORE_CHARS: usize = 6;
/// Longest firmware version string carried in the header.
pub const MAX_FW: usize = 24;

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
}

/// CRC-16/CCITT-FALSE lookup table, built at compile time.
const CRC_TABLE: [u16; 256] = {
    let mut t = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = (i as u16) << 8;
        let mut k = 0;
        while k < 8 {
            c = if c & 0x8000 != 0 {
                (c << 1) ^ 0x1021
            } else {
                c << 1
            };
            k += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
};

/// CRC-16/CCITT-FALSE of `data` (check value: `crc16(b"123456789") == 0x29B1`).
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in data {
        let idx = ((crc >> 8) as u8 ^ b) as usize;
        crc = (crc << 8) ^ CRC_TABLE.get(idx).copied().unwrap_or(0);
    }
    crc
}

const HEX: &[u8; 16] = b"0123456789ABCDEF";
/// URL-safe base64 alphabet: no `,`, `*` or newline, so scores need no escaping.
const B64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";

/// A line under construction in a fixed buffer. Writes past `MAX_LINE`
/// are dropped and remembered (they cannot happen for the lines this module
/// writes; the length bounds are tested).
pub struct LineBuf {
    buf: [u8; MAX_LINE],
    len: usize,
    overflow: bool,
}

impl LineBuf {
    pub fn new(kind: u8) -> Self {
        let mut l = LineBuf {
            buf: [0; MAX_LINE],
            len: 0,
            overflow: false,
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
            return;
        }
        self.overflow = true;
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

    pub fn u64(&mut self, v: u64) {
        let mut digits = [0u8; 20];
        let mut n = 0;
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

    pub fn overflowed(&self) -> bool {
        self.overflow
    }

    /// Appends `*XXXX\n` and returns the whole line.
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

/// One position in a score line: 36 bits as 6 base64 digits, most
/// significant first; bits 0-31 the magnitude, bits 32-35 the flags.
pub fn encode_score(s: &PositionScore) -> [u8; SCORE_CHARS] {
    let v = ((s.flags as u64 & 0xF) << 32) | s.mag as u64;
    let mut out = [b'A'; SCORE_CHARS];
    for (i, o) in out.iter_mut().enumerate() {
        let shift = 6 * (SCORE_CHARS - 1 - i);
        *o = B64[((v >> shift) & 63) as usize];
    }
    out
}

/// Inverse of [`encode_score`]: `(magnitude, flags)`.
pub fn decode_score(chars: &[u8]) -> Option<(u32, u8)> {
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
    Some((v as u32, (v >> 32) as u8))
}

/// What the header says about the scan and the scoring.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeaderInfo<'s> {
    pub version: u32,
    pub firmware: &'s str,
    pub j1: u8,
    pub j2: u8,
    pub cols: u32,
    /// `b'P'` paper kernels or `b'S'` square kernels.
    pub kernels: u8,
    /// `bmax` (paper, 0 = all) or `kmax` (square).
    pub kernel_size: u8,
    /// `"uniform"`, `"unit"` or `"separable"`.
    pub weights: &'s str,
    pub normalise: bool,
    pub full_scale: u16,
    pub threshold: u32,
    /// Score format: a score `s` is `s / 2^q` distance units.
    pub q: i32,
    pub scores: bool,
}

impl<'s> HeaderInfo<'s> {
    pub fn new(
        scorer: &Scorer,
        cols: u32,
        threshold: u32,
        scores: bool,
        firmware: &'s str,
    ) -> Self {
        let cfg: &Config = scorer.config();
        let (kernels, kernel_size) = match cfg.kernels {
            Kernels::Paper { bmax } => (b'P', bmax),
            Kernels::Square { kmax } => (b'S', kmax),
        };
        let weights = match (cfg.kernels, cfg.weights) {
            (Kernels::Square { .. }, _) | (_, Weights::Unit) => "unit",
            (_, Weights::Uniform) => "uniform",
            (_, Weights::Separable { .. }) => "separable",
        };
        HeaderInfo {
            version: VERSION,
            firmware,
            j1: cfg.geometry.j1,
            j2: cfg.geometry.j2,
            cols,
            kernels,
            kernel_size,
            weights,
            normalise: cfg.normalise,
            full_scale: cfg.full_scale,
            threshold,
            q: scorer.score_frac_bits(),
            scores,
        }
    }
}

/// `H,v=2,fw=..,j=15x15,cols=300,k=P,b=0,w=uniform,norm=1,fs=65535,thr=..,q=23,scores=0`
pub fn encode_header(h: &HeaderInfo, sink: &mut impl LineSink) {
    let mut l = LineBuf::new(b'H');
    l.kv_u64(b"v", h.version as u64);
    l.field(b"fw=");
    let fw = h.firmware.as_bytes();
    // Only characters that cannot break the line's syntax.
    for &b in fw.iter().take(MAX_FW) {
        l.byte(if b.is_ascii_graphic() && b != b',' && b != b'*' {
            b
        } else {
            b'?'
        });
    }
    l.field(b"j=");
    l.u64(h.j1 as u64);
    l.byte(b'x');
    l.u64(h.j2 as u64);
    l.kv_u64(b"cols", h.cols as u64);
    l.field(b"k=");
    l.byte(h.kernels);
    l.kv_u64(b"b", h.kernel_size as u64);
    l.field(b"w=");
    l.bytes(h.weights.as_bytes());
    l.kv_u64(b"norm", h.normalise as u64);
    l.kv_u64(b"fs", h.full_scale as u64);
    l.kv_u64(b"thr", h.threshold as u64);
    l.field(b"q=");
    l.i64(h.q as i64);
    l.kv_u64(b"scores", h.scores as u64);
    sink.line(l.finish(), Priority::Keep);
}

/// Encodes a finished row: the `R` summary, up to `max_defects` `D` lines,
/// and with `scores` its `S` lines.
pub fn encode_row(view: &RowView, max_defects: u16, scores: bool, sink: &mut impl LineSink) {
    let s = &view.summary;
    let listed = s.defects.min(max_defects as u32);
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
    for v in [s.defects, listed, s.no_data, s.dark, s.saturated] {
        l.byte(b',');
        l.u64(v as u64);
    }
    sink.line(l.finish(), Priority::Keep);

    let mut left = listed;
    for (c, p) in view.scores.iter().enumerate() {
        if left == 0 {
            break;
        }
        if p.flags & crate::flags::NO_DATA == 0 && p.mag >= view.threshold {
            let mut l = LineBuf::new(b'D');
            for v in [s.row, c as u32, p.mag, p.flags as u32] {
                l.byte(b',');
                l.u64(v as u64);
            }
            sink.line(l.finish(), Priority::Keep);
            left -= 1;
        }
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

/// `E,rows=..,frames=..,missing=..,dark=..,sat=..,defects=..,rejected=..,extra=..,bad=..,clipped=..,misplaced=..,dropped=..`
pub fn encode_end(t: &Totals, dropped: u32, sink: &mut impl LineSink) {
    let mut l = LineBuf::new(b'E');
    for (k, v) in end_fields(t, dropped) {
        l.kv_u64(k, v as u64);
    }
    sink.line(l.finish(), Priority::Keep);
}

fn end_fields(t: &Totals, dropped: u32) -> [(&'static [u8], u32); 12] {
    [
        (b"rows", t.rows),
        (b"frames", t.frames),
        (b"missing", t.missing),
        (b"dark", t.dark),
        (b"sat", t.saturated),
        (b"defects", t.defects),
        (b"rejected", t.rejected),
        (b"extra", t.extra),
        (b"bad", t.bad),
        (b"clipped", t.clipped),
        (b"misplaced", t.misplaced),
        (b"dropped", dropped),
    ]
}

/// Totals as the end line carries them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EndInfo {
    pub totals: Totals,
    pub dropped: u32,
}

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
        flags: u8,
    },
    /// Scores of `col0..col0 + chars.len() / 6`; decode with [`decode_score`].
    Scores {
        row: u32,
        col0: u32,
        chars: &'s [u8],
    },
    End(EndInfo),
}

/// Why a line was not accepted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParseError {
    /// No `*XXXX` trailer.
    NoChecksum,
    /// The checksum does not match the line.
    Checksum,
    /// Right checksum, but fields that do not parse.
    Format,
    /// Unknown line type.
    Type,
}

fn parse_u64(s: &[u8]) -> Option<u64> {
    if s.is_empty() || s.len() > 20 {
        return None;
    }
    let mut v: u64 = 0;
    for &c in s {
        if !c.is_ascii_digit() {
            return None;
        }
        v = v.checked_mul(10)?.checked_add((c - b'0') as u64)?;
    }
    Some(v)
}

fn parse_u32(s: &[u8]) -> Option<u32> {
    parse_u64(s).and_then(|v| u32::try_from(v).ok())
}

fn parse_i32(s: &[u8]) -> Option<i32> {
    match s.split_first() {
        Some((b'-', rest)) => parse_u64(rest).and_then(|v| i32::try_from(-(v as i64)).ok()),
        _ => parse_u32(s).and_then(|v| i32::try_from(v).ok()),
    }
}

/// Splits `key=value`, checking the key.
fn kv<'s>(field: Option<&'s [u8]>, key: &[u8]) -> Option<&'s [u8]> {
    let f = field?;
    let rest = f.strip_prefix(key)?;
    rest.strip_prefix(b"=")
}

/// Parses one line (with or without its trailing `\r\n`/`\n`).
pub fn parse(line: &[u8]) -> Result<Line<'_>, ParseError> {
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
    let mut it = body.split(|&b| b == b',');
    let kind = it.next().ok_or(ParseError::Format)?;
    let f = ParseError::Format;
    match kind {
        b"H" => {
            let version = parse_u32(kv(it.next(), b"v").ok_or(f)?).ok_or(f)?;
            let fw = core::str::from_utf8(kv(it.next(), b"fw").ok_or(f)?).map_err(|_| f)?;
            let j = kv(it.next(), b"j").ok_or(f)?;
            let x = j.iter().position(|&b| b == b'x').ok_or(f)?;
            let (a, b) = j.split_at(x);
            let j1 = parse_u32(a).and_then(|v| u8::try_from(v).ok()).ok_or(f)?;
            let j2 = parse_u32(b.get(1..).ok_or(f)?)
                .and_then(|v| u8::try_from(v).ok())
                .ok_or(f)?;
            let cols = parse_u32(kv(it.next(), b"cols").ok_or(f)?).ok_or(f)?;
            let kernels = match kv(it.next(), b"k").ok_or(f)? {
                b"P" => b'P',
                b"S" => b'S',
                _ => return Err(f),
            };
            let kernel_size = parse_u32(kv(it.next(), b"b").ok_or(f)?)
                .and_then(|v| u8::try_from(v).ok())
                .ok_or(f)?;
            let weights = core::str::from_utf8(kv(it.next(), b"w").ok_or(f)?).map_err(|_| f)?;
            let normalise = parse_u32(kv(it.next(), b"norm").ok_or(f)?).ok_or(f)? != 0;
            let full_scale = parse_u32(kv(it.next(), b"fs").ok_or(f)?)
                .and_then(|v| u16::try_from(v).ok())
                .ok_or(f)?;
            let threshold = parse_u32(kv(it.next(), b"thr").ok_or(f)?).ok_or(f)?;
            let q = parse_i32(kv(it.next(), b"q").ok_or(f)?).ok_or(f)?;
            let scores = parse_u32(kv(it.next(), b"scores").ok_or(f)?).ok_or(f)? != 0;
            if it.next().is_some() {
                return Err(f);
            }
            Ok(Line::Header(HeaderInfo {
                version,
                firmware: fw,
                j1,
                j2,
                cols,
                kernels,
                kernel_size,
                weights,
                normalise,
                full_scale,
                threshold,
                q,
                scores,
            }))
        }
        b"R" => {
            let mut v = [0u32; 8];
            let mut argmax = None;
            for (i, slot) in v.iter_mut().enumerate() {
                let field = it.next().ok_or(f)?;
                if i == 2 && field == b"-" {
                    continue;
                }
                *slot = parse_u32(field).ok_or(f)?;
                if i == 2 {
                    argmax = Some(*slot);
                }
            }
            if it.next().is_some() {
                return Err(f);
            }
            let [row, max, _, defects, listed, no_data, dark, saturated] = v;
            Ok(Line::Row {
                summary: RowSummary {
                    row,
                    max,
                    argmax,
                    defects,
                    no_data,
                    dark,
                    saturated,
                },
                listed,
            })
        }
        b"D" => {
            let mut v = [0u32; 4];
            for slot in v.iter_mut() {
                *slot = parse_u32(it.next().ok_or(f)?).ok_or(f)?;
            }
            if it.next().is_some() || v[3] > 0xFF {
                return Err(f);
            }
            Ok(Line::Defect {
                row: v[0],
                col: v[1],
                mag: v[2],
                flags: v[3] as u8,
            })
        }
        b"S" => {
            let row = parse_u32(it.next().ok_or(f)?).ok_or(f)?;
            let col0 = parse_u32(it.next().ok_or(f)?).ok_or(f)?;
            let chars = it.next().ok_or(f)?;
            if it.next().is_some() || chars.is_empty() || chars.len() % SCORE_CHARS != 0 {
                return Err(f);
            }
            if chars.chunks(SCORE_CHARS).any(|c| decode_score(c).is_none()) {
                return Err(f);
            }
            Ok(Line::Scores { row, col0, chars })
        }
        b"E" => {
            let mut vals = [0u32; 12];
            for (slot, (key, _)) in vals.iter_mut().zip(end_fields(&Totals::default(), 0)) {
                *slot = parse_u32(kv(it.next(), key).ok_or(f)?).ok_or(f)?;
            }
            if it.next().is_some() {
                return Err(f);
            }
            let [
                rows,
                frames,
                missing,
                dark,
                saturated,
                defects,
                rejected,
                extra,
                bad,
                clipped,
                misplaced,
                dropped,
            ] = vals;
            Ok(Line::End(EndInfo {
                totals: Totals {
                    rows,
                    frames,
                    missing,
                    dark,
                    saturated,
                    defects,
                    rejected,
                    extra,
                    bad,
                    clipped,
                    misplaced,
                },
                dropped,
            }))
        }
        _ => Err(ParseError::Type),
    }
}
