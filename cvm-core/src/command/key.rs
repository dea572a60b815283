//! How a runtime setting's value is written and read on the command
//! channel. The settings themselves (names, kinds, units, ranges, fields)
//! are declared once, in [`crate::settings::SETTINGS`].

use super::refusal::Refusal;
use super::wire::parse_u32;
use crate::protocol::LineBuf;
use crate::settings::{Capacity, Key, Kind, RejectMode, Settings};

impl Key {
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
}

/// Settings that cannot work together: row mode pulses REJECT, so it
/// needs a pulse width. `set` refuses a change that would leave the
/// settings so (`conflict`): set `pulse` before `mode=row`.
pub fn conflict(s: &Settings) -> bool {
    s.outputs.reject_mode == RejectMode::Row && s.outputs.pulse_us == 0
}
