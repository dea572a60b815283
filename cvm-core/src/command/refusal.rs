//! Why a request was refused: the reason a refusal reply carries.

/// The reason of an `err` reply.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Refusal {
    /// The line's checksum does not match (`checksum`); its id is not trusted.
    Checksum,
    /// Not a request line: no trailer, no id, wrong type letter, wrong
    /// number of fields (`malformed`).
    Malformed,
    /// More than `MAX_LINE` bytes before the `\n` (`too-long`).
    TooLong,
    /// A command this version does not know (`unknown-command`).
    UnknownCommand,
    /// A setting this firmware does not have (`unknown-key`).
    UnknownKey,
    /// A value of the wrong type: not a decimal number, or a flag not `0`
    /// or `1` (`type`).
    WrongType,
    /// A number outside the key's range (`range,<min>,<max>`).
    OutOfRange { min: u32, max: u32 },
    /// The request cannot run now, e.g. while a calibration runs (`busy`).
    Busy,
    /// Received bytes were lost to a receiver overrun (`overrun`).
    Overrun,
    /// A byte of the line arrived with a framing error (`framing`).
    Framing,
    /// A byte of the line arrived with noise (`noise`).
    Noise,
    /// Writing the settings to flash failed (`storage`).
    Storage,
    /// The value would leave the settings unable to work together, e.g.
    /// row mode without a pulse width (`conflict`).
    Conflict,
    /// A calibration ended without a result: its scans had no position
    /// with data, or more positions than its counts hold (`no-result`).
    NoResult,
}

impl Refusal {
    /// The reason's word on the wire.
    pub const fn word(self) -> &'static str {
        match self {
            Refusal::Checksum => "checksum",
            Refusal::Malformed => "malformed",
            Refusal::TooLong => "too-long",
            Refusal::UnknownCommand => "unknown-command",
            Refusal::UnknownKey => "unknown-key",
            Refusal::WrongType => "type",
            Refusal::OutOfRange { .. } => "range",
            Refusal::Busy => "busy",
            Refusal::Overrun => "overrun",
            Refusal::Framing => "framing",
            Refusal::Noise => "noise",
            Refusal::Storage => "storage",
            Refusal::Conflict => "conflict",
            Refusal::NoResult => "no-result",
        }
    }

    /// Every reason without a value, in the order of the protocol document.
    pub const SIMPLE: [Refusal; 13] = [
        Refusal::Checksum,
        Refusal::Malformed,
        Refusal::TooLong,
        Refusal::UnknownCommand,
        Refusal::UnknownKey,
        Refusal::WrongType,
        Refusal::Busy,
        Refusal::Overrun,
        Refusal::Framing,
        Refusal::Noise,
        Refusal::Storage,
        Refusal::Conflict,
        Refusal::NoResult,
    ];
}

impl core::fmt::Display for Refusal {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Refusal::Checksum => f.write_str("checksum mismatch (the request was damaged)"),
            Refusal::Malformed => f.write_str("malformed request line"),
            Refusal::TooLong => f.write_str("request line too long"),
            Refusal::UnknownCommand => f.write_str("unknown command"),
            Refusal::UnknownKey => f.write_str("unknown setting"),
            Refusal::WrongType => f.write_str("value of the wrong type"),
            Refusal::OutOfRange { min, max } => write!(f, "value out of range {min}..={max}"),
            Refusal::Busy => f.write_str("busy (a calibration is running)"),
            Refusal::Overrun => f.write_str("bytes lost to a receiver overrun"),
            Refusal::Framing => f.write_str("framing error on the link"),
            Refusal::Noise => f.write_str("noise on the link"),
            Refusal::Storage => f.write_str("the settings could not be written to flash"),
            Refusal::NoResult => {
                f.write_str("the calibration has no result (no position with data, or too many)")
            }
            Refusal::Conflict => {
                f.write_str("conflicts with another setting (row mode needs a pulse width)")
            }
        }
    }
}
