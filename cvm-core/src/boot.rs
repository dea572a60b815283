//! The facts of a board's start that its header and `status` report
//! beside the settings: the firmware, why it started, how many starts
//! since power-on, and what became of its settings record. They are fixed
//! at start-up; the command channel changes settings, never these.

/// Why the board last started, as the header's `rst` carries it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ResetCause {
    /// Power-on (`por`); also `dmap stream` and the emulated board.
    PowerOn,
    /// A watchdog (`wdg`).
    Watchdog,
    /// A software reset: after a panic, or a debugger's request (`sw`).
    Software,
    /// The reset pin (`pin`).
    Pin,
    /// Anything else (`other`): a brown-out among them.
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

    /// The cause whose `rst=` value is `s`.
    pub(crate) fn parse(s: &[u8]) -> Option<Self> {
        ResetCause::ALL
            .into_iter()
            .find(|c| c.as_str().as_bytes() == s)
    }
}

/// What became of the settings record in flash at start-up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Store {
    /// No record: the compiled values are in use (`none`; the host and
    /// the emulated board, which keep none, always say this).
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

    pub fn parse(s: &[u8]) -> Option<Store> {
        Store::ALL.into_iter().find(|v| v.word().as_bytes() == s)
    }
}

/// The start a header reports (`fw`, `rst`, `boots`, `store`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Boot {
    /// The firmware's version (`fw`).
    pub firmware: &'static str,
    /// Why the board last started (`rst`; [`ResetCause::PowerOn`] on the host).
    pub reset_cause: ResetCause,
    /// Starts since power-on, this one included (`boots`; 1 on the host).
    pub boots: u32,
    /// What became of the settings record in flash at start-up (`store`).
    pub store: Store,
}

impl Boot {
    /// A power-on start of `firmware` without a settings record: the
    /// host's and the emulated board's.
    pub const fn power_on(firmware: &'static str) -> Self {
        Boot {
            firmware,
            reset_cause: ResetCause::PowerOn,
            boots: 1,
            store: Store::Empty,
        }
    }
}
