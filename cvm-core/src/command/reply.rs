//! Reply lines, board to host: `A,<id>,ok,...*XXXX\n` or
//! `A,<id>,err,<reason>[,<min>,<max>]*XXXX\n`, the id `-` when the
//! request's own could not be trusted.

use super::refusal::Refusal;
use super::status::Status;
use super::wire::{FrameError, REPLY, checked_body, kv, parse_u32, split_once};
use crate::calibration::Calibration;
use crate::calibration::rule::DEFAULT_RATE_PPM;
use crate::protocol::{LineBuf, LineSink, ParseError, Priority};
use crate::settings::Key;
use crate::settings::Source;

/// A reply, decoded. `F` is the status's firmware text, borrowed from the
/// line unless [`Reply::detach`] made it something else.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reply<'s, F = &'s str> {
    /// `ok,status,...` (see [`Status`]), followed by one [`Reply::Value`]
    /// per setting.
    Status(Status<F>),
    /// `ok,<key>=<value>:<source>`: the answer to `get`, and to `set`
    /// (the value now in effect for the next scan).
    Value {
        key: Key,
        value: u32,
        source: Source,
    },
    /// `ok,<key>=<value>:<source>` with a key this decoder does not know
    /// (a later board's setting): well formed, so a client passes over it
    /// (docs/commands.md, "Settings (keys)"). The key is letters, digits
    /// and `_`; the value is printable and has no `,`, `*` or `:`.
    OtherKey {
        key: &'s [u8],
        value: &'s [u8],
        source: Source,
    },
    /// `ok,calibrate,<n>`: the next n scans calibrate.
    Calibrating(u16),
    /// `ok,calibrated,scans=..,positions=..,thr=..,pthr=..,sthr=..,med=..,mad=..,pmed=..,pmad=..,smed=..,smad=..`,
    /// once the last of them has ended; carries the `calibrate` request's id.
    Calibrated(Calibration),
    /// `ok,save`: written to flash.
    Saved,
    /// `ok,defaults`: the compiled values are in effect from the next scan.
    Defaults,
    /// `ok,reset`: the board restarts after this line.
    Resetting,
    /// `err,<reason>`: nothing changed.
    Refused(Refusal),
}

impl<'s> Reply<'s> {
    /// The reply without its borrow of the line, for a client that keeps
    /// it longer: the status's firmware text goes through `keep` (to an
    /// owned copy, say). `None` for [`Reply::OtherKey`], which is the
    /// line's bytes and nothing else.
    pub fn detach<F>(self, keep: impl FnOnce(&'s str) -> F) -> Option<Reply<'static, F>> {
        Some(match self {
            Reply::Status(s) => Reply::Status(s.with_firmware(keep)),
            Reply::Value { key, value, source } => Reply::Value { key, value, source },
            Reply::OtherKey { .. } => return None,
            Reply::Calibrating(n) => Reply::Calibrating(n),
            Reply::Calibrated(c) => Reply::Calibrated(c),
            Reply::Saved => Reply::Saved,
            Reply::Defaults => Reply::Defaults,
            Reply::Resetting => Reply::Resetting,
            Reply::Refused(why) => Reply::Refused(why),
        })
    }
}

/// Writes the reply line; `id` is the request's, or `None` when it could
/// not be trusted (written `-`).
pub fn encode_reply(id: Option<u32>, r: &Reply, sink: &mut impl LineSink) {
    let mut l = LineBuf::new(REPLY);
    l.byte(b',');
    match id {
        Some(id) => l.u64(id as u64),
        None => l.byte(b'-'),
    }
    l.field(if matches!(r, Reply::Refused(_)) {
        b"err"
    } else {
        b"ok"
    });
    match *r {
        Reply::Status(ref s) => {
            l.field(b"status");
            s.encode(&mut l);
        }
        Reply::Value { key, value, source } => {
            l.field(key.name().as_bytes());
            l.byte(b'=');
            key.encode(value, &mut l);
            l.byte(b':');
            l.byte(source.as_char());
        }
        Reply::OtherKey { key, value, source } => {
            l.field(key);
            l.byte(b'=');
            l.bytes(value);
            l.byte(b':');
            l.byte(source.as_char());
        }
        Reply::Calibrating(n) => {
            l.field(b"calibrate");
            l.byte(b',');
            l.u64(n as u64);
        }
        Reply::Calibrated(c) => {
            l.field(b"calibrated");
            l.kv_u64(b"scans", c.scans as u64);
            l.kv_u64(b"positions", c.positions as u64);
            l.kv_u64(b"thr", c.threshold as u64);
            l.kv_u64(b"pthr", c.power_threshold as u64);
            l.kv_u64(b"sthr", c.spread_threshold as u64);
            l.kv_u64(b"med", c.median as u64);
            l.kv_u64(b"mad", c.mad as u64);
            l.kv_u64(b"pmed", c.power_median as u64);
            l.kv_u64(b"pmad", c.power_mad as u64);
            l.kv_u64(b"smed", c.spread_median as u64);
            l.kv_u64(b"smad", c.spread_mad as u64);
            l.kv_u64(b"rate", c.rate_ppm as u64);
        }
        Reply::Saved => l.field(b"save"),
        Reply::Defaults => l.field(b"defaults"),
        Reply::Resetting => l.field(b"reset"),
        Reply::Refused(why) => {
            l.field(why.word().as_bytes());
            if let Refusal::OutOfRange { min, max } = why {
                l.byte(b',');
                l.u64(min as u64);
                l.byte(b',');
                l.u64(max as u64);
            }
        }
    }
    sink.line(l.finish(), Priority::Keep);
}

/// Decodes a reply line: the id it echoes (`None` for `-`) and the reply.
pub fn parse_reply(line: &[u8]) -> Result<(Option<u32>, Reply<'_>), ParseError> {
    let body = checked_body(line).map_err(|e| match e {
        FrameError::NoChecksum => ParseError::NoChecksum,
        FrameError::Checksum => ParseError::Checksum,
    })?;
    let mut f = body.split(|&b| b == b',');
    if f.next() != Some(&[REPLY][..]) {
        return Err(ParseError::Type);
    }
    let id = match f.next() {
        Some(b"-") => None,
        Some(s) => Some(parse_u32(s).ok_or(ParseError::Format)?),
        None => return Err(ParseError::Format),
    };
    let reply = match f.next() {
        Some(b"ok") => parse_ok(&mut f)?,
        Some(b"err") => Reply::Refused(parse_refusal(&mut f)?),
        _ => return Err(ParseError::Format),
    };
    if f.next().is_some() {
        return Err(ParseError::Format);
    }
    if id.is_none() && !matches!(reply, Reply::Refused(_)) {
        return Err(ParseError::Format);
    }
    Ok((id, reply))
}

fn parse_ok<'s, I: Iterator<Item = &'s [u8]>>(f: &mut I) -> Result<Reply<'s>, ParseError> {
    let what = f.next().ok_or(ParseError::Format)?;
    Ok(match what {
        b"status" => return Status::parse(f).map(Reply::Status),
        b"save" => Reply::Saved,
        b"defaults" => Reply::Defaults,
        b"reset" => Reply::Resetting,
        b"calibrate" => {
            let n = f.next().and_then(parse_u32).ok_or(ParseError::Format)?;
            Reply::Calibrating(u16::try_from(n).map_err(|_| ParseError::Format)?)
        }
        b"calibrated" => {
            let mut field = |key: &str| {
                f.next()
                    .and_then(|x| kv(x, key.as_bytes()))
                    .and_then(parse_u32)
                    .ok_or(ParseError::Format)
            };
            let scans = u16::try_from(field("scans")?).map_err(|_| ParseError::Format)?;
            let mut c = Calibration {
                scans,
                positions: field("positions")?,
                threshold: field("thr")?,
                power_threshold: field("pthr")?,
                spread_threshold: field("sthr")?,
                median: field("med")?,
                mad: field("mad")?,
                power_median: field("pmed")?,
                power_mad: field("pmad")?,
                spread_median: field("smed")?,
                spread_mad: field("smad")?,
                // A board that does not say calibrated for the default.
                rate_ppm: DEFAULT_RATE_PPM,
            };
            if let Some(x) = f.next() {
                c.rate_ppm = kv(x, b"rate")
                    .and_then(parse_u32)
                    .ok_or(ParseError::Format)?;
            }
            Reply::Calibrated(c)
        }
        kv_field => match key_value_source(kv_field) {
            Some((key, value, source)) => Reply::Value { key, value, source },
            None => other_key(kv_field).ok_or(ParseError::Format)?,
        },
    })
}

fn parse_refusal<'s, I: Iterator<Item = &'s [u8]>>(f: &mut I) -> Result<Refusal, ParseError> {
    let word = f.next().ok_or(ParseError::Format)?;
    if word == b"range" {
        let min = f.next().and_then(parse_u32).ok_or(ParseError::Format)?;
        let max = f.next().and_then(parse_u32).ok_or(ParseError::Format)?;
        return Ok(Refusal::OutOfRange { min, max });
    }
    Refusal::SIMPLE
        .into_iter()
        .find(|r| r.word().as_bytes() == word)
        .ok_or(ParseError::Format)
}

/// `key=value:source`, the form of a setting in replies.
/// A well-formed `key=value:source` whose key is not one of [`Key::ALL`].
fn other_key(s: &[u8]) -> Option<Reply<'_>> {
    let (key, rest) = split_once(s, b'=')?;
    if key.is_empty()
        || Key::from_name(key).is_some()
        || !key
            .iter()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || *b == b'_')
    {
        return None;
    }
    let colon = rest.iter().rposition(|&b| b == b':')?;
    let (value, src) = (rest.get(..colon)?, rest.get(colon + 1..)?);
    let [c] = src else { return None };
    if value.is_empty() || !value.iter().all(|b| b.is_ascii_graphic() && *b != b':') {
        return None;
    }
    Some(Reply::OtherKey {
        key,
        value,
        source: Source::from_char(*c)?,
    })
}

fn key_value_source(s: &[u8]) -> Option<(Key, u32, Source)> {
    let (name, rest) = split_once(s, b'=')?;
    let key = Key::from_name(name)?;
    let colon = rest.iter().rposition(|&b| b == b':')?;
    let (v, src) = (rest.get(..colon)?, rest.get(colon + 1..)?);
    let [c] = src else { return None };
    Some((key, key.decode(v)?, Source::from_char(*c)?))
}
