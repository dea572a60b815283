//! Request lines, host to board: `C,<id>,<command>[,<argument>]*XXXX\n`.

use super::refusal::Refusal;
use super::wire::{
    FrameError, MAX_CALIBRATION_RATE_PPM, MAX_CALIBRATION_SCANS, MAX_LINE, REQUEST, checked_body,
    parse_u32, split_once,
};
use crate::calibration::rule::DEFAULT_RATE_PPM;
use crate::protocol::{LineBuf, LineSink, Priority};
use crate::settings::{Capacity, Key};

/// A request, decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Request {
    /// `status`
    Status,
    /// `get,<key>`
    Get(Key),
    /// `set,<key>=<value>`, the value checked against the key's range.
    Set(Key, u32),
    /// `calibrate,<n>[,<rate>]`: the next n scans are of defect-free
    /// reference parts, and the thresholds are set for a target of `rate`
    /// false positions per million parts (the tail rule's; 1000, one in
    /// 1000 parts, when not given).
    Calibrate { scans: u16, rate_ppm: u32 },
    /// `save`: the settings in effect go to flash.
    Save,
    /// `defaults`: back to the compiled values (not saved).
    Defaults,
    /// `reset`: the board restarts once the reply is out.
    Reset,
}

/// Writes the request line with this id.
pub fn encode_request(id: u32, r: &Request, sink: &mut impl LineSink) {
    let mut l = LineBuf::new(REQUEST);
    l.byte(b',');
    l.u64(id as u64);
    match *r {
        Request::Status => l.field(b"status"),
        Request::Get(k) => {
            l.field(b"get");
            l.field(k.name().as_bytes());
        }
        Request::Set(k, v) => {
            l.field(b"set");
            l.field(k.name().as_bytes());
            l.byte(b'=');
            k.encode(v, &mut l);
        }
        Request::Calibrate { scans, rate_ppm } => {
            l.field(b"calibrate");
            l.byte(b',');
            l.u64(scans as u64);
            // The default goes unsaid, so that a board that predates the
            // argument takes the request.
            if rate_ppm != DEFAULT_RATE_PPM {
                l.byte(b',');
                l.u64(rate_ppm as u64);
            }
        }
        Request::Save => l.field(b"save"),
        Request::Defaults => l.field(b"defaults"),
        Request::Reset => l.field(b"reset"),
    }
    sink.line(l.finish(), Priority::Keep);
}

/// A refused request: the id to echo (`None` when the line's id cannot
/// be trusted: a bad checksum, or no readable id) and the reason.
pub type Refused = (Option<u32>, Refusal);

/// Decodes a received request line (its `\n` or `\r\n` optional), checks
/// every value against `cap`, and returns its id and request, or what to
/// refuse it with.
pub fn parse_request(line: &[u8], cap: &Capacity) -> Result<(u32, Request), Refused> {
    let without_nl = line.strip_suffix(b"\n").unwrap_or(line);
    if without_nl.len() >= MAX_LINE {
        return Err((None, Refusal::TooLong));
    }
    let body = match checked_body(line) {
        Ok(b) => b,
        Err(FrameError::Checksum) => return Err((None, Refusal::Checksum)),
        Err(FrameError::NoChecksum) => return Err((None, Refusal::Malformed)),
    };
    let mut f = body.split(|&b| b == b',');
    if f.next() != Some(&[REQUEST][..]) {
        return Err((None, Refusal::Malformed));
    }
    let id = f
        .next()
        .and_then(parse_u32)
        .ok_or((None, Refusal::Malformed))?;
    let refuse = |r| (Some(id), r);
    let command = f.next().ok_or(refuse(Refusal::Malformed))?;
    let arg = f.next();
    // Only `calibrate` takes a second argument.
    let second = match command {
        b"calibrate" => f.next(),
        _ => None,
    };
    if f.next().is_some() {
        return Err(refuse(Refusal::Malformed));
    }
    let bare = |r: Request| match arg {
        None => Ok((id, r)),
        Some(_) => Err(refuse(Refusal::Malformed)),
    };
    match command {
        b"status" => bare(Request::Status),
        b"save" => bare(Request::Save),
        b"defaults" => bare(Request::Defaults),
        b"reset" => bare(Request::Reset),
        b"get" => {
            let name = arg.ok_or(refuse(Refusal::Malformed))?;
            let key = Key::from_name(name).ok_or(refuse(Refusal::UnknownKey))?;
            Ok((id, Request::Get(key)))
        }
        b"set" => {
            let (name, value) = arg
                .and_then(|a| split_once(a, b'='))
                .ok_or(refuse(Refusal::Malformed))?;
            let key = Key::from_name(name).ok_or(refuse(Refusal::UnknownKey))?;
            let v = key.parse_value(value, cap).map_err(refuse)?;
            Ok((id, Request::Set(key, v)))
        }
        b"calibrate" => {
            let n = arg.ok_or(refuse(Refusal::Malformed))?;
            let scans = count(n, MAX_CALIBRATION_SCANS as u32).map_err(refuse)?;
            let rate_ppm = match second {
                None => DEFAULT_RATE_PPM,
                Some(r) => count(r, MAX_CALIBRATION_RATE_PPM).map_err(refuse)?,
            };
            Ok((
                id,
                Request::Calibrate {
                    // At most MAX_CALIBRATION_SCANS, a u16.
                    scans: scans as u16,
                    rate_ppm,
                },
            ))
        }
        _ => Err(refuse(Refusal::UnknownCommand)),
    }
}

/// A decimal count in `1..=max`: digits only (`wrong-type` otherwise),
/// and `range,1,<max>` outside it (or past 32 bits).
fn count(s: &[u8], max: u32) -> Result<u32, Refusal> {
    if s.is_empty() || !s.iter().all(u8::is_ascii_digit) {
        return Err(Refusal::WrongType);
    }
    match parse_u32(s) {
        Some(n) if (1..=max).contains(&n) => Ok(n),
        _ => Err(Refusal::OutOfRange { min: 1, max }),
    }
}
