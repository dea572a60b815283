//! What the decoder rebuilds of one scan ([`ScanResult`]): its header,
//! row summaries, scores, defects and objects as they arrived, and the
//! images written from them.

use cvm_core::flags;
use cvm_core::objects::Object;
use cvm_core::protocol::{EndInfo, ResetCause, ScoreValue};
use std::collections::{BTreeMap, BTreeSet};

/// A damaged or unexpected line.
#[derive(Clone, Debug, PartialEq)]
pub struct LineError {
    /// 1-based line number in the stream.
    pub line: usize,
    pub kind: Kind,
    pub what: String,
}

/// What kind of damage a [`LineError`] is: a stable name for machines
/// (`dmap listen --json`'s `"kind"`, the conformance vectors), beside the
/// sentence for people. docs/dmap.md ("Kinds of damage") lists them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// No `*XXXX` trailer.
    NoChecksum,
    /// The CRC does not match.
    Checksum,
    /// Right CRC, fields that do not parse.
    Malformed,
    /// Right CRC, a field outside its range.
    Range,
    /// Right CRC, an unknown line type.
    UnknownType,
    /// Longer than the protocol allows.
    TooLong,
    /// Cut: by a signal, or by the start of another line in it.
    Cut,
    /// A line outside any scan.
    OutsideScan,
    /// A scan without its end line (a new header, the stream's end, a signal).
    ScanCut,
    /// No scan in the whole stream.
    NoScan,
    /// A scan beyond `--max-scans`.
    MaxScans,
    /// A header of another protocol version.
    Version,
    /// A line out of the protocol's order.
    Order,
    /// A row, score or object reported twice.
    Duplicate,
    /// Fields of one line that contradict each other or the header.
    Field,
    /// Lines that should have arrived and did not, or counts that do not add up.
    Missing,
    /// A line that contradicts other lines of its scan (`O`, `D`, `S`, `R`, `E`).
    CrossCheck,
    /// An end line whose verdict its own totals contradict.
    Verdict,
    /// Maps the firmware scored at a wrong position.
    Misplaced,
    /// More lines than the decoder holds.
    Capacity,
}

impl Kind {
    pub fn name(self) -> &'static str {
        match self {
            Kind::NoChecksum => "no-checksum",
            Kind::Checksum => "checksum",
            Kind::Malformed => "malformed",
            Kind::Range => "range",
            Kind::UnknownType => "unknown-type",
            Kind::TooLong => "too-long",
            Kind::Cut => "cut",
            Kind::OutsideScan => "outside-scan",
            Kind::ScanCut => "scan-cut",
            Kind::NoScan => "no-scan",
            Kind::MaxScans => "max-scans",
            Kind::Version => "version",
            Kind::Order => "order",
            Kind::Duplicate => "duplicate",
            Kind::Field => "field",
            Kind::Missing => "missing",
            Kind::CrossCheck => "cross-check",
            Kind::Verdict => "verdict",
            Kind::Misplaced => "misplaced",
            Kind::Capacity => "capacity",
        }
    }
}

impl std::fmt::Display for LineError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line {}: {}", self.line, self.what)
    }
}

/// A defect as the firmware reported it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Defect {
    pub row: u32,
    pub col: u32,
    /// Magnitude in distance units.
    pub score: f64,
    /// Power magnitude, a contrast (`pmag / 2^15`).
    pub power: f64,
    /// How far past its threshold the strongest channel that fired is,
    /// `Q16` (65536 = at the threshold).
    pub strength: u32,
    pub flags: u8,
    /// Spread magnitude, a share of the power (`smag / 2^16`).
    pub spread: f64,
    /// The magnitudes as the line carries them (`Q(q)`, `Q15`, `Q16`).
    pub mag: u32,
    pub pmag: u16,
    pub smag: u32,
    /// Its line number in the stream.
    pub line: usize,
}

/// Strength (`Q16` ratio to the threshold) as a ratio.
pub fn strength_ratio(strength: u32) -> f64 {
    strength as f64 / 65536.0
}

/// `"cvm"`, `"power"`, `"spread"`: the channels of a flag or `channels` value.
pub fn channel_names(bits: u8) -> Vec<&'static str> {
    let mut v = Vec::new();
    if bits & flags::CVM_DEFECT != 0 {
        v.push("cvm");
    }
    if bits & flags::POWER_DEFECT != 0 {
        v.push("power");
    }
    if bits & flags::SPREAD_DEFECT != 0 {
        v.push("spread");
    }
    v
}

/// Size of a defect object along its rows and columns, in positions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ObjectSize {
    /// Detected extent (height, width): `row1 - row0 + 1`, `col1 - col0 + 1`.
    pub extent: (u64, u64),
    /// The defect's size: the extent less one position on each side (at
    /// least 1). Eq. 1 compares a position's two neighbours, so the
    /// positions just outside a defect score like its edge.
    pub size: (u64, u64),
}

impl ObjectSize {
    pub fn of(o: &Object) -> Self {
        let h = u64::from(o.row1.saturating_sub(o.row0)) + 1;
        let w = u64::from(o.col1.saturating_sub(o.col0)) + 1;
        let corrected = |n: u64| n.saturating_sub(2).max(1);
        ObjectSize {
            extent: (h, w),
            size: (corrected(h), corrected(w)),
        }
    }
}

/// A `Q8` centroid coordinate in positions.
pub fn q8(v: u64) -> f64 {
    v as f64 / 256.0
}

/// Everything decoded about one scan.
#[derive(Clone, Debug, Default)]
pub struct ScanResult {
    /// Protocol version of the header.
    pub version: u32,
    pub firmware: String,
    pub geometry: (u8, u8),
    pub cols: usize,
    /// Score format: integer scores are `s / 2^q` distance units.
    pub q: i32,
    pub threshold: f64,
    /// The header's thresholds as the lines compare with them (`thr`, `Q(q)`;
    /// `pthr`, `Q15`; `sthr`, `Q16`, 4294967295 when off).
    pub thr: u32,
    pub pthr: u32,
    pub sthr: u32,
    /// The header's `rows` (version 6 on).
    pub header_rows: Option<u32>,
    /// Power channel threshold as a contrast (`pthr / 2^15`); `None`: the
    /// channel is off (`pthr` above every power magnitude).
    pub power_threshold: Option<f64>,
    /// Spread channel threshold as a share of the power (`sthr / 2^16`);
    /// `None`: the channel is off.
    pub spread_threshold: Option<f64>,
    /// `k`, `b`, `w` and `norm` of the header.
    pub kernels: char,
    pub kernel_size: u8,
    pub weights: String,
    pub normalise: bool,
    pub scores_enabled: bool,
    /// Full scale of the samples (`fs`).
    pub full_scale: u16,
    /// Most defect lines per row (`dcap`).
    pub max_defect_lines: u16,
    /// Why the board last started (`rst`), and its starts since power-on (`boots`).
    pub reset_cause: Option<ResetCause>,
    pub boots: u32,
    /// The header's `rows`, `src` and `store` (version 6 on).
    pub origin: Option<cvm_core::protocol::Origin>,
    /// Magnitudes, power magnitudes and flags received, by row then
    /// column (integers as the lines carry them). Sparse, so that memory
    /// follows the lines received, never the geometry a (possibly
    /// corrupted) header claims.
    pub scores: BTreeMap<u32, BTreeMap<u32, ScoreValue>>,
    /// Row summaries received, and the line each came on.
    pub rows: BTreeMap<u32, cvm_core::RowSummary>,
    pub(super) row_lines: BTreeMap<u32, usize>,
    /// `S` lines filed (within the columns, not repeated).
    pub(super) score_lines: u64,
    pub defects: Vec<Defect>,
    /// Defects counted by row lines but not listed (per-row cap).
    pub unlisted_defects: u64,
    /// Defect objects (`O` lines) in the order they arrived, and the line
    /// each came on.
    pub objects: Vec<Object>,
    pub(super) object_lines: Vec<usize>,
    /// `O` lines that arrived in the scan, kept or not (for the end
    /// line's `obj`).
    pub objects_arrived: u64,
    /// Ids of the objects that arrived.
    pub(super) object_ids: BTreeSet<u32>,
    pub end: Option<EndInfo>,
    /// Problems found while decoding this scan (beyond damaged lines; the
    /// first [`MAX_PROBLEMS`]).
    pub problems: Vec<LineError>,
    /// Problems beyond [`MAX_PROBLEMS`], counted only.
    pub problems_not_listed: usize,
    /// Scores held in `scores`.
    pub n_scores: usize,
    /// Where the scan's lines have got to, to check their order.
    pub(super) order: Order,
}

/// The line order of docs/protocol.md: rows ascending, each its `R` line,
/// its `D` lines strongest first, its `S` lines by column, then the `O`
/// lines of the objects it closed in increasing id; at the scan's end, the
/// `O` lines of the objects still open.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Order {
    /// The row of the last `R` line, its `listed` count and the `D` lines
    /// that arrived for it.
    pub(super) row: Option<(u32, u32, u32)>,
    /// Strength and column of the row's last `D` line.
    pub(super) last_defect: Option<(u32, u32)>,
    /// `col0` of the row's last `S` line.
    pub(super) last_scores: Option<u32>,
    /// Since the last `R` line: the last `O` line's id, and whether its
    /// object ends in that very row (only the end of the scan closes such
    /// an object).
    pub(super) last_object: Option<(u32, bool)>,
}

impl ScanResult {
    /// `thr`, `pthr` and `sthr`, as [`super::linechecks::decide`] takes them.
    pub fn thresholds(&self) -> [u32; 3] {
        [self.thr, self.pthr, self.sthr]
    }

    pub(super) fn add_problem(&mut self, e: LineError) {
        if self.problems.len() < MAX_PROBLEMS {
            self.problems.push(e);
        } else {
            self.problems_not_listed += 1;
        }
    }

    /// Problems in all, listed or not.
    pub fn problem_count(&self) -> usize {
        self.problems.len() + self.problems_not_listed
    }

    /// Distinct rows of which a row line or a score arrived: what the
    /// stream shows of the scan's size, beyond what its header and end line
    /// claim.
    pub fn rows_arrived(&self) -> usize {
        let mut n = self.rows.len();
        n += self
            .scores
            .keys()
            .filter(|r| !self.rows.contains_key(r))
            .count();
        n
    }

    pub(super) fn units(&self, s: u32) -> f64 {
        s as f64 * (-(self.q as f64)).exp2()
    }

    /// Rows of the image: from the end line, else the highest row seen.
    pub fn n_rows(&self) -> usize {
        let seen = self
            .rows
            .keys()
            .chain(self.scores.keys())
            .max()
            .map_or(0, |&r| r as usize + 1);
        match self.end {
            Some(e) => (e.totals.rows as usize).max(seen),
            None => seen,
        }
    }

    /// The image of docs/method.md §2: only the magnitude travels over the link,
    /// so components 0 and 1 are NaN; NaN also where no score arrived or
    /// the position had no data.
    pub fn image(&self) -> Vec<f64> {
        self.plane(|v| self.units(v.mag), |d| d.score)
    }

    /// The power channel's image in the layout of [`ScanResult::image`]:
    /// the power magnitude (a contrast) in component 2, NaN elsewhere.
    pub fn power_image(&self) -> Vec<f64> {
        self.plane(|v| cvm_core::power::to_units(v.pmag as u32), |d| d.power)
    }

    /// The spread channel's image in the layout of [`ScanResult::image`]:
    /// the spread magnitude (a share of the power) in component 2, NaN
    /// elsewhere and where only a defect line arrived (it carries no
    /// spread).
    pub fn spread_image(&self) -> Vec<f64> {
        self.plane(|v| cvm_core::spread::to_units(v.smag), |_| f64::NAN)
    }

    /// `(rows, cols, 3)` with `value` of each score in component 2 (from
    /// the defect lines when the scan has no score lines).
    fn plane(
        &self,
        value: impl Fn(&ScoreValue) -> f64,
        defect: impl Fn(&Defect) -> f64,
    ) -> Vec<f64> {
        let (rows, cols) = (self.n_rows(), self.cols);
        let mut img = vec![f64::NAN; rows * cols * 3];
        for (&r, line) in &self.scores {
            for (&c, v) in line {
                let c = c as usize;
                if v.flags & flags::NO_DATA == 0 && (r as usize) < rows && c < cols {
                    img[(r as usize * cols + c) * 3 + 2] = value(v);
                }
            }
        }
        if !self.scores_enabled {
            // Without score lines, the defects are the only positions known.
            for d in &self.defects {
                let (r, c) = (d.row as usize, d.col as usize);
                if r < rows && c < cols {
                    img[(r * cols + c) * 3 + 2] = defect(d);
                }
            }
        }
        img
    }

    /// Positions with a score (data), positions reported without data.
    pub fn coverage(&self) -> (usize, usize) {
        let mut with = 0;
        let mut without = 0;
        for line in self.scores.values() {
            for v in line.values() {
                if v.flags & flags::NO_DATA == 0 {
                    with += 1;
                } else {
                    without += 1;
                }
            }
        }
        (with, without)
    }
}

/// Problems kept per scan; beyond, they are only counted.
pub const MAX_PROBLEMS: usize = 1000;

/// Largest score image `dmap listen -o` writes (about 800 MB of f64).
pub const MAX_IMAGE_POSITIONS: usize = 1 << 25;

/// Why the image of `s` is not written, if it is not: larger than
/// [`MAX_IMAGE_POSITIONS`], or claiming (by its header, end line or a row
/// number) at least twice the rows that arrived.
pub fn image_refusal(s: &ScanResult) -> Option<String> {
    let (rows, cols) = (s.n_rows(), s.cols);
    if rows
        .checked_mul(cols)
        .is_none_or(|p| p > MAX_IMAGE_POSITIONS)
    {
        return Some(format!(
            "claims {rows} rows x {cols} columns, more than the {MAX_IMAGE_POSITIONS} positions an image may hold"
        ));
    }
    let arrived = s.rows_arrived();
    if rows > 2 * arrived {
        return Some(format!(
            "claims {rows} rows but only {arrived} arrived (row or score lines): an image of what did not arrive is not worth {} MB",
            rows * cols * 24 / 1_000_000
        ));
    }
    None
}

/// `n` positions at a pitch of `pitch_um` µm, in mm.
pub(super) fn mm(n: u64, pitch_um: f64) -> f64 {
    n as f64 * pitch_um / 1000.0
}
