//! Reading the fields of a received line: numbers, `key=value` pairs, and
//! the one error type every parser returns.

/// Why a line was not accepted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParseError {
    /// No `*XXXX` trailer.
    NoChecksum,
    /// The checksum does not match the line.
    Checksum,
    /// Right checksum, but fields that do not parse.
    Format,
    /// Right checksum and syntax, but a field outside the range
    /// docs/protocol.md gives it (named here).
    Range(&'static str),
    /// Unknown line type.
    Type,
}

impl core::fmt::Display for ParseError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ParseError::NoChecksum => f.write_str("no checksum (truncated or garbled line)"),
            ParseError::Checksum => f.write_str("checksum mismatch (corrupted line)"),
            ParseError::Format => f.write_str("malformed fields"),
            ParseError::Range(field) => write!(f, "field outside its range: {field}"),
            ParseError::Type => f.write_str("unknown line type"),
        }
    }
}

pub(super) fn parse_u64(s: &[u8]) -> Option<u64> {
    // Leading zeros are allowed, however many (docs/protocol.md, "Values").
    if s.is_empty() || !s.iter().all(u8::is_ascii_digit) {
        return None;
    }
    let first = s.iter().position(|&c| c != b'0').unwrap_or(s.len());
    let significant = s.get(first..)?;
    if significant.len() > 20 {
        return None;
    }
    let mut v: u64 = 0;
    for &c in significant {
        v = v.checked_mul(10)?.checked_add((c - b'0') as u64)?;
    }
    Some(v)
}

pub(super) fn parse_u32(s: &[u8]) -> Option<u32> {
    parse_u64(s).and_then(|v| u32::try_from(v).ok())
}

pub(super) fn parse_i32(s: &[u8]) -> Option<i32> {
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
pub(super) struct Fields<'s, I: Iterator<Item = &'s [u8]>>(pub(super) I);

impl<'s, I: Iterator<Item = &'s [u8]>> Fields<'s, I> {
    pub(super) fn next(&mut self) -> Result<&'s [u8], ParseError> {
        self.0.next().ok_or(ParseError::Format)
    }

    pub(super) fn u32(&mut self) -> Result<u32, ParseError> {
        parse_u32(self.next()?).ok_or(ParseError::Format)
    }

    /// The value of the next field, which must be `key=value`.
    pub(super) fn key(&mut self, key: &str) -> Result<&'s [u8], ParseError> {
        kv(self.0.next(), key.as_bytes()).ok_or(ParseError::Format)
    }

    pub(super) fn key_u32(&mut self, key: &str) -> Result<u32, ParseError> {
        parse_u32(self.key(key)?).ok_or(ParseError::Format)
    }

    pub(super) fn key_u8(&mut self, key: &str) -> Result<u8, ParseError> {
        u8::try_from(self.key_u32(key)?).map_err(|_| ParseError::Format)
    }

    /// A `0`/`1` field; any other value is out of range (`range` names it).
    pub(super) fn key_flag(&mut self, key: &str, range: &'static str) -> Result<bool, ParseError> {
        match self.key(key)? {
            b"0" => Ok(false),
            b"1" => Ok(true),
            _ => Err(ParseError::Range(range)),
        }
    }

    pub(super) fn key_str(&mut self, key: &str) -> Result<&'s str, ParseError> {
        core::str::from_utf8(self.key(key)?).map_err(|_| ParseError::Format)
    }

    /// Succeeds when no field is left.
    pub(super) fn end(mut self) -> Result<(), ParseError> {
        match self.0.next() {
            Some(_) => Err(ParseError::Format),
            None => Ok(()),
        }
    }
}
