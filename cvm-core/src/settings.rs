//! The settings value of a scan: what the pipeline needs besides the
//! scorer. The facts of the board's start, which the header reports too,
//! are apart in [`crate::boot`].
//!
//! It is its own module so that the pipeline (which acts on it) and the
//! line protocol (whose header carries it) both read it without reading
//! each other. The host resolves it once from its options; a board builds
//! it at start-up, and a command channel may later get and set the same
//! value between scans.

pub use crate::boot::{Boot, ResetCause, Store};

/// The settings of a scan: the runtime values a board scans with (the
/// thresholds, which lines it emits, the scan's width) and where each came
/// from. The scoring itself (geometry, kernels, formats) is the
/// [`crate::Scorer`]'s, fixed when it is built; the start's facts are a
/// [`Boot`].
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
    /// Rows of a scan (`rows`): the boards end a scan after this many;
    /// the host writes its scan's.
    pub rows: u32,
    /// The part verdict's rules and the READY and REJECT outputs.
    pub outputs: Outputs,
    /// Where each runtime setting's value came from, in the order of
    /// `command::Key::ALL` (`src`).
    pub sources: [Source; KEYS],
}

impl Settings {
    /// Settings of `cols` x `rows` scans with these thresholds, everything
    /// else at its default: the spread channel off, no score or defect lines, [`Outputs::DEFAULT`],
    /// every value compiled in.
    pub const fn new(cols: u32, rows: u32, threshold: u32, power_threshold: u32) -> Self {
        Settings {
            cols,
            threshold,
            power_threshold,
            spread_threshold: crate::channels::spread::SPREAD_OFF,
            scores: false,
            max_defect_lines_per_row: 0,
            rows,
            outputs: Outputs::DEFAULT,
            sources: [Source::Default; KEYS],
        }
    }
}

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

/// One runtime setting as [`SETTINGS`] lists it: its name and kind. Its
/// range, field, unit and text are [`Key`]'s methods, written from the same
/// row of `declare_settings!`.
#[derive(Clone, Copy)]
pub struct Spec {
    pub key: Key,
    /// The name on the wire, in `CVM_H743_SCAN`, in `dmap`'s `--set` and
    /// in the docs (the header's field too, where the header has one).
    pub name: &'static str,
    pub kind: Kind,
}

/// Declares the runtime settings once: the [`Key`] enum and its table,
/// [`SETTINGS`], from one row per setting.
macro_rules! declare_settings {
    ($(
        $key:ident $name:literal $kind:expr, $unit:literal, $about:literal,
        range |$c:ident| $range:expr,
        get |$g:ident| $get:expr,
        set |$s:ident, $v:ident| $set:expr;
    )*) => {
        /// A runtime setting (its row of [`SETTINGS`]).
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum Key {
            $(#[doc = $about] $key,)*
        }

        /// Every runtime setting, in the order of the `status` reply, the
        /// header's `src` and the settings record.
        pub const SETTINGS: [Spec; KEYS] = [$(Spec {
            key: Key::$key,
            name: $name,
            kind: $kind,
        },)*];

        /// Runtime settings a command channel may get and set.
        pub const KEYS: usize = [$($name),*].len();

        // The rest as matches rather than function pointers in the table:
        // each arm inlines where a key is known, and a firmware (which
        // never prints the texts) does not carry them in its flash.
        impl Key {
            /// The smallest and largest value the key takes on a board of
            /// this capacity (0 and 1 for flags and choices).
            pub fn range(self, cap: &Capacity) -> (u32, u32) {
                match self { $(Key::$key => { let $c = cap; $range })* }
            }

            /// The key's value in `s`.
            pub fn get(self, s: &Settings) -> u32 {
                match self { $(Key::$key => { let $g = s; $get })* }
            }

            /// Sets the key's value in `s` (a value checked by
            /// `command::Key::parse_value`); false, and `s` unchanged, for a
            /// value the field cannot hold.
            pub fn set(self, s: &mut Settings, v: u32) -> bool {
                match self { $(Key::$key => { let $s = &mut *s; let $v = v; $set })* }
            }

            /// The unit of the value as every interface writes it.
            pub const fn unit(self) -> &'static str {
                match self { $(Key::$key => $unit,)* }
            }

            /// One line on what the setting does (the key's doc, `dmap
            /// sensor`'s help).
            pub const fn about(self) -> &'static str {
                match self { $(Key::$key => $about,)* }
            }
        }
    };
}

const ANY: (u32, u32) = (0, u32::MAX);
const FLAG: (u32, u32) = (0, 1);

declare_settings! {
    Cols "cols" Kind::Number, "beams", "Columns (beams per row) of a scan.",
        range |c| (1, c.max_cols as u32),
        get |s| s.cols,
        set |s, v| v >= 1 && { s.cols = v; true };
    Rows "rows" Kind::Number, "rows", "Rows of a scan: after this many the end line goes out.",
        range |c| (1, c.max_rows as u32),
        get |s| s.rows,
        set |s, v| v >= 1 && { s.rows = v; true };
    Threshold "thr" Kind::Number, "magnitude, integer", "Magnitude at or above which a position is a defect (the header's `thr`).",
        range |_c| ANY,
        get |s| s.threshold,
        set |s, v| { s.threshold = v; true };
    PowerThreshold "pthr" Kind::Number, "Q15", "Power contrast at or above which a position is a defect (above 46340 the power channel is off).",
        range |_c| ANY,
        get |s| s.power_threshold,
        set |s, v| { s.power_threshold = v; true };
    SpreadThreshold "sthr" Kind::Number, "Q16", "Spread at or above which a position is a defect (above 92680 the spread channel is off; `calibrate` sets it, with `thr` and `pthr`).",
        range |_c| ANY,
        get |s| s.spread_threshold,
        set |s, v| { s.spread_threshold = v; true };
    Scores "scores" Kind::Flag, "0 or 1", "Per-position score (`S`) lines.",
        range |_c| FLAG,
        get |s| s.scores as u32,
        set |s, v| v <= 1 && { s.scores = v == 1; true };
    DefectCap "dcap" Kind::Number, "lines per row", "Defect (`D`) lines per row, the strongest.",
        range |c| (0, c.max_dcap as u32),
        get |s| s.max_defect_lines_per_row as u32,
        set |s, v| match u16::try_from(v) { Ok(v) => { s.max_defect_lines_per_row = v; true } Err(_) => false };
    MinArea "area" Kind::Number, "positions", "Smallest area of an object that rejects its part.",
        range |_c| ANY,
        get |s| s.outputs.min_area,
        set |s, v| { s.outputs.min_area = v; true };
    MinPeak "peak" Kind::Number, "Q16 of the threshold", "Smallest peak strength (as the `O` line's `peak`) of an object that rejects its part.",
        range |_c| ANY,
        get |s| s.outputs.min_strength,
        set |s, v| { s.outputs.min_strength = v; true };
    MaxMissing "miss" Kind::Number, "positions", "Positions without data a scan may have and still be inspected.",
        range |_c| ANY,
        get |s| s.outputs.max_missing,
        set |s, v| { s.outputs.max_missing = v; true };
    MaxMisplaced "misp" Kind::Number, "frames", "Misplaced frames a scan may have and still be inspected.",
        range |_c| ANY,
        get |s| s.outputs.max_misplaced,
        set |s, v| { s.outputs.max_misplaced = v; true };
    RejectMode "mode" Kind::Choice(["part", "row"]), "part or row", "When REJECT is asserted: at the scan's end (`part`) or a pulse per object as it closes (`row`).",
        range |_c| FLAG,
        get |s| (s.outputs.reject_mode == RejectMode::Row) as u32,
        set |s, v| v <= 1 && {
            s.outputs.reject_mode = if v == 1 { RejectMode::Row } else { RejectMode::Part };
            true
        };
    Pulse "pulse" Kind::Number, "µs", "REJECT's pulse width (0: held until the next scan starts, part mode only; set it before `mode=row`).",
        range |c| (0, c.max_pulse_us),
        get |s| s.outputs.pulse_us,
        set |s, v| { s.outputs.pulse_us = v; true };
    RowDelay "delay" Kind::Number, "rows", "Row mode: rows between the closing row and the pulse.",
        range |_c| ANY,
        get |s| s.outputs.row_delay,
        set |s, v| { s.outputs.row_delay = v; true };
    // The fail-safe levels only (docs/firmware.md, "Fail-safe"): a line
    // left floating, reset or unpowered reads low, "not ready" and "reject".
    ReadyLevel "ready" Kind::Choice(["low", "high"]), "low or high", "READY's asserted level: `high` only.",
        range |_c| (1, 1),
        get |s| s.outputs.ready_high as u32,
        set |s, v| v == 1 && { s.outputs.ready_high = true; true };
    RejectLevel "reject" Kind::Choice(["low", "high"]), "low or high", "REJECT's asserted level: `low` only.",
        range |_c| (0, 0),
        get |s| s.outputs.reject_high as u32,
        set |s, v| v == 0 && { s.outputs.reject_high = false; true };
}

impl Key {
    /// Every key, in [`SETTINGS`]' order.
    pub const ALL: [Key; KEYS] = {
        let mut all = [Key::Cols; KEYS];
        let mut i = 0;
        while i < KEYS {
            all[i] = SETTINGS[i].key;
            i += 1;
        }
        all
    };

    /// Its row of [`SETTINGS`].
    pub const fn spec(self) -> &'static Spec {
        &SETTINGS[self as usize]
    }

    /// The name on the wire, the same as the header's field where there is one.
    pub const fn name(self) -> &'static str {
        self.spec().name
    }

    pub const fn kind(self) -> Kind {
        self.spec().kind
    }

    /// The key named `s`.
    pub fn from_name(s: &[u8]) -> Option<Key> {
        SETTINGS
            .iter()
            .find(|r| r.name.as_bytes() == s)
            .map(|r| r.key)
    }

    /// Its place in [`Key::ALL`] (and in `Settings::sources`).
    pub const fn index(self) -> usize {
        self as usize
    }

    /// For a channel's threshold, the largest value that can still decide
    /// a position: above it the channel is off. The board keeps any value
    /// it is set to (its header shows it); the host's tools, whose scan
    /// files carry thresholds in units, write every such value as the
    /// channel's off value, `u32::MAX`, and so refuse the others rather
    /// than show another header than the board.
    pub const fn off_above(self) -> Option<u32> {
        match self {
            Key::PowerThreshold => Some(crate::power::POWER_MAX),
            Key::SpreadThreshold => Some(crate::spread::SPREAD_MAX),
            _ => None,
        }
    }
}

// `Key::index` is the discriminant: the table's rows are in the enum's
// order, which the macro guarantees by writing both from one list.
const _: () = {
    let mut i = 0;
    while i < KEYS {
        assert!(SETTINGS[i].key as usize == i);
        i += 1;
    }
};

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
