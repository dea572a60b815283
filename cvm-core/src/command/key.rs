//! The runtime settings a host may read and change: their names on the
//! wire, their types and ranges, and where each lives in [`Settings`].

use super::refusal::Refusal;
use super::wire::parse_u32;
use crate::protocol::LineBuf;
use crate::settings::{KEYS, RejectMode, Settings};

/// What the firmware was built to hold: the ranges of `cols`, `rows`,
/// `dcap` and `pulse` (`cols`, `rows` and `dcap` at most 65535, which
/// bounds the `status` reply's length).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Capacity {
    /// Most columns a scan may have (the pipeline's `MAX_COLS`).
    pub max_cols: u16,
    /// Most rows a scan may have.
    pub max_rows: u16,
    /// Most defect lines per row the firmware will list.
    pub max_dcap: u16,
    /// Longest REJECT pulse the board can time, µs.
    pub max_pulse_us: u32,
}

/// A runtime setting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Key {
    /// Columns of a scan (`1..=max_cols`).
    Cols,
    /// Rows of a scan (`1..=max_rows`).
    Rows,
    /// Integer magnitude threshold, as the header's `thr` (any 32-bit value).
    Threshold,
    /// Power threshold, as the header's `pthr` (any 32-bit value; above
    /// 46340 the power channel is off).
    PowerThreshold,
    /// Spread threshold (`Q16`, as [`Settings::spread_threshold`]; any
    /// 32-bit value, like `pthr`: above 92680, `spread::SPREAD_MAX`, the
    /// spread channel is off).
    SpreadThreshold,
    /// Per-position score lines (`0` or `1`).
    Scores,
    /// Defect lines per row (`0..=max_dcap`).
    DefectCap,
    /// Smallest area (positions) of an object that rejects its part.
    MinArea,
    /// Smallest peak strength (`Q16`, as the `O` line's `peak`) of an
    /// object that rejects its part.
    MinPeak,
    /// Positions without data a scan may have and still be inspected.
    MaxMissing,
    /// Misplaced frames a scan may have and still be inspected.
    MaxMisplaced,
    /// When REJECT is asserted: `part` (at the scan's end) or `row`
    /// (a pulse per object as it closes).
    RejectMode,
    /// REJECT's pulse width, µs (`0..=max_pulse_us`; 0: held until the
    /// next scan starts, part mode only).
    Pulse,
    /// Row mode: rows between the closing row and the pulse.
    RowDelay,
    /// READY's asserted level: `high` only (fail-safe: a line left
    /// floating, reset or unpowered reads low, "not ready").
    ReadyLevel,
    /// REJECT's asserted level: `low` only (fail-safe: a line left
    /// floating, reset or unpowered reads low, "reject").
    RejectLevel,
}

/// What a key's value looks like on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// 1 to 10 decimal digits.
    Number,
    /// `0` or `1`.
    Flag,
    /// One of two words, for the values 0 and 1.
    Choice([&'static str; 2]),
}

impl Key {
    /// Every key, in the order of the `status` reply and the header's `src`.
    pub const ALL: [Key; KEYS] = [
        Key::Cols,
        Key::Rows,
        Key::Threshold,
        Key::PowerThreshold,
        Key::SpreadThreshold,
        Key::Scores,
        Key::DefectCap,
        Key::MinArea,
        Key::MinPeak,
        Key::MaxMissing,
        Key::MaxMisplaced,
        Key::RejectMode,
        Key::Pulse,
        Key::RowDelay,
        Key::ReadyLevel,
        Key::RejectLevel,
    ];

    /// The name on the wire, the same as the header's field where there is one.
    pub const fn name(self) -> &'static str {
        match self {
            Key::Cols => "cols",
            Key::Rows => "rows",
            Key::Threshold => "thr",
            Key::PowerThreshold => "pthr",
            Key::SpreadThreshold => "sthr",
            Key::Scores => "scores",
            Key::DefectCap => "dcap",
            Key::MinArea => "area",
            Key::MinPeak => "peak",
            Key::MaxMissing => "miss",
            Key::MaxMisplaced => "misp",
            Key::RejectMode => "mode",
            Key::Pulse => "pulse",
            Key::RowDelay => "delay",
            Key::ReadyLevel => "ready",
            Key::RejectLevel => "reject",
        }
    }

    /// The key named `s`.
    pub fn from_name(s: &[u8]) -> Option<Key> {
        Key::ALL.into_iter().find(|k| k.name().as_bytes() == s)
    }

    /// Its place in [`Key::ALL`] (and in `Settings::sources`).
    pub fn index(self) -> usize {
        Key::ALL.iter().position(|&k| k == self).unwrap_or(0)
    }

    pub const fn kind(self) -> Kind {
        match self {
            Key::Scores => Kind::Flag,
            Key::RejectMode => Kind::Choice(["part", "row"]),
            Key::ReadyLevel | Key::RejectLevel => Kind::Choice(["low", "high"]),
            _ => Kind::Number,
        }
    }

    /// The smallest and largest value the key takes on a board of this
    /// capacity (0 and 1 for flags and choices).
    pub const fn range(self, cap: &Capacity) -> (u32, u32) {
        match self {
            Key::Cols => (1, cap.max_cols as u32),
            Key::Rows => (1, cap.max_rows as u32),
            Key::DefectCap => (0, cap.max_dcap as u32),
            Key::Pulse => (0, cap.max_pulse_us),
            // The fail-safe levels only (docs/firmware.md, "Fail-safe").
            Key::ReadyLevel => (1, 1),
            Key::RejectLevel => (0, 0),
            _ => match self.kind() {
                Kind::Number => (0, u32::MAX),
                Kind::Flag | Kind::Choice(_) => (0, 1),
            },
        }
    }

    /// Reads a value of this key as a reply or header carries it: digits
    /// for a number, `0`/`1` for a flag, the word for a choice.
    pub fn decode(self, s: &[u8]) -> Option<u32> {
        match self.kind() {
            Kind::Number => parse_u32(s),
            Kind::Flag => match s {
                b"0" => Some(0),
                b"1" => Some(1),
                _ => None,
            },
            Kind::Choice(words) => words
                .iter()
                .position(|w| w.as_bytes() == s)
                .map(|i| i as u32),
        }
    }

    /// Writes value `v` of this key.
    pub(crate) fn encode(self, v: u32, l: &mut LineBuf) {
        match self.kind() {
            Kind::Choice(words) => l.bytes(words[(v != 0) as usize].as_bytes()),
            Kind::Flag => l.u64((v != 0) as u64),
            Kind::Number => l.u64(v as u64),
        }
    }

    /// Reads and checks a requested value for this key: anything not of
    /// the key's [`Kind`] (a number of 1 to 10 digits, `0`/`1`, one of the
    /// choice's words) is the wrong type, and a number outside
    /// [`Key::range`] (or beyond 32 bits) is out of range.
    pub fn parse_value(self, s: &[u8], cap: &Capacity) -> Result<u32, Refusal> {
        let (min, max) = self.range(cap);
        if self.kind() != Kind::Number {
            let v = self.decode(s).ok_or(Refusal::WrongType)?;
            return if v >= min && v <= max {
                Ok(v)
            } else {
                Err(Refusal::OutOfRange { min, max })
            };
        }
        if s.is_empty() || !s.iter().all(u8::is_ascii_digit) {
            return Err(Refusal::WrongType);
        }
        match parse_u32(s) {
            Some(v) if v >= min && v <= max => Ok(v),
            _ => Err(Refusal::OutOfRange { min, max }),
        }
    }

    /// The key's value in `s`.
    pub fn get(self, s: &Settings) -> u32 {
        let o = &s.outputs;
        match self {
            Key::Cols => s.cols,
            Key::Rows => s.rows,
            Key::Threshold => s.threshold,
            Key::PowerThreshold => s.power_threshold,
            Key::SpreadThreshold => s.spread_threshold,
            Key::Scores => s.scores as u32,
            Key::DefectCap => s.max_defect_lines_per_row as u32,
            Key::MinArea => o.min_area,
            Key::MinPeak => o.min_strength,
            Key::MaxMissing => o.max_missing,
            Key::MaxMisplaced => o.max_misplaced,
            Key::RejectMode => (o.reject_mode == RejectMode::Row) as u32,
            Key::Pulse => o.pulse_us,
            Key::RowDelay => o.row_delay,
            Key::ReadyLevel => o.ready_high as u32,
            Key::RejectLevel => o.reject_high as u32,
        }
    }

    /// Sets the key's value in `s` (a value checked by [`Key::parse_value`]);
    /// false, and `s` unchanged, for a value the field cannot hold.
    pub fn set(self, s: &mut Settings, v: u32) -> bool {
        let o = &mut s.outputs;
        match self {
            Key::Cols if v >= 1 => s.cols = v,
            Key::Rows if v >= 1 => s.rows = v,
            Key::Threshold => s.threshold = v,
            Key::PowerThreshold => s.power_threshold = v,
            Key::SpreadThreshold => s.spread_threshold = v,
            Key::Scores if v <= 1 => s.scores = v == 1,
            Key::DefectCap => match u16::try_from(v) {
                Ok(v) => s.max_defect_lines_per_row = v,
                Err(_) => return false,
            },
            Key::MinArea => o.min_area = v,
            Key::MinPeak => o.min_strength = v,
            Key::MaxMissing => o.max_missing = v,
            Key::MaxMisplaced => o.max_misplaced = v,
            Key::RejectMode if v <= 1 => {
                o.reject_mode = if v == 1 {
                    RejectMode::Row
                } else {
                    RejectMode::Part
                }
            }
            Key::Pulse => o.pulse_us = v,
            Key::RowDelay => o.row_delay = v,
            Key::ReadyLevel if v == 1 => o.ready_high = true,
            Key::RejectLevel if v == 0 => o.reject_high = false,
            Key::Cols
            | Key::Rows
            | Key::Scores
            | Key::RejectMode
            | Key::ReadyLevel
            | Key::RejectLevel => return false,
        }
        true
    }
}

/// Settings that cannot work together: row mode pulses REJECT, so it
/// needs a pulse width. `set` refuses a change that would leave the
/// settings so (`conflict`): set `pulse` before `mode=row`.
pub fn conflict(s: &Settings) -> bool {
    s.outputs.reject_mode == RejectMode::Row && s.outputs.pulse_us == 0
}
