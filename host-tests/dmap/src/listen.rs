//! `dmap listen`: decodes the firmware's result lines (from a file, stdin or
//! a serial port), checks every CRC, reports damaged lines by number and
//! keeps going, and rebuilds each scan's score images, defect objects and
//! summary.

use crate::npy::write_gradient;
use crate::stream::fmt_num;
use anyhow::{Context, Result, bail};
use clap::Args;
use cvm_core::flags;
use cvm_core::objects::Object;
use cvm_core::protocol::{self, EndInfo, Line, ResetCause, ScoreValue};
use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

#[derive(Args, Clone, Debug)]
pub struct ListenArgs {
    /// Read lines from FILE ("-" for standard input)
    #[arg(
        long,
        value_name = "FILE",
        conflicts_with = "port",
        required_unless_present = "port"
    )]
    pub input: Option<String>,
    /// Read lines from a serial port (e.g. /dev/ttyACM0, the ST-LINK virtual COM port)
    #[arg(long, value_name = "DEV")]
    pub port: Option<String>,
    /// Serial baud rate
    #[arg(long, default_value_t = 921600)]
    pub baud: u32,
    /// With --port: stop after this many scans have ended (0 = run until interrupted)
    #[arg(long, default_value_t = 1)]
    pub scans: usize,
    /// Write the score image of docs/method.md §2: float64, shape (rows, cols, 3), the
    /// magnitude in [..., 2] (distance units), NaN in [..., 0] and [..., 1] (the components
    /// do not travel) and where no score arrived; a second scan goes to OUT_2.npy, and so on
    #[arg(short, long, value_name = "OUT.npy")]
    pub output: Option<PathBuf>,
    /// Write the power channel's image (docs/method.md §6) in the same shape and layout as
    /// -o, so that dmap render and dmap eval read it alike: the power magnitude (a
    /// contrast, 0 to 1.41) in [..., 2], NaN in [..., 0] and [..., 1] and where no score
    /// arrived; a second scan goes to OUT_2.npy, and so on
    #[arg(long, value_name = "OUT.npy")]
    pub power_output: Option<PathBuf>,
    /// Scan pitch in µm (the same on both axes): object sizes in mm besides positions.
    /// An object's extent is one position wider on each side than its defect (Eq. 1
    /// compares a position's two neighbours); the defect size printed is the extent less
    /// 2 positions per axis, at least 1
    #[arg(long, value_name = "P", value_parser = positive_f64)]
    pub pitch_um: Option<f64>,
    /// Decode at most this many scans in one run; later scans are reported, not kept
    #[arg(long, default_value_t = DEFAULT_MAX_SCANS, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..=MAX_SCANS as i64))]
    pub max_scans: u32,
    /// Print the summary as one JSON document instead of text: {"objects", "totals"} of
    /// the last (or only) scan, "problems" of the whole stream, and "scans" (every scan's
    /// header, objects, defect lines, totals and problems); see docs/protocol.md
    #[arg(long)]
    pub json: bool,
}

/// A finite number above 0 (`--pitch-um`).
fn positive_f64(s: &str) -> Result<f64, String> {
    s.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && *v > 0.0)
        .ok_or_else(|| "expected a finite number above 0".to_string())
}

/// A damaged or unexpected line.
#[derive(Clone, Debug, PartialEq)]
pub struct LineError {
    /// 1-based line number in the stream.
    pub line: usize,
    pub what: String,
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
}

/// Strength (`Q16` ratio to the threshold) as a ratio.
pub fn strength_ratio(strength: u32) -> f64 {
    strength as f64 / 65536.0
}

/// `"cvm"`, `"power"`: the channels of a flag or `channels` value.
pub fn channel_names(bits: u8) -> Vec<&'static str> {
    let mut v = Vec::new();
    if bits & flags::CVM_DEFECT != 0 {
        v.push("cvm");
    }
    if bits & flags::POWER_DEFECT != 0 {
        v.push("power");
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
    /// Power channel threshold as a contrast (`pthr / 2^15`); `None`: the
    /// channel is off (`pthr` above every power magnitude).
    pub power_threshold: Option<f64>,
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
    /// Magnitudes, power magnitudes and flags received, by row then
    /// column (integers as the lines carry them). Sparse, so that memory
    /// follows the lines received, never the geometry a (possibly
    /// corrupted) header claims.
    pub scores: BTreeMap<u32, BTreeMap<u32, ScoreValue>>,
    /// Row summaries received.
    pub rows: BTreeMap<u32, cvm_core::RowSummary>,
    pub defects: Vec<Defect>,
    /// Defects counted by row lines but not listed (per-row cap).
    pub unlisted_defects: u64,
    /// Defect objects (`O` lines) in the order they arrived.
    pub objects: Vec<Object>,
    /// `O` lines that arrived in the scan, kept or not (for the end
    /// line's `obj`).
    pub objects_arrived: u64,
    /// Ids of the objects that arrived.
    object_ids: BTreeSet<u32>,
    pub end: Option<EndInfo>,
    /// Problems found while decoding this scan (beyond damaged lines; the
    /// first [`MAX_PROBLEMS`]).
    pub problems: Vec<LineError>,
    /// Problems beyond [`MAX_PROBLEMS`], counted only.
    pub problems_not_listed: usize,
    /// Scores held in `scores`.
    pub n_scores: usize,
    /// Where the scan's lines have got to, to check their order.
    order: Order,
}

/// The line order of docs/protocol.md: rows ascending, each its `R` line,
/// its `D` lines strongest first, its `S` lines by column, then the `O`
/// lines of the objects it closed in increasing id; at the scan's end, the
/// `O` lines of the objects still open.
#[derive(Clone, Copy, Debug, Default)]
struct Order {
    /// The row of the last `R` line, its `listed` count and the `D` lines
    /// that arrived for it.
    row: Option<(u32, u32, u32)>,
    /// Strength and column of the row's last `D` line.
    last_defect: Option<(u32, u32)>,
    /// `col0` of the row's last `S` line.
    last_scores: Option<u32>,
    /// Since the last `R` line: the last `O` line's id, and whether its
    /// object ends in that very row (only the end of the scan closes such
    /// an object).
    last_object: Option<(u32, bool)>,
}

impl ScanResult {
    fn add_problem(&mut self, e: LineError) {
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

    fn units(&self, s: u32) -> f64 {
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

/// Scans one run decodes by default, and at most (`--max-scans`).
pub const DEFAULT_MAX_SCANS: u32 = 64;
pub const MAX_SCANS: u32 = 4096;

/// Row lines, defects and scores one run holds, over all its scans (the
/// largest image's worth, about 1.5 GB at most): memory does not grow with
/// the number of scans either.
pub const MAX_KEPT: usize = MAX_IMAGE_POSITIONS;

/// Line errors kept (and listed); beyond, they are only counted.
pub const MAX_ERRORS: usize = 1000;
/// Problems kept per scan; beyond, they are only counted.
pub const MAX_PROBLEMS: usize = 1000;
/// Defect lines kept per scan (a scan of the largest image with a defect
/// listed at every position).
pub const MAX_DEFECTS: usize = MAX_IMAGE_POSITIONS;

/// The stream decoder: feed it lines, collect scans and errors. Memory is
/// bounded whatever the stream: at most `max_scans` scans, each with at
/// most [`MAX_IMAGE_POSITIONS`] scores and [`MAX_DEFECTS`] defects, and
/// [`MAX_ERRORS`] errors listed.
pub struct Decoder {
    line_no: usize,
    current: Option<ScanResult>,
    pub scans: Vec<ScanResult>,
    /// Damaged lines and lines outside any scan (the first [`MAX_ERRORS`]).
    pub errors: Vec<LineError>,
    /// Errors beyond [`MAX_ERRORS`], counted only.
    pub errors_not_listed: usize,
    /// Scans beyond `max_scans`, whose lines were skipped.
    pub scans_skipped: usize,
    skipping: bool,
    max_scans: usize,
    /// Row lines, defects and scores held, over all scans, and at most.
    kept: usize,
    max_kept: usize,
}

impl Default for Decoder {
    fn default() -> Self {
        Self::with_max_scans(DEFAULT_MAX_SCANS as usize)
    }
}

impl Decoder {
    pub fn new() -> Self {
        Self::default()
    }

    /// A decoder that keeps at most `max_scans` scans (at least one).
    pub fn with_max_scans(max_scans: usize) -> Self {
        Decoder {
            line_no: 0,
            current: None,
            scans: Vec::new(),
            errors: Vec::new(),
            errors_not_listed: 0,
            scans_skipped: 0,
            skipping: false,
            max_scans: max_scans.max(1),
            kept: 0,
            max_kept: MAX_KEPT,
        }
    }

    /// The same decoder holding at most `kept` row lines, defects and
    /// scores over all its scans (default [`MAX_KEPT`]).
    pub fn with_budget(mut self, kept: usize) -> Self {
        self.max_kept = kept;
        self
    }

    /// Line errors in all, listed or not.
    pub fn error_count(&self) -> usize {
        self.errors.len() + self.errors_not_listed
    }

    /// One line per kind of damage seen in the stream (none: the stream
    /// arrived whole): line errors, problems of scans, skipped scans.
    pub fn damage(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.error_count() > 0 {
            out.push(format!("{} line error(s)", self.error_count()));
        }
        for (k, s) in self.scans.iter().enumerate() {
            if s.problem_count() > 0 {
                out.push(format!("scan {}: {} problem(s)", k + 1, s.problem_count()));
            }
        }
        if self.scans_skipped > 0 {
            out.push(format!(
                "{} scan(s) beyond --max-scans {} skipped",
                self.scans_skipped, self.max_scans
            ));
        }
        out
    }

    /// A line too long for the protocol, of which only the length is known.
    pub fn feed_too_long(&mut self, len: usize) {
        self.line_no += 1;
        self.error(format!(
            "line of {len} bytes is longer than the protocol's {} (garbage or a lost newline)",
            protocol::MAX_LINE
        ));
    }

    /// Scans that have ended (an end line arrived).
    pub fn ended(&self) -> usize {
        self.scans.iter().filter(|s| s.end.is_some()).count()
    }

    fn error(&mut self, what: impl Into<String>) {
        if self.errors.len() < MAX_ERRORS {
            self.errors.push(LineError {
                line: self.line_no,
                what: what.into(),
            });
        } else {
            self.errors_not_listed += 1;
        }
    }

    fn problem(&mut self, what: impl Into<String>) {
        let e = LineError {
            line: self.line_no,
            what: what.into(),
        };
        match &mut self.current {
            Some(s) => s.add_problem(e),
            None => self.error(e.what),
        }
    }

    /// Decodes one line (with or without its newline).
    pub fn feed(&mut self, raw: &[u8]) {
        self.line_no += 1;
        let trimmed = raw.strip_suffix(b"\n").unwrap_or(raw);
        let trimmed = trimmed.strip_suffix(b"\r").unwrap_or(trimmed);
        if trimmed.is_empty() {
            return;
        }
        if self.skipping && !trimmed.starts_with(b"H,") {
            // A scan beyond --max-scans: its lines are counted, not kept.
            if trimmed.starts_with(b"E,") {
                self.skipping = false;
            }
            return;
        }
        // MAX_LINE counts the newline.
        if trimmed.len() >= protocol::MAX_LINE {
            self.error(format!(
                "line of {} bytes is longer than the protocol's {} (garbage or a lost newline)",
                trimmed.len() + 1,
                protocol::MAX_LINE
            ));
            return;
        }
        let line = match protocol::parse(trimmed) {
            Ok(l) => l,
            Err(e) => {
                self.error(e.to_string());
                return;
            }
        };
        match line {
            Line::Object(o) => self.object(o),
            Line::Header(h) => {
                self.skipping = false;
                if let Some(prev) = self.current.take() {
                    self.error("new scan header before the previous scan's end line");
                    self.scans.push(prev);
                }
                if self.scans.len() >= self.max_scans {
                    self.scans_skipped += 1;
                    self.skipping = true;
                    if self.scans_skipped == 1 {
                        self.error(format!(
                            "more than {} scans in one run: this scan and later ones are skipped (--max-scans)",
                            self.max_scans
                        ));
                    }
                    return;
                }
                let mut s = ScanResult {
                    version: h.version,
                    firmware: h.firmware.to_string(),
                    geometry: (h.j1, h.j2),
                    cols: h.cols as usize,
                    q: h.q,
                    scores_enabled: h.scores,
                    full_scale: h.full_scale,
                    max_defect_lines: h.max_defect_lines,
                    reset_cause: Some(h.reset_cause),
                    boots: h.boots,
                    kernels: h.kernels as char,
                    kernel_size: h.kernel_size,
                    weights: h.weights.to_string(),
                    normalise: h.normalise,
                    power_threshold: (h.power_threshold <= cvm_core::power::POWER_MAX)
                        .then(|| cvm_core::power::to_units(h.power_threshold)),
                    ..ScanResult::default()
                };
                s.threshold = s.units(h.threshold);
                if h.version != protocol::VERSION {
                    s.problems.push(LineError {
                        line: self.line_no,
                        what: format!(
                            "protocol version {} (this decoder reads {})",
                            h.version,
                            protocol::VERSION
                        ),
                    });
                }
                self.current = Some(s);
            }
            Line::Row { summary, listed } => {
                let Some(s) = self.current.as_mut() else {
                    return self.error("row line outside a scan (header lost?)");
                };
                if s.rows.contains_key(&summary.row) {
                    return self.problem(format!("row {} reported twice", summary.row));
                }
                let order = s.order;
                s.order = Order {
                    row: Some((summary.row, listed, 0)),
                    ..Order::default()
                };
                if let Some((prev, ..)) = order.row
                    && summary.row < prev
                {
                    self.problem(format!(
                        "row line of row {} after row {prev} (rows out of order)",
                        summary.row
                    ));
                }
                if let (Some((prev, ..)), Some((id, true))) = (order.row, order.last_object) {
                    self.problem(format!(
                        "object {id} ends in row {prev} but row {}'s line follows it: only the scan's end closes an object in the last row reported (out of order)",
                        summary.row
                    ));
                }
                self.check_defects_arrived(order);
                let Some(s) = self.current.as_mut() else {
                    return;
                };
                if s.rows.len() >= MAX_IMAGE_POSITIONS || self.kept >= self.max_kept {
                    return self.problem("more row lines than an image can hold; the rest ignored");
                }
                s.unlisted_defects += (summary.defects - listed.min(summary.defects)) as u64;
                s.rows.insert(summary.row, summary);
                self.kept += 1;
            }
            Line::Defect {
                row,
                col,
                mag,
                pmag,
                strength,
                flags,
            } => {
                let Some(s) = self.current.as_mut() else {
                    return self.error("defect line outside a scan (header lost?)");
                };
                if s.defects.len() >= MAX_DEFECTS || self.kept >= self.max_kept {
                    return self
                        .problem("more defect lines than an image can hold; the rest ignored");
                }
                self.kept += 1;
                let score = s.units(mag);
                s.defects.push(Defect {
                    row,
                    col,
                    score,
                    power: cvm_core::power::to_units(pmag as u32),
                    strength,
                    flags,
                });
                let order = &mut s.order;
                let what = match order.row {
                    Some((r, ..)) if r != row => Some(format!(
                        "defect line of row {row} among the lines of row {r} (out of order)"
                    )),
                    None => Some(format!(
                        "defect line of row {row} before any row line (out of order)"
                    )),
                    Some(_) if order.last_scores.is_some() => Some(format!(
                        "defect line of row {row} after its score lines (out of order)"
                    )),
                    Some(_) if order.last_object.is_some() => Some(format!(
                        "defect line of row {row} after the object lines of its row (out of order)"
                    )),
                    Some((_, listed, arrived)) if arrived >= listed => Some(format!(
                        "row {row} lists {listed} defect line(s); more arrived"
                    )),
                    Some(_) => match order.last_defect {
                        Some((m, c)) if strength > m || (strength == m && col <= c) => {
                            Some(format!(
                                "defect lines of row {row} not strongest first (column {col} after column {c})"
                            ))
                        }
                        _ => None,
                    },
                };
                if let Some((_, _, arrived)) = order.row.as_mut() {
                    *arrived += 1;
                }
                order.last_defect = Some((strength, col));
                if let Some(what) = what {
                    self.problem(what);
                }
                if flags & cvm_core::flags::DEFECT == 0 || strength < 1 << 16 {
                    self.problem(format!(
                        "defect line of row {row} column {col} is no defect (flags {flags}, strength {strength})"
                    ));
                }
            }
            Line::Scores { row, col0, chars } => {
                let Some(s) = self.current.as_mut() else {
                    return self.error("score line outside a scan (header lost?)");
                };
                let order = &mut s.order;
                let misplaced = match (order.row, order.last_scores) {
                    (Some((r, ..)), _) if r != row => Some(format!(
                        "score line of row {row} among the lines of row {r} (out of order)"
                    )),
                    (None, _) => Some(format!(
                        "score line of row {row} before any row line (out of order)"
                    )),
                    (_, Some(c)) if col0 <= c => Some(format!(
                        "score line of row {row} from column {col0} after the one from column {c} (out of order)"
                    )),
                    _ if order.last_object.is_some() => Some(format!(
                        "score line of row {row} after the object lines of its row (out of order)"
                    )),
                    _ => None,
                };
                order.last_scores = Some(col0);
                if let Some(what) = misplaced {
                    self.problem(what);
                }
                let Some(s) = self.current.as_mut() else {
                    return;
                };
                let cols = s.cols;
                let n = chars.len() / protocol::SCORE_CHARS;
                if col0 as usize + n > cols {
                    return self
                        .problem(format!("score line for row {row} runs past column {cols}"));
                }
                if s.n_scores + n > MAX_IMAGE_POSITIONS || self.kept + n > self.max_kept {
                    return self.problem("more scores than an image can hold; the rest ignored");
                }
                let mut added = 0;
                let line = s.scores.entry(row).or_default();
                let mut dup = false;
                for (k, c) in chars.chunks(protocol::SCORE_CHARS).enumerate() {
                    // In range: `col0 + n <= cols` was checked above.
                    if let Some(v) = protocol::decode_score(c) {
                        let again = line.insert(col0 + k as u32, v).is_some();
                        dup |= again;
                        added += usize::from(!again);
                    }
                }
                s.n_scores += added;
                self.kept += added;
                if dup {
                    self.problem(format!(
                        "scores of row {row} from column {col0} received twice"
                    ));
                }
            }
            Line::End(e) => {
                let Some(mut s) = self.current.take() else {
                    return self.error("end line outside a scan (header lost?)");
                };
                s.end = Some(e);
                let order = s.order;
                self.current = Some(s);
                self.check_defects_arrived(order);
                let Some(mut s) = self.current.take() else {
                    return;
                };
                self.check_complete(&mut s);
                self.scans.push(s);
            }
        }
    }

    /// An `O` line: filed with its scan, its place in the line order and
    /// its fields checked.
    fn object(&mut self, o: Object) {
        let Some(s) = self.current.as_mut() else {
            return self.error("object line outside a scan (header lost?)");
        };
        s.objects_arrived += 1;
        let id = o.id;
        let mut what = Vec::new();
        let order = &mut s.order;
        let ends_here = match order.row {
            None => {
                what.push(format!("object {id} before any row line (out of order)"));
                false
            }
            Some((r, ..)) if o.row1 > r => {
                what.push(format!(
                    "object {id} ends in row {}, after the last row reported ({r}): an object line follows the lines of the row that closes it (out of order)",
                    o.row1
                ));
                false
            }
            Some((r, ..)) => {
                let ends_here = o.row1 == r;
                match order.last_object {
                    Some((prev, true)) if !ends_here => what.push(format!(
                        "object {id}, closed by row {r}, after object {prev}, which only the scan's end closes (out of order)"
                    )),
                    Some((prev, prev_ends)) if prev_ends == ends_here && id <= prev => {
                        what.push(format!(
                            "object lines after row {r} not in increasing id ({id} after {prev})"
                        ))
                    }
                    _ => {}
                }
                ends_here
            }
        };
        order.last_object = Some((id, ends_here));
        if !s.object_ids.insert(id) {
            what.push(format!("object {id} reported twice in the scan"));
        }
        if let Some(bad) = object_fault(&o, s.cols) {
            what.push(format!("object {id}: {bad}"));
        }
        for w in what {
            self.problem(w);
        }
        let Some(s) = self.current.as_mut() else {
            return;
        };
        if s.objects.len() >= MAX_DEFECTS || self.kept >= self.max_kept {
            return self.problem("more object lines than an image can hold; the rest ignored");
        }
        self.kept += 1;
        s.objects.push(o);
    }

    /// After the last line of a row: as many `D` lines as its `R` line listed.
    fn check_defects_arrived(&mut self, order: Order) {
        if let Some((row, listed, arrived)) = order.row
            && arrived < listed
        {
            self.problem(format!(
                "row {row} lists {listed} defect line(s), {arrived} arrived"
            ));
        }
    }

    /// Cross-checks a finished scan: every row has its row line, every
    /// listed defect arrived, every position has a score when scores are on.
    fn check_complete(&self, s: &mut ScanResult) {
        let rows = s.n_rows() as u32;
        // Gaps between the rows received, not every missing row: an end line
        // may claim billions of rows.
        let missing = gaps(s.rows.keys().copied(), rows);
        let count: u64 = missing.iter().map(|&(a, b)| u64::from(b - a) + 1).sum();
        if count > 0 {
            s.add_problem(LineError {
                line: self.line_no,
                what: format!("no row line for {count} row(s): {}", ranges(&missing)),
            });
        }
        let listed: u64 =
            s.rows.values().map(|r| r.defects as u64).sum::<u64>() - s.unlisted_defects;
        if listed != s.defects.len() as u64 {
            s.add_problem(LineError {
                line: self.line_no,
                what: format!(
                    "row lines list {listed} defect line(s), {} arrived",
                    s.defects.len()
                ),
            });
        }
        if let Some(e) = s.end {
            let (claimed, arrived) = (u64::from(e.totals.objects), s.objects_arrived);
            if claimed != arrived {
                s.add_problem(LineError {
                    line: self.line_no,
                    what: format!(
                        "end line counts {claimed} object(s), {arrived} object line(s) arrived"
                    ),
                });
            } else if s.objects.len() as u64 == arrived {
                // Every defective position is in one object or counted in `unobj`.
                let covered: u64 = s.objects.iter().map(|o| u64::from(o.area)).sum();
                let left_out = u64::from(e.totals.unobjected);
                if covered + left_out != u64::from(e.totals.defects) {
                    s.add_problem(LineError {
                        line: self.line_no,
                        what: format!(
                            "objects cover {covered} position(s) and {left_out} were left out of every object, but the end line counts {} defect(s)",
                            e.totals.defects
                        ),
                    });
                }
            }
        }
        let misplaced = s.end.map_or(0, |e| e.totals.misplaced);
        if misplaced > 0 {
            s.add_problem(LineError {
                line: self.line_no,
                what: format!(
                    "{misplaced} map(s) were scored at a wrong position (a short row: beams without DRDY); \
                     scores next to the short row are unreliable"
                ),
            });
        }
        if s.scores_enabled {
            let dropped = s.end.map_or(0, |e| e.dropped);
            let expected = rows as usize * s.cols;
            let (with, without) = s.coverage();
            if with + without < expected {
                s.add_problem(LineError {
                    line: self.line_no,
                    what: format!(
                        "{} of {expected} positions have no score ({dropped} score line(s) reported dropped by the firmware)",
                        expected - with - without
                    ),
                });
            }
        }
    }

    /// Ends the stream: a scan without its end line is kept and reported.
    pub fn finish(&mut self) {
        if let Some(s) = self.current.take() {
            self.error("stream ended before the scan's end line");
            self.scans.push(s);
        }
    }
}

/// What is impossible about an object of a scan of `cols` columns, if
/// anything: a box past the last column, an area of 0 or beyond its box,
/// a peak outside its box or below the threshold, no channel, a centroid
/// outside its box.
fn object_fault(o: &Object, cols: usize) -> Option<String> {
    let (h, w) = (
        u64::from(o.row1 - o.row0) + 1,
        u64::from(o.col1 - o.col0) + 1,
    );
    let inside = |r: u32, c: u32| (o.row0..=o.row1).contains(&r) && (o.col0..=o.col1).contains(&c);
    let box_q8 = |v: u64, a: u32, b: u32| (u64::from(a) << 8..=u64::from(b) << 8).contains(&v);
    if o.col1 as usize >= cols {
        Some(format!(
            "columns {}-{} run past the scan's {cols} columns",
            o.col0, o.col1
        ))
    } else if o.area == 0 || u64::from(o.area) > h * w {
        Some(format!("area {} does not fit its {h}x{w} box", o.area))
    } else if !inside(o.peak_row, o.peak_col) {
        Some(format!(
            "peak at row {} column {} outside its box",
            o.peak_row, o.peak_col
        ))
    } else if o.peak < 1 << 16 {
        Some(format!(
            "peak strength {} below the threshold (65536)",
            o.peak
        ))
    } else if o.channels == 0 {
        Some("no channel fired".to_string())
    } else if !box_q8(o.centroid_row_q8, o.row0, o.row1)
        || !box_q8(o.centroid_col_q8, o.col0, o.col1)
    {
        Some(format!(
            "centroid ({:.2}, {:.2}) outside its box",
            q8(o.centroid_row_q8),
            q8(o.centroid_col_q8)
        ))
    } else {
        None
    }
}

/// The ranges of `0..end` not in `present` (ascending).
fn gaps(present: impl Iterator<Item = u32>, end: u32) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    let mut next = 0;
    for k in present.take_while(|&k| k < end) {
        if k > next {
            out.push((next, k - 1));
        }
        next = k + 1;
    }
    if next < end {
        out.push((next, end - 1));
    }
    out
}

/// `1-3, 7` style list, at most a dozen ranges.
fn ranges(v: &[(u32, u32)]) -> String {
    let mut out: Vec<String> = v
        .iter()
        .take(12)
        .map(|&(a, b)| {
            if a == b {
                a.to_string()
            } else {
                format!("{a}-{b}")
            }
        })
        .collect();
    if v.len() > 12 {
        out.push(format!("and {} more ranges", v.len() - 12));
    }
    out.join(", ")
}

/// What [`next_line`] found.
#[derive(Debug, PartialEq, Eq)]
pub enum NextLine {
    /// A line (with its newline, unless the stream ended without one) in the buffer.
    Line,
    /// A line longer than the limit, of this many bytes, discarded as it came.
    TooLong(usize),
    /// The end of the stream.
    End,
}

/// Reads the next line into `buf`, holding at most `max` bytes of it: a
/// longer line is read to its end and dropped, never buffered. A timeout
/// (an idle serial port) keeps the partial line and waits on.
pub fn next_line(r: &mut impl BufRead, buf: &mut Vec<u8>, max: usize) -> std::io::Result<NextLine> {
    buf.clear();
    let (mut total, mut too_long) = (0usize, false);
    loop {
        let avail = match r.fill_buf() {
            Ok(b) => b,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::Interrupted | std::io::ErrorKind::TimedOut
                ) =>
            {
                continue;
            }
            Err(e) => return Err(e),
        };
        if avail.is_empty() {
            return Ok(match (total, too_long) {
                (0, _) => NextLine::End,
                (_, true) => NextLine::TooLong(total),
                _ => NextLine::Line,
            });
        }
        let (len, done) = match avail.iter().position(|&b| b == b'\n') {
            Some(i) => (i + 1, true),
            None => (avail.len(), false),
        };
        total = total.saturating_add(len);
        if !too_long {
            if buf.len() + len > max {
                too_long = true;
                buf.clear();
            } else {
                buf.extend_from_slice(&avail[..len]);
            }
        }
        r.consume(len);
        if done {
            return Ok(if too_long {
                NextLine::TooLong(total)
            } else {
                NextLine::Line
            });
        }
    }
}

/// Longest line held: the protocol's `MAX_LINE` (newline included), and a
/// carriage return before the newline.
pub const LINE_BUFFER: usize = protocol::MAX_LINE + 1;

/// Decodes every line of `reader`, stopping early after `stop_after` ended
/// scans (0: read to the end), keeping at most `max_scans` scans.
pub fn decode_with(reader: impl Read, stop_after: usize, max_scans: usize) -> Result<Decoder> {
    let mut dec = Decoder::with_max_scans(max_scans);
    let mut r = BufReader::new(reader);
    let mut buf = Vec::with_capacity(LINE_BUFFER);
    loop {
        match next_line(&mut r, &mut buf, LINE_BUFFER).context("reading the result stream")? {
            NextLine::End => break,
            NextLine::Line => dec.feed(&buf),
            NextLine::TooLong(n) => dec.feed_too_long(n),
        }
        if stop_after > 0 && dec.ended() >= stop_after {
            break;
        }
    }
    dec.finish();
    Ok(dec)
}

/// [`decode_with`] with the default cap on scans.
pub fn decode(reader: impl Read, stop_after: usize) -> Result<Decoder> {
    decode_with(reader, stop_after, DEFAULT_MAX_SCANS as usize)
}

fn output_path(base: &Path, k: usize) -> PathBuf {
    if k == 0 {
        return base.to_path_buf();
    }
    let stem = base
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    base.with_file_name(format!("{stem}_{}.npy", k + 1))
}

/// Objects listed per scan in the text summary.
pub const TEXT_OBJECTS: usize = 100;

/// [`summary_text_with`] without a pitch: sizes in positions only.
pub fn summary_text(dec: &Decoder) -> String {
    summary_text_with(dec, None)
}

/// `3x5 positions`, and with a pitch `(1.00 x 1.67 mm)`: height (rows)
/// by width (columns).
fn size_text((h, w): (u64, u64), pitch_um: Option<f64>) -> String {
    match pitch_um {
        Some(p) => format!("{h}x{w} positions ({:.2} x {:.2} mm)", mm(h, p), mm(w, p)),
        None => format!("{h}x{w} positions"),
    }
}

/// `n` positions at a pitch of `pitch_um` µm, in mm.
fn mm(n: u64, pitch_um: f64) -> f64 {
    n as f64 * pitch_um / 1000.0
}

/// A value for the report: four decimals, or four significant digits in
/// exponent form when it is huge or tiny.
fn short(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() || (1e-3..1e6).contains(&a) {
        format!("{v:.4}")
    } else {
        format!("{v:.3e}")
    }
}

/// One object of the text summary.
pub fn object_text(o: &Object, s: &ScanResult, pitch_um: Option<f64>) -> String {
    let size = ObjectSize::of(o);
    format!(
        "object {}: rows {}-{}, cols {}-{}, area {}, extent {}, defect {}; peak {:.2}x threshold at row {} col {} (magnitude {}, power {}); centroid row {:.2} col {:.2}; channels {}",
        o.id,
        o.row0,
        o.row1,
        o.col0,
        o.col1,
        o.area,
        size_text(size.extent, pitch_um),
        size_text(size.size, pitch_um),
        strength_ratio(o.peak),
        o.peak_row,
        o.peak_col,
        short(s.units(o.peak_mag)),
        short(cvm_core::power::to_units(o.peak_power as u32)),
        q8(o.centroid_row_q8),
        q8(o.centroid_col_q8),
        channel_names(o.channels).join("+")
    )
}

/// The human report: per scan its header, defect lines, objects, totals
/// and problems; then the stream's line errors. With `pitch_um`, object
/// sizes in mm too.
pub fn summary_text_with(dec: &Decoder, pitch_um: Option<f64>) -> String {
    use std::fmt::Write;
    let mut o = String::new();
    for (k, s) in dec.scans.iter().enumerate() {
        let (with, without) = s.coverage();
        let _ = writeln!(
            o,
            "scan {}: firmware {}, {}x{} maps, {} rows x {} cols, threshold {}, {}",
            k + 1,
            s.firmware,
            s.geometry.0,
            s.geometry.1,
            s.n_rows(),
            s.cols,
            fmt_num(s.threshold),
            match s.power_threshold {
                Some(t) => format!("power threshold {} (contrast)", short(t)),
                None => "power channel off".to_string(),
            }
        );
        let _ = writeln!(
            o,
            "  protocol v{}, full scale {}, at most {} defect line(s) per row, reset cause {}, start {} since power-on",
            s.version,
            s.full_scale,
            s.max_defect_lines,
            s.reset_cause.map_or("-", |c| c.as_str()),
            s.boots
        );
        let total: u64 = s.rows.values().map(|r| r.defects as u64).sum();
        let _ = writeln!(o, "  defects: {total} ({} listed)", s.defects.len());
        for d in s.defects.iter().take(20) {
            let _ = writeln!(
                o,
                "    row {:4} col {:4} score {:.6} power {:.6} strength {:.2}x threshold, {}",
                d.row,
                d.col,
                d.score,
                d.power,
                strength_ratio(d.strength),
                channel_names(d.flags).join("+")
            );
        }
        if s.defects.len() > 20 {
            let _ = writeln!(o, "    ... {} more", s.defects.len() - 20);
        }
        let _ = writeln!(o, "  objects: {}", s.objects.len());
        for obj in s.objects.iter().take(TEXT_OBJECTS) {
            let _ = writeln!(o, "    {}", object_text(obj, s, pitch_um));
        }
        if s.objects.len() > TEXT_OBJECTS {
            let _ = writeln!(
                o,
                "    ... {} more (all of them in --json)",
                s.objects.len() - TEXT_OBJECTS
            );
        }
        if let Some(e) = s.end
            && e.totals.unobjected > 0
        {
            let _ = writeln!(
                o,
                "    {} defective position(s) are in no object (more than {} objects or runs open at once): an object may be reported in parts",
                e.totals.unobjected,
                cvm_core::objects::MAX_OBJECTS
            );
        }
        if s.scores_enabled {
            let _ = writeln!(
                o,
                "  scores: {with} positions with data, {without} without data"
            );
        }
        match &s.end {
            Some(e) => {
                let _ = writeln!(o, "  totals: {}", totals_text(e));
            }
            None => {
                let _ = writeln!(o, "  totals: none (no end line)");
            }
        }
        for p in s.problems.iter().take(50) {
            let _ = writeln!(o, "  problem at line {}: {}", p.line, p.what);
        }
        if s.problem_count() > 50 {
            let _ = writeln!(o, "  ... {} more problems", s.problem_count() - 50);
        }
    }
    if dec.scans.is_empty() {
        let _ = writeln!(o, "no scan in the stream (no header line decoded)");
    }
    if dec.scans_skipped > 0 {
        let _ = writeln!(
            o,
            "scans skipped (beyond --max-scans): {}",
            dec.scans_skipped
        );
    }
    let _ = writeln!(o, "line errors: {}", dec.error_count());
    for e in dec.errors.iter().take(50) {
        let _ = writeln!(o, "  line {}: {}", e.line, e.what);
    }
    if dec.error_count() > 50 {
        let _ = writeln!(o, "  ... {} more", dec.error_count() - 50);
    }
    o
}

/// `rows 300 frames 90000 ... dropped 0`: the end line's totals in its
/// order (`sat` written out).
fn totals_text(e: &EndInfo) -> String {
    let mut t = e.totals;
    let mut parts: Vec<String> = protocol::END_FIELDS
        .iter()
        .map(|(key, field)| {
            let key = if *key == "sat" { "saturated" } else { key };
            format!("{key} {}", field(&mut t))
        })
        .collect();
    parts.push(format!("{} {}", protocol::DROPPED, e.dropped));
    parts.join(" ")
}

/// The end line's totals as a JSON object, keyed as in the line.
pub fn totals_json(e: &EndInfo) -> serde_json::Value {
    let mut t = e.totals;
    let mut m = serde_json::Map::new();
    for (key, field) in protocol::END_FIELDS {
        m.insert(key.into(), (*field(&mut t)).into());
    }
    m.insert(protocol::DROPPED.into(), e.dropped.into());
    serde_json::Value::Object(m)
}

/// One object in JSON: `peak` and `centroid` as numbers of positions and
/// threshold ratios, sizes in positions, and in mm with `pitch_um`.
pub fn object_json(o: &Object, s: &ScanResult, pitch_um: Option<f64>) -> serde_json::Value {
    let size = ObjectSize::of(o);
    let mut v = serde_json::json!({
        "id": o.id,
        "rows": [o.row0, o.row1],
        "cols": [o.col0, o.col1],
        "area": o.area,
        "extent": [size.extent.0, size.extent.1],
        "size": [size.size.0, size.size.1],
        "peak": strength_ratio(o.peak),
        "peak_at": [o.peak_row, o.peak_col],
        "peak_magnitude": s.units(o.peak_mag),
        "peak_power": cvm_core::power::to_units(o.peak_power as u32),
        "centroid": [q8(o.centroid_row_q8), q8(o.centroid_col_q8)],
        "channels": channel_names(o.channels),
    });
    if let (Some(p), Some(m)) = (pitch_um, v.as_object_mut()) {
        m.insert(
            "extent_mm".into(),
            serde_json::json!([mm(size.extent.0, p), mm(size.extent.1, p)]),
        );
        m.insert(
            "size_mm".into(),
            serde_json::json!([mm(size.size.0, p), mm(size.size.1, p)]),
        );
    }
    v
}

fn problems_json(v: &[LineError]) -> Vec<serde_json::Value> {
    v.iter()
        .map(|p| serde_json::json!({"line": p.line, "what": p.what}))
        .collect()
}

/// One scan in JSON.
pub fn scan_json(s: &ScanResult, pitch_um: Option<f64>) -> serde_json::Value {
    serde_json::json!({
        "header": {
            "version": s.version,
            "firmware": s.firmware,
            "geometry": [s.geometry.0, s.geometry.1],
            "cols": s.cols,
            "kernels": s.kernels.to_string(),
            "kernel_size": s.kernel_size,
            "weights": s.weights,
            "normalise": s.normalise,
            "full_scale": s.full_scale,
            "threshold": s.threshold,
            "power_threshold": s.power_threshold,
            "q": s.q,
            "scores": s.scores_enabled,
            "max_defect_lines": s.max_defect_lines,
            "reset_cause": s.reset_cause.map(|c| c.as_str()),
            "boots": s.boots,
        },
        "rows": s.n_rows(),
        "objects": s.objects.iter().map(|o| object_json(o, s, pitch_um)).collect::<Vec<_>>(),
        "defects": s.defects.iter().map(|d| serde_json::json!({
            "row": d.row,
            "col": d.col,
            "score": d.score,
            "power": d.power,
            "strength": strength_ratio(d.strength),
            "channels": channel_names(d.flags),
            "flags": d.flags,
        })).collect::<Vec<_>>(),
        "totals": s.end.as_ref().map(totals_json),
        "problems": problems_json(&s.problems),
        "problem_count": s.problem_count(),
    })
}

/// The whole stream as one JSON document: `objects` and `totals` of the
/// last (or only) scan (`[]` and `null` without one), `problems` of the
/// whole stream (each scan's, with `"scan"` its number from 1, then the
/// line errors, with `"scan": null`), and `scans`, every scan with its
/// header, objects, defect lines, totals and problems.
pub fn summary_json(dec: &Decoder, pitch_um: Option<f64>) -> serde_json::Value {
    let last = dec.scans.last();
    let mut problems = Vec::new();
    for (k, s) in dec.scans.iter().enumerate() {
        for p in &s.problems {
            problems.push(serde_json::json!({"scan": k + 1, "line": p.line, "what": p.what}));
        }
    }
    for p in &dec.errors {
        problems.push(serde_json::json!({"scan": null, "line": p.line, "what": p.what}));
    }
    let problem_count =
        dec.error_count() + dec.scans.iter().map(|s| s.problem_count()).sum::<usize>();
    serde_json::json!({
        "objects": last.map_or_else(Vec::new, |s| s.objects.iter().map(|o| object_json(o, s, pitch_um)).collect()),
        "totals": last.and_then(|s| s.end.as_ref().map(totals_json)),
        "problems": problems,
        "problem_count": problem_count,
        "damaged": !dec.damage().is_empty(),
        "line_errors": problems_json(&dec.errors),
        "line_error_count": dec.error_count(),
        "scans_skipped": dec.scans_skipped,
        "pitch_um": pitch_um,
        "scans": dec.scans.iter().map(|s| scan_json(s, pitch_um)).collect::<Vec<_>>(),
    })
}

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

pub fn run(args: &ListenArgs) -> Result<()> {
    let max_scans = args.max_scans as usize;
    if args.port.is_some() && args.scans > max_scans {
        bail!(
            "--scans {} is more than --max-scans {max_scans}",
            args.scans
        );
    }
    let outputs: Vec<(&str, &PathBuf)> =
        [("-o", &args.output), ("--power-output", &args.power_output)]
            .into_iter()
            .filter_map(|(name, p)| p.as_ref().map(|p| (name, p)))
            .collect();
    for &(name, out) in &outputs {
        if out.as_os_str() == "-" {
            bail!("{name} -: standard output carries the summary; give the image a file name");
        }
        // Every name this run may write (OUT.npy, OUT_2.npy, ...) against the input.
        if let Some(input) = &args.input {
            for k in 0..max_scans {
                crate::out::refuse_inputs(&output_path(out, k), &[Path::new(input)])?;
            }
        }
    }
    if let (Some(a), Some(b)) = (&args.output, &args.power_output) {
        for k in 0..max_scans {
            for j in 0..max_scans {
                if crate::out::same_destination(&output_path(a, k), &output_path(b, j)) {
                    bail!(
                        "-o and --power-output would both write {}",
                        output_path(a, k).display()
                    );
                }
            }
        }
    }
    let dec = match (&args.input, &args.port) {
        (Some(p), _) if p == "-" => decode_with(std::io::stdin().lock(), 0, max_scans)?,
        (Some(p), _) => {
            let f = std::fs::File::open(p).with_context(|| format!("cannot open {p}"))?;
            decode_with(f, 0, max_scans)?
        }
        (None, Some(dev)) => {
            let port = serialport::new(dev, args.baud)
                .timeout(std::time::Duration::from_secs(3600))
                .open()
                .with_context(|| format!("cannot open serial port {dev} at {} baud", args.baud))?;
            decode_with(port, args.scans, max_scans)?
        }
        (None, None) => bail!("give --input FILE (or -) or --port DEV"),
    };
    let mut failures = Vec::new();
    for (k, s) in dec.scans.iter().enumerate() {
        // The size comes from what the stream claims: refuse an image that
        // what arrived does not justify rather than exhaust memory and disk.
        let refusal = image_refusal(s);
        for &(name, out) in &outputs {
            let path = output_path(out, k);
            match &refusal {
                Some(why) => failures.push(format!(
                    "scan {} {why}; {} not written",
                    k + 1,
                    path.display()
                )),
                None => {
                    let img = if name == "-o" {
                        s.image()
                    } else {
                        s.power_image()
                    };
                    write_gradient(&path, s.n_rows(), s.cols, &img)?
                }
            }
        }
    }
    if dec.scans.is_empty() {
        for &(_, out) in &outputs {
            failures.push(format!(
                "no scan in the stream (no header line decoded); nothing written to {}",
                out.display()
            ));
        }
    }
    let text = if args.json {
        format!("{}\n", summary_json(&dec, args.pitch_um))
    } else {
        summary_text_with(&dec, args.pitch_um)
    };
    crate::out::stdout(text.as_bytes())?;
    let damage = dec.damage();
    if !damage.is_empty() {
        failures.push(format!(
            "the stream was damaged ({}; details in the summary)",
            damage.join(", ")
        ));
    }
    if !failures.is_empty() {
        bail!("{}", failures.join("; "));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all_lines(input: &[u8], max: usize) -> Vec<(NextLine, Vec<u8>)> {
        let mut r = BufReader::with_capacity(7, input);
        let mut buf = Vec::new();
        let mut out = Vec::new();
        loop {
            let next = next_line(&mut r, &mut buf, max).unwrap();
            if next == NextLine::End {
                return out;
            }
            out.push((next, buf.clone()));
        }
    }

    #[test]
    fn the_run_holds_a_bounded_number_of_scores_over_all_scans() {
        let scorer = crate::options::ScoringArgs::default().scorer(3, 3).unwrap();
        let settings = crate::stream::OutputArgs {
            threshold: Some(0.0),
            scores: true,
            max_defect_lines: 20,
            ..Default::default()
        }
        .settings(&scorer, 10)
        .unwrap();
        // Two rows of ten columns: 2 row lines, 20 scores, 20 defects and
        // (every position a defect) one object a scan.
        let frames: Vec<u16> = (0..20 * 9).map(|i| (i * 37 % 1000) as u16).collect();
        let one = crate::stream::stream_scan(&scorer, settings, 2, &frames).unwrap();
        let mut dec = Decoder::new().with_budget(100);
        for line in one.repeat(3).split_inclusive(|&b| b == b'\n') {
            dec.feed(line);
        }
        dec.finish();
        assert_eq!(dec.scans.len(), 3);
        let held: Vec<usize> = dec
            .scans
            .iter()
            .map(|s| s.rows.len() + s.defects.len() + s.n_scores + s.objects.len())
            .collect();
        // 43 each, until the budget of 100 runs out in the third scan.
        assert_eq!(held[..2], [43, 43]);
        assert!(held[2] <= 16, "{held:?}");
        assert!(dec.scans[0].problems.is_empty() && dec.scans[1].problems.is_empty());
        assert!(dec.scans[2].problem_count() > 0);
        assert!(!dec.damage().is_empty());
    }

    #[test]
    fn lines_longer_than_the_limit_are_measured_and_dropped() {
        let input = b"abc\n0123456789abcdef\nxyz\n\nlast";
        assert_eq!(
            all_lines(input, 8),
            vec![
                (NextLine::Line, b"abc\n".to_vec()),
                (NextLine::TooLong(17), Vec::new()),
                (NextLine::Line, b"xyz\n".to_vec()),
                (NextLine::Line, b"\n".to_vec()),
                (NextLine::Line, b"last".to_vec()),
            ]
        );
        // Exactly the limit, newline included, is a line.
        assert_eq!(
            all_lines(b"1234567\n12345678\n", 8),
            vec![
                (NextLine::Line, b"1234567\n".to_vec()),
                (NextLine::TooLong(9), Vec::new()),
            ]
        );
    }

    #[test]
    fn a_line_of_max_line_bytes_is_whole_one_more_is_damage() {
        // A valid frame padded with digits in a field to the exact length.
        let line = |len: usize| {
            let body = "R,0,0,-,0,0,0,0,";
            let mut b = body.to_string();
            while b.len() + 6 < len {
                b.push('0');
            }
            format!("{b}*{:04X}\n", protocol::crc16(b.as_bytes()))
        };
        for (len, damaged) in [(protocol::MAX_LINE, false), (protocol::MAX_LINE + 1, true)] {
            let mut d = Decoder::new();
            let l = line(len);
            assert_eq!(l.len(), len);
            d.feed(l.as_bytes());
            let too_long = d.errors.iter().any(|e| e.what.contains("longer than"));
            assert_eq!(too_long, damaged, "{len}");
        }
    }
}
