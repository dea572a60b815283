//! The `status` reply: what the board is, what it scans with and where
//! each value came from, why it started, and how its last scan went.
//!
//! `A,<id>,ok,status,pv=7,fw=..,j=15x15,cap=<cols>x<rows>,store=..,rst=..,boots=..,last=<scans>/<defects>/<objects>/<verdict>,keys=<n>`,
//! followed by `n` value replies (`A,<id>,ok,<key>=<value>:<source>`),
//! one per setting in `Key::ALL`'s order: every setting with its source
//! would not fit one line.

use super::wire::{VERSION, kv, parse_u32, split_once};
use crate::protocol::{LineBuf, MAX_FW, ParseError};
use crate::settings::{KEYS, ResetCause, Store};
use crate::verdict::Verdict;

/// The last scan, as its end line counted it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LastScan {
    /// Scans ended since start-up.
    pub scans: u32,
    /// Its defective positions (the end line's `defects`).
    pub defects: u32,
    /// Its defect objects (the end line's `objects`).
    pub objects: u32,
    /// Its verdict, as its end line's (`none` before the first scan).
    pub verdict: Option<Verdict>,
}

/// The `status` reply's content. `F` holds the firmware text: borrowed
/// from the line as decoded (`&str`), or a copy of it for a client that
/// keeps the reply after its line is gone ([`Status::with_firmware`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Status<F = &'static str> {
    /// At most `MAX_FW` characters are sent, as in the header.
    pub firmware: F,
    pub j1: u8,
    pub j2: u8,
    /// The capacity's columns and rows (`cap=`; the defect-line cap's
    /// range is the `range` refusal's business).
    pub max_cols: u16,
    pub max_rows: u16,
    pub store: Store,
    pub reset_cause: ResetCause,
    pub boots: u32,
    pub last: LastScan,
}

impl<F> Status<F> {
    /// The same status with `keep` applied to its firmware text (to own
    /// it, say: `s.with_firmware(String::from)`).
    pub fn with_firmware<G>(self, keep: impl FnOnce(F) -> G) -> Status<G> {
        Status {
            firmware: keep(self.firmware),
            j1: self.j1,
            j2: self.j2,
            max_cols: self.max_cols,
            max_rows: self.max_rows,
            store: self.store,
            reset_cause: self.reset_cause,
            boots: self.boots,
            last: self.last,
        }
    }
}

impl Status<&str> {
    /// Appends the fields after `status`.
    pub(super) fn encode(&self, l: &mut LineBuf) {
        l.kv_u64(b"pv", VERSION as u64);
        l.field(b"fw=");
        for &b in self.firmware.as_bytes().iter().take(MAX_FW) {
            // Only characters that cannot break the line's syntax.
            l.byte(if b.is_ascii_graphic() && b != b',' && b != b'*' {
                b
            } else {
                b'?'
            });
        }
        l.field(b"j=");
        l.u64(self.j1 as u64);
        l.byte(b'x');
        l.u64(self.j2 as u64);
        l.field(b"cap=");
        l.u64(self.max_cols as u64);
        l.byte(b'x');
        l.u64(self.max_rows as u64);
        l.field(b"store=");
        l.bytes(self.store.word().as_bytes());
        l.field(b"rst=");
        l.bytes(self.reset_cause.as_str().as_bytes());
        l.kv_u64(b"boots", self.boots as u64);
        l.kv_u64(b"last", self.last.scans as u64);
        l.byte(b'/');
        l.u64(self.last.defects as u64);
        l.byte(b'/');
        l.u64(self.last.objects as u64);
        l.byte(b'/');
        l.bytes(match self.last.verdict {
            Some(v) => v.as_str().as_bytes(),
            None => b"none",
        });
        l.kv_u64(b"keys", KEYS as u64);
    }

    /// Reads the fields after `status`.
    pub(super) fn parse<'s, I: Iterator<Item = &'s [u8]>>(
        mut f: I,
    ) -> Result<Status<&'s str>, ParseError> {
        let mut field = |key: &str| f.next().and_then(|x| kv(x, key.as_bytes()));
        if field("pv").and_then(parse_u32) != Some(VERSION) {
            return Err(ParseError::Format);
        }
        let fw = field("fw").ok_or(ParseError::Format)?;
        let firmware = core::str::from_utf8(fw).map_err(|_| ParseError::Format)?;
        let pair = |s: Option<&[u8]>| {
            let (a, b) = split_once(s?, b'x')?;
            Some((parse_u32(a)?, parse_u32(b)?))
        };
        let (j1, j2) = pair(field("j")).ok_or(ParseError::Format)?;
        let (cols, rows) = pair(field("cap")).ok_or(ParseError::Format)?;
        let store = field("store").and_then(Store::parse);
        let reset_cause = field("rst").and_then(ResetCause::parse);
        let boots = field("boots").and_then(parse_u32);
        let last = field("last").and_then(parse_last);
        // The value replies that follow: this firmware's keys.
        if field("keys").and_then(parse_u32) != Some(KEYS as u32) {
            return Err(ParseError::Format);
        }
        if f.next().is_some() {
            return Err(ParseError::Format);
        }
        let fits = |v: u32| u8::try_from(v).ok();
        let wide = |v: u32| u16::try_from(v).ok();
        Ok(Status {
            firmware,
            j1: fits(j1).ok_or(ParseError::Format)?,
            j2: fits(j2).ok_or(ParseError::Format)?,
            max_cols: wide(cols).ok_or(ParseError::Format)?,
            max_rows: wide(rows).ok_or(ParseError::Format)?,
            store: store.ok_or(ParseError::Format)?,
            reset_cause: reset_cause.ok_or(ParseError::Format)?,
            boots: boots.ok_or(ParseError::Format)?,
            last: last.ok_or(ParseError::Format)?,
        })
    }
}

fn parse_last(s: &[u8]) -> Option<LastScan> {
    let mut p = s.split(|&b| b == b'/');
    let scans = parse_u32(p.next()?)?;
    let defects = parse_u32(p.next()?)?;
    let objects = parse_u32(p.next()?)?;
    let word = p.next()?;
    let verdict = match word {
        b"none" => None,
        w => Some(Verdict::parse(w)?),
    };
    if p.next().is_some() {
        return None;
    }
    Some(LastScan {
        scans,
        defects,
        objects,
        verdict,
    })
}
