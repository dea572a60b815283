//! The result line protocol (docs/protocol.md): ASCII, one record per line,
//! every line `<type>,<fields>*XXXX\n` where `XXXX` is the CRC-16/CCITT-FALSE
//! (polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR) of
//! every byte before the `*`, in upper-case hex.
//!
//! The encoder writes into fixed buffers (no allocation); the parser borrows
//! from the line it is given, so both run on the target and on the host.

use crate::config::{Config, Kernels, Weights};
use crate::objects::Object;
use crate::pipeline::Settings;
use crate::scorer::Scorer;
use crate::stream::{PositionScore, RowSummary, RowView, Totals};

/// Protocol version written in the header.
pub const VERSION: u32 = 4;
/// Upper bound on the length of any line, newline included.
pub const MAX_LINE: usize = 256;
/// Positions per score (`S`) line.
pub const SCORES_PER_LINE: usize = 24;
/// Characters of one position in a score line.
pub const SCORE_CHARS: usize = 9;
/// Flag bits a score line carries.
const SCORE_FLAGS: u64 = 0x3F;
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

// The encoder's two tables are read for every character of every line. On
// bare metal they go to their own section, `.cvm_hot_rodata`, so that a
// board's memory map can put them in memory without wait states (the H743
// keeps them in DTCM, loaded from flash at start-up; from flash each read
// waits for the bus); elsewhere they are ordinary read-only data.

/// CRC-16/CCITT-FALSE, catalogued as CRC-16/IBM-3740; its table is built
/// at compile time.
#[cfg_attr(target_os = "none", unsafe(link_section = ".cvm_hot_rodata"))]
static CRC16: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740);

/// CRC-16/CCITT-FALSE of `data` (check value: `crc16(b"123456789") == 0x29B1`).
pub fn crc16(data: &[u8]) -> u16 {
    CRC16.checksum(data)
}

const HEX: &[u8; 16] = b"0123456789ABCDEF";
/// URL-safe base64 alphabet: no `,`, `*` or newline, so scores need no escaping.
#[cfg_attr(target_os = "none", unsafe(link_section = ".cvm_hot_rodata"))]
static B64: [u8; 64] = *b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";

/// A line under construction in a fixed buffer. Writes past `MAX_LINE`
/// are dropped (they cannot happen for the lines this module writes; the
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

/// Why the board last started, as the header's `rst` carries it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ResetCause {
    /// Power-on or brown-out (`por`); also `dmap stream` and the emulated board.
    PowerOn,
    /// A watchdog (`wdg`).
    Watchdog,
    /// A software reset: after a panic, or a debugger's request (`sw`).
    Software,
    /// The reset pin (`pin`).
    Pin,
    /// Anything else (`other`).
    Other,
}

impl ResetCause {
    /// Every cause, in the order of the protocol document.
    pub const ALL: [ResetCause; 5] = [
        ResetCause::PowerOn,
        ResetCause::Watchdog,
        ResetCause::Software,
        ResetCause::Pin,
        ResetCause::Other,
    ];

    /// The value of `rst=`.
    pub const fn as_str(self) -> &'static str {
        match self {
            ResetCause::PowerOn => "por",
            ResetCause::Watchdog => "wdg",
            ResetCause::Software => "sw",
            ResetCause::Pin => "pin",
            ResetCause::Other => "other",
        }
    }

    fn parse(s: &[u8]) -> Option<Self> {
        ResetCause::ALL
            .into_iter()
            .find(|c| c.as_str().as_bytes() == s)
    }
}

/// What the header says about the scan, the scoring and the board's start.
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
    /// Power channel threshold, `Q15` (`pthr`; [`crate::power::POWER_OFF`]: off).
    pub power_threshold: u32,
    /// Score format: a score `s` is `s / 2^q` distance units.
    pub q: i32,
    pub scores: bool,
    /// Most `D` lines per row (`dcap`).
    pub max_defect_lines: u16,
    /// Why the board last started (`rst`).
    pub reset_cause: ResetCause,
    /// Starts since power-on, this one included (`boots`; 1 after power-on).
    pub boots: u32,
}

impl HeaderInfo<'static> {
    /// The header of a pipeline with these settings.
    pub fn new(scorer: &Scorer, settings: &Settings) -> Self {
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
            firmware: settings.firmware_version,
            j1: cfg.geometry.j1,
            j2: cfg.geometry.j2,
            cols: settings.cols,
            kernels,
            kernel_size,
            weights,
            normalise: cfg.normalise,
            full_scale: cfg.full_scale,
            threshold: settings.threshold,
            power_threshold: settings.power_threshold,
            q: scorer.score_frac_bits(),
            scores: settings.scores,
            max_defect_lines: settings.max_defect_lines_per_row,
            reset_cause: settings.reset_cause,
            boots: settings.boots,
        }
    }
}

/// `H,v=4,fw=..,j=15x15,cols=300,k=P,b=0,w=uniform,norm=1,fs=65535,thr=..,pthr=..,q=23,scores=0,dcap=0,rst=por,boots=1`
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
    l.kv_u64(b"pthr", h.power_threshold as u64);
    l.field(b"q=");
    l.i64(h.q as i64);
    l.kv_u64(b"scores", h.scores as u64);
    l.kv_u64(b"dcap", h.max_defect_lines as u64);
    l.field(b"rst=");
    l.bytes(h.reset_cause.as_str().as_bytes());
    l.kv_u64(b"boots", h.boots as u64);
    sink.line(l.finish(), Priority::Keep);
}

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
        let defect = p.flags & crate::flags::NO_DATA == 0 && p.is_defect();
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

/// `O,id,row0,row1,col0,col1,area,peak,peak_row,peak_col,peak_mag,peak_power,centroid_row,centroid_col,channels`:
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
        o.centroid_row_q8,
        o.centroid_col_q8,
        o.channels as u64,
    ] {
        l.byte(b',');
        l.u64(v);
    }
    sink.line(l.finish(), Priority::Keep);
}

/// `E,rows=..,frames=..,missing=..,dark=..,sat=..,defects=..,rejected=..,extra=..,bad=..,clipped=..,misplaced=..,dropped=..`
pub fn encode_end(t: &Totals, dropped: u32, sink: &mut impl LineSink) {
    let mut l = LineBuf::new(b'E');
    let mut t = *t;
    for (key, field) in END_FIELDS {
        l.kv_u64(key.as_bytes(), *field(&mut t) as u64);
    }
    l.kv_u64(DROPPED.as_bytes(), dropped as u64);
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
        pmag: u16,
        strength: u32,
        flags: u8,
    },
    Object(Object),
    /// Scores of `col0..col0 + chars.len() / 9`; decode with [`decode_score`].
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

impl core::fmt::Display for ParseError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            ParseError::NoChecksum => "no checksum (truncated or garbled line)",
            ParseError::Checksum => "checksum mismatch (corrupted line)",
            ParseError::Format => "malformed fields",
            ParseError::Type => "unknown line type",
        })
    }
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

/// The fields of a line, read in order; every read fails as [`ParseError::Format`].
struct Fields<'s, I: Iterator<Item = &'s [u8]>>(I);

impl<'s, I: Iterator<Item = &'s [u8]>> Fields<'s, I> {
    fn next(&mut self) -> Result<&'s [u8], ParseError> {
        self.0.next().ok_or(ParseError::Format)
    }

    fn u32(&mut self) -> Result<u32, ParseError> {
        parse_u32(self.next()?).ok_or(ParseError::Format)
    }

    /// The value of the next field, which must be `key=value`.
    fn key(&mut self, key: &str) -> Result<&'s [u8], ParseError> {
        kv(self.0.next(), key.as_bytes()).ok_or(ParseError::Format)
    }

    fn key_u32(&mut self, key: &str) -> Result<u32, ParseError> {
        parse_u32(self.key(key)?).ok_or(ParseError::Format)
    }

    fn key_u8(&mut self, key: &str) -> Result<u8, ParseError> {
        u8::try_from(self.key_u32(key)?).map_err(|_| ParseError::Format)
    }

    fn key_str(&mut self, key: &str) -> Result<&'s str, ParseError> {
        core::str::from_utf8(self.key(key)?).map_err(|_| ParseError::Format)
    }

    /// Succeeds when no field is left.
    fn end(mut self) -> Result<(), ParseError> {
        match self.0.next() {
            Some(_) => Err(ParseError::Format),
            None => Ok(()),
        }
    }
}

/// The body of a line (before its `*`), once its CRC has been checked.
fn checked_body(line: &[u8]) -> Result<&[u8], ParseError> {
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

/// Parses one line (with or without its trailing `\r\n`/`\n`).
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
    Ok(line)
}

fn parse_header<'s>(
    f: &mut Fields<'s, impl Iterator<Item = &'s [u8]>>,
) -> Result<HeaderInfo<'s>, ParseError> {
    let e = ParseError::Format;
    let version = f.key_u32("v")?;
    let firmware = f.key_str("fw")?;
    let (j1, j2) = {
        let j = f.key("j")?;
        let x = j.iter().position(|&b| b == b'x').ok_or(e)?;
        let (a, b) = j.split_at(x);
        let axis = |s: &[u8]| parse_u32(s).and_then(|v| u8::try_from(v).ok()).ok_or(e);
        (axis(a)?, axis(b.get(1..).ok_or(e)?)?)
    };
    let cols = f.key_u32("cols")?;
    let kernels = match f.key("k")? {
        b"P" => b'P',
        b"S" => b'S',
        _ => return Err(e),
    };
    let kernel_size = f.key_u8("b")?;
    let weights = f.key_str("w")?;
    let normalise = f.key_u32("norm")? != 0;
    let full_scale = u16::try_from(f.key_u32("fs")?).map_err(|_| e)?;
    let threshold = f.key_u32("thr")?;
    let power_threshold = f.key_u32("pthr")?;
    let q = parse_i32(f.key("q")?).ok_or(e)?;
    let scores = f.key_u32("scores")? != 0;
    let max_defect_lines = u16::try_from(f.key_u32("dcap")?).map_err(|_| e)?;
    let reset_cause = ResetCause::parse(f.key("rst")?).ok_or(e)?;
    let boots = f.key_u32("boots")?;
    Ok(HeaderInfo {
        version,
        firmware,
        j1,
        j2,
        cols,
        kernels,
        kernel_size,
        weights,
        normalise,
        full_scale,
        threshold,
        power_threshold,
        q,
        scores,
        max_defect_lines,
        reset_cause,
        boots,
    })
}

fn parse_row<'s>(
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

fn parse_defect<'s>(
    f: &mut Fields<'s, impl Iterator<Item = &'s [u8]>>,
) -> Result<Line<'s>, ParseError> {
    let [row, col, mag] = [f.u32()?, f.u32()?, f.u32()?];
    let pmag = u16::try_from(f.u32()?).map_err(|_| ParseError::Format)?;
    let strength = f.u32()?;
    let flags = u8::try_from(f.u32()?).map_err(|_| ParseError::Format)?;
    Ok(Line::Defect {
        row,
        col,
        mag,
        pmag,
        strength,
        flags,
    })
}

fn parse_object<'s>(
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
    let centroid_row_q8 = parse_u64(f.next()?).ok_or(e)?;
    let centroid_col_q8 = parse_u64(f.next()?).ok_or(e)?;
    let channels = u8::try_from(f.u32()?).map_err(|_| e)?;
    if row0 > row1 || col0 > col1 || channels & !crate::flags::DEFECT != 0 {
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
        channels,
        centroid_row_q8,
        centroid_col_q8,
    })
}

fn parse_scores<'s>(
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

fn parse_end<'s>(
    f: &mut Fields<'s, impl Iterator<Item = &'s [u8]>>,
) -> Result<EndInfo, ParseError> {
    let mut totals = Totals::default();
    for (key, field) in END_FIELDS {
        *field(&mut totals) = f.key_u32(key)?;
    }
    let dropped = f.key_u32(DROPPED)?;
    Ok(EndInfo { totals, dropped })
}
