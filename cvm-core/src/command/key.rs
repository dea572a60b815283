//! The runtime settings a host may read and change: their names on the
//! wire, their types and ranges, and where each lives in [`Settings`].

use super::refusal::Refusal;
use super::wire::parse_u32;
use crate::settings::Settings;

/// What the firmware was built to hold: the ranges of `cols`, `rows` and
/// `dcap` (16 bits each, which also bounds the length of a `status` reply).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Capacity {
    /// Most columns a scan may have (the pipeline's `MAX_COLS`).
    pub max_cols: u16,
    /// Most rows a scan may have.
    pub max_rows: u16,
    /// Most defect lines per row the firmware will list.
    pub max_dcap: u16,
}

/// A runtime setting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Key {
    /// Integer magnitude threshold, as the header's `thr` (any 32-bit value).
    Threshold,
    /// Power threshold, as the header's `pthr` (any 32-bit value; above
    /// 46340 the power channel is off).
    PowerThreshold,
    /// Per-position score lines (`0` or `1`).
    Scores,
    /// Defect lines per row (`0..=max_dcap`).
    DefectCap,
    /// Columns of a scan (`1..=max_cols`).
    Cols,
    /// Rows of a scan (`1..=max_rows`).
    Rows,
}

impl Key {
    /// Every key, in the order of the `status` reply.
    pub const ALL: [Key; 6] = [
        Key::Cols,
        Key::Rows,
        Key::Threshold,
        Key::PowerThreshold,
        Key::Scores,
        Key::DefectCap,
    ];

    /// The name on the wire, the same as the header's field where there is one.
    pub const fn name(self) -> &'static str {
        match self {
            Key::Threshold => "thr",
            Key::PowerThreshold => "pthr",
            Key::Scores => "scores",
            Key::DefectCap => "dcap",
            Key::Cols => "cols",
            Key::Rows => "rows",
        }
    }

    /// The key named `s`.
    pub fn from_name(s: &[u8]) -> Option<Key> {
        Key::ALL.into_iter().find(|k| k.name().as_bytes() == s)
    }

    /// Whether the value is a flag (`0` or `1`) rather than a number.
    pub const fn is_flag(self) -> bool {
        matches!(self, Key::Scores)
    }

    /// The smallest and largest value the key takes on a board of this capacity.
    pub const fn range(self, cap: &Capacity) -> (u32, u32) {
        match self {
            Key::Threshold | Key::PowerThreshold => (0, u32::MAX),
            Key::Scores => (0, 1),
            Key::DefectCap => (0, cap.max_dcap as u32),
            Key::Cols => (1, cap.max_cols as u32),
            Key::Rows => (1, cap.max_rows as u32),
        }
    }

    /// Reads and checks a value for this key: a flag is `0` or `1`, a
    /// number is 1 to 10 decimal digits; anything else is the wrong type,
    /// and a number outside [`Key::range`] (or beyond 32 bits) is out of
    /// range.
    pub fn parse_value(self, s: &[u8], cap: &Capacity) -> Result<u32, Refusal> {
        if s.is_empty() || !s.iter().all(u8::is_ascii_digit) {
            return Err(Refusal::WrongType);
        }
        if self.is_flag() {
            return match s {
                b"0" => Ok(0),
                b"1" => Ok(1),
                _ => Err(Refusal::WrongType),
            };
        }
        let (min, max) = self.range(cap);
        match parse_u32(s) {
            Some(v) if v >= min && v <= max => Ok(v),
            _ => Err(Refusal::OutOfRange { min, max }),
        }
    }

    /// The key's value in `s`; `None` for `rows`, which the firmware keeps
    /// beside [`Settings`] (the pipeline itself does not count rows).
    pub fn get(self, s: &Settings) -> Option<u32> {
        match self {
            Key::Threshold => Some(s.threshold),
            Key::PowerThreshold => Some(s.power_threshold),
            Key::Scores => Some(s.scores as u32),
            Key::DefectCap => Some(s.max_defect_lines_per_row as u32),
            Key::Cols => Some(s.cols),
            Key::Rows => None,
        }
    }

    /// Sets the key's value in `s` (a value checked by [`Key::parse_value`]);
    /// false for `rows`, and for a value the field cannot hold.
    pub fn set(self, s: &mut Settings, v: u32) -> bool {
        match self {
            Key::Threshold => s.threshold = v,
            Key::PowerThreshold => s.power_threshold = v,
            Key::Scores if v <= 1 => s.scores = v == 1,
            Key::DefectCap => match u16::try_from(v) {
                Ok(v) => s.max_defect_lines_per_row = v,
                Err(_) => return false,
            },
            Key::Cols if v >= 1 => s.cols = v,
            Key::Scores | Key::Cols | Key::Rows => return false,
        }
        true
    }
}
