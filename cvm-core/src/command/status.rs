//! The `status` reply: what the board is, what it scans with and where
//! each value came from, why it started, and how its last scan went.
//!
//! `A,<id>,ok,status,pv=5,fw=..,j=15x15,cap=<cols>x<rows>,store=..,cols=<v>:<s>,rows=..,thr=..,pthr=..,scores=..,dcap=..,rst=..,boots=..,last=<scans>/<defects>/<objects>/<verdict>`

use super::key::Key;
use super::wire::{VERSION, kv, parse_u32, split_once, value_source};
use crate::protocol::{LineBuf, MAX_FW, ParseError};
use crate::settings::{ResetCause, Source};

/// What became of the settings record in flash at start-up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Store {
    /// No record: the compiled values are in use (`none`).
    Empty,
    /// A record for this firmware was read (`ok`).
    Loaded,
    /// A record made for another build (settings layout, geometry, kernels
    /// or full scale) was ignored (`foreign`).
    Foreign,
    /// The storage could not be read (`bad`).
    Unreadable,
}

impl Store {
    pub const ALL: [Store; 4] = [
        Store::Empty,
        Store::Loaded,
        Store::Foreign,
        Store::Unreadable,
    ];

    pub const fn word(self) -> &'static str {
        match self {
            Store::Empty => "none",
            Store::Loaded => "ok",
            Store::Foreign => "foreign",
            Store::Unreadable => "bad",
        }
    }

    fn parse(s: &[u8]) -> Option<Store> {
        Store::ALL.into_iter().find(|v| v.word().as_bytes() == s)
    }
}

/// How the last scan ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Verdict {
    /// No scan has ended since start-up (`none`).
    NoScan,
    /// No defect (`pass`).
    Pass,
    /// At least one defect (`fail`).
    Fail,
}

impl Verdict {
    pub const ALL: [Verdict; 3] = [Verdict::NoScan, Verdict::Pass, Verdict::Fail];

    pub const fn word(self) -> &'static str {
        match self {
            Verdict::NoScan => "none",
            Verdict::Pass => "pass",
            Verdict::Fail => "fail",
        }
    }
}

/// The last scan, as its end line counted it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LastScan {
    /// Scans ended since start-up.
    pub scans: u32,
    /// Its defective positions (the end line's `defects`).
    pub defects: u32,
    /// Its defect objects (the end line's `objects`).
    pub objects: u32,
    pub verdict: Verdict,
}

/// The `status` reply's content.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Status<'s> {
    /// At most `MAX_FW` characters are sent, as in the header.
    pub firmware: &'s str,
    pub j1: u8,
    pub j2: u8,
    /// The capacity's columns and rows (`cap=`; the defect-line cap's
    /// range is the `range` refusal's business).
    pub max_cols: u16,
    pub max_rows: u16,
    pub store: Store,
    /// Each runtime setting's value and source, in [`Key::ALL`]'s order;
    /// `cols`, `rows` and `dcap` below 65536, as their ranges make them,
    /// which keeps the longest reply within `MAX_LINE` (tested).
    pub values: [(u32, Source); 6],
    pub reset_cause: ResetCause,
    pub boots: u32,
    pub last: LastScan,
}

fn value(l: &mut LineBuf, key: Key, (v, src): (u32, Source)) {
    l.kv_u64(key.name().as_bytes(), v as u64);
    l.byte(b':');
    l.byte(src.as_char());
}

impl Status<'_> {
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
        for (key, v) in Key::ALL.into_iter().zip(self.values) {
            value(l, key, v);
        }
        l.field(b"rst=");
        l.bytes(self.reset_cause.as_str().as_bytes());
        l.kv_u64(b"boots", self.boots as u64);
        l.kv_u64(b"last", self.last.scans as u64);
        l.byte(b'/');
        l.u64(self.last.defects as u64);
        l.byte(b'/');
        l.u64(self.last.objects as u64);
        l.byte(b'/');
        l.bytes(self.last.verdict.word().as_bytes());
    }

    /// Reads the fields after `status`.
    pub(super) fn parse<'s, I: Iterator<Item = &'s [u8]>>(
        mut f: I,
    ) -> Result<Status<'s>, ParseError> {
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
        let mut values = [(0, Source::Default); 6];
        for (slot, key) in values.iter_mut().zip(Key::ALL) {
            *slot = field(key.name())
                .and_then(value_source)
                .ok_or(ParseError::Format)?;
        }
        let reset_cause = field("rst").and_then(ResetCause::parse);
        let boots = field("boots").and_then(parse_u32);
        let last = field("last").and_then(parse_last);
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
            values,
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
    let verdict = Verdict::ALL
        .into_iter()
        .find(|v| v.word().as_bytes() == word)?;
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
