//! The settings value of a scan: what the pipeline needs besides the
//! scorer, and what the header line reports about the board's start.
//!
//! It is its own module so that the pipeline (which acts on it) and the
//! line protocol (whose header carries it) both read it without reading
//! each other. The host resolves it once from its options; a board builds
//! it at start-up, and a command channel may later get and set the same
//! value between scans.

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

/// The settings of a scan: the runtime values a board scans with (the
/// thresholds, which lines it emits, the scan's width) and the facts about
/// its start that the header reports. The scoring itself (geometry,
/// kernels, formats) is the [`crate::Scorer`]'s, fixed when it is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Settings {
    /// Columns (beams per row) of the scan.
    pub cols: u32,
    /// Integer magnitude at or above which a position is a defect.
    pub threshold: u32,
    /// Power magnitude (`Q15`) at or above which a position is a defect
    /// ([`crate::channels::power::POWER_OFF`]: never).
    pub power_threshold: u32,
    /// Spread magnitude (`Q16`) at or above which a position is a defect
    /// ([`crate::channels::spread::SPREAD_OFF`], the default: the channel is off and
    /// measures nothing).
    pub spread_threshold: u32,
    /// Emit per-position score (`S`) lines.
    pub scores: bool,
    /// At most this many defect (`D`) lines per row, the strongest; the row
    /// line carries the full count, so a truncated list is visible, and the
    /// header the cap (`dcap`). 0 (no per-position lines; the objects
    /// describe the defects) is the boards' default.
    pub max_defect_lines_per_row: u16,
    pub firmware_version: &'static str,
    /// Why the board last started (`rst`; [`ResetCause::PowerOn`] on the host).
    pub reset_cause: ResetCause,
    /// Starts since power-on, this one included (`boots`; 1 on the host).
    pub boots: u32,
    /// Rows of a scan (`rows`): the boards end a scan after this many;
    /// the host writes its scan's.
    pub rows: u32,
    /// The part verdict's rules and the READY and REJECT outputs.
    pub outputs: Outputs,
    /// Where each runtime setting's value came from, in the order of
    /// `command::Key::ALL` (`src`).
    pub sources: [Source; KEYS],
    /// What became of the settings record in flash at start-up (`store`).
    pub store: Store,
}

/// Runtime settings a command channel may get and set (`command::Key`).
pub const KEYS: usize = 16;

impl Settings {
    /// Settings of `cols` x `rows` scans with these thresholds, everything
    /// else at its default: the spread channel off, no score or defect lines, [`Outputs::DEFAULT`],
    /// every value compiled in, no settings record, a power-on start.
    pub const fn new(
        cols: u32,
        rows: u32,
        threshold: u32,
        power_threshold: u32,
        firmware_version: &'static str,
    ) -> Self {
        Settings {
            cols,
            threshold,
            power_threshold,
            spread_threshold: crate::channels::spread::SPREAD_OFF,
            scores: false,
            max_defect_lines_per_row: 0,
            firmware_version,
            reset_cause: ResetCause::PowerOn,
            boots: 1,
            rows,
            outputs: Outputs::DEFAULT,
            sources: [Source::Default; KEYS],
            store: Store::Empty,
        }
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

/// Where a runtime setting's value came from, as the command channel's
/// `status`, `get` and `set` replies report it (docs/commands.md,
/// "Settings").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Source {
    /// The value compiled into the firmware (`d`).
    Default,
    /// The value of the settings record read from flash at start-up (`f`).
    Flash,
    /// Changed through the command channel since start-up and not saved (`c`).
    Changed,
}

impl Source {
    /// Every source, in the order of the protocol document.
    pub const ALL: [Source; 3] = [Source::Default, Source::Flash, Source::Changed];

    /// The letter a reply carries after the value.
    pub const fn as_char(self) -> u8 {
        match self {
            Source::Default => b'd',
            Source::Flash => b'f',
            Source::Changed => b'c',
        }
    }

    /// The source whose letter is `c`.
    pub fn from_char(c: u8) -> Option<Self> {
        Source::ALL.into_iter().find(|s| s.as_char() == c)
    }
}

/// When REJECT is asserted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RejectMode {
    /// Once per part, at the scan's end, when the verdict rejects it.
    Part,
    /// A pulse each time a row closes an object that counts, `row_delay`
    /// rows later.
    Row,
}

/// The part verdict's rules and the READY and REJECT outputs: plain data,
/// compiled defaults on the boards today, so that a command channel can
/// later get and set the same value between scans. The pipeline reads the
/// verdict's fields; the pins' fields are the board's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Outputs {
    /// An object rejects its part when its area (positions) is at least this.
    pub min_area: u32,
    /// ... and its peak strength (`Q16`, as the `O` line's `peak`) at
    /// least this (65536: at its threshold, which every object reaches).
    pub min_strength: u32,
    /// Positions without data a scan may have and still be inspected.
    pub max_missing: u32,
    /// Misplaced frames a scan may have and still be inspected.
    pub max_misplaced: u32,
    pub reject_mode: RejectMode,
    /// REJECT's pulse width, µs; 0 in part mode: held until the next
    /// scan starts.
    pub pulse_us: u32,
    /// Row mode: the pulse starts this many rows after the closing row.
    pub row_delay: u32,
    /// READY's asserted level is high: always, the fail-safe level (a
    /// pin in reset, an unpowered board or a broken wire reads low at the
    /// PLC's input, "not ready"). The command channel refuses the other.
    pub ready_high: bool,
    /// REJECT's asserted level is high: never, REJECT is active low for
    /// the same reason (a floating line reads "reject").
    pub reject_high: bool,
}

impl Outputs {
    /// The defaults: every object and every lost position rejects the
    /// part; REJECT held per part; READY active high and REJECT active
    /// low, the levels at which a line that nothing drives reads "not
    /// ready" and "reject".
    pub const DEFAULT: Outputs = Outputs {
        min_area: 0,
        min_strength: 0,
        max_missing: 0,
        max_misplaced: 0,
        reject_mode: RejectMode::Part,
        pulse_us: 0,
        row_delay: 0,
        ready_high: true,
        reject_high: false,
    };
}

impl Default for Outputs {
    fn default() -> Self {
        Outputs::DEFAULT
    }
}
