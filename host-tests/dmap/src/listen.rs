//! `dmap listen`: decodes the firmware's result lines (from a file, stdin or
//! a serial port), checks every CRC, reports damaged lines by number and
//! keeps going, and rebuilds each scan's score image and summary.

use crate::npy::write_gradient;
use crate::stream::fmt_num;
use anyhow::{Context, Result, bail};
use clap::Args;
use cvm_core::flags;
use cvm_core::protocol::{self, EndInfo, Line, ResetCause};
use std::collections::BTreeMap;
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
    /// Write the score image of docs/method.md §2 (magnitude in [..., 2], NaN where no
    /// score arrived); a second scan goes to OUT_2.npy, and so on
    #[arg(short, long, value_name = "OUT.npy")]
    pub output: Option<PathBuf>,
    /// Decode at most this many scans in one run; later scans are reported, not kept
    #[arg(long, default_value_t = DEFAULT_MAX_SCANS, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..=MAX_SCANS as i64))]
    pub max_scans: u32,
    /// Print the summary as one JSON object per scan instead of text
    #[arg(long)]
    pub json: bool,
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
    pub flags: u8,
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
    pub scores_enabled: bool,
    /// Full scale of the samples (`fs`).
    pub full_scale: u16,
    /// Most defect lines per row (`dcap`).
    pub max_defect_lines: u16,
    /// Why the board last started (`rst`), and its starts since power-on (`boots`).
    pub reset_cause: Option<ResetCause>,
    pub boots: u32,
    /// Magnitudes and flags received, by row then column (integer scores).
    /// Sparse, so that memory follows the lines received, never the
    /// geometry a (possibly corrupted) header claims.
    pub scores: BTreeMap<u32, BTreeMap<u32, (u32, u8)>>,
    /// Row summaries received.
    pub rows: BTreeMap<u32, cvm_core::RowSummary>,
    pub defects: Vec<Defect>,
    /// Defects counted by row lines but not listed (per-row cap).
    pub unlisted_defects: u64,
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
/// its `D` lines strongest first, its `S` lines by column.
#[derive(Clone, Copy, Debug, Default)]
struct Order {
    /// The row of the last `R` line, its `listed` count and the `D` lines
    /// that arrived for it.
    row: Option<(u32, u32, u32)>,
    /// Magnitude and column of the row's last `D` line.
    last_defect: Option<(u32, u32)>,
    /// `col0` of the row's last `S` line.
    last_scores: Option<u32>,
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
        let (rows, cols) = (self.n_rows(), self.cols);
        let mut img = vec![f64::NAN; rows * cols * 3];
        for (&r, line) in &self.scores {
            for (&c, (mag, fl)) in line {
                let c = c as usize;
                if fl & flags::NO_DATA == 0 && (r as usize) < rows && c < cols {
                    img[(r as usize * cols + c) * 3 + 2] = self.units(*mag);
                }
            }
        }
        if !self.scores_enabled {
            // Without score lines, the defects are the only positions known.
            for d in &self.defects {
                let (r, c) = (d.row as usize, d.col as usize);
                if r < rows && c < cols {
                    img[(r * cols + c) * 3 + 2] = d.score;
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
            for (_, fl) in line.values() {
                if fl & flags::NO_DATA == 0 {
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
            // Objects are read by the object report (not yet in this decoder).
            Line::Object(_) => {}
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
                flags,
                ..
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
                    Some((_, listed, arrived)) if arrived >= listed => Some(format!(
                        "row {row} lists {listed} defect line(s); more arrived"
                    )),
                    Some(_) => match order.last_defect {
                        Some((m, c)) if mag > m || (mag == m && col <= c) => Some(format!(
                            "defect lines of row {row} not strongest first (column {col} after column {c})"
                        )),
                        _ => None,
                    },
                };
                if let Some((_, _, arrived)) = order.row.as_mut() {
                    *arrived += 1;
                }
                order.last_defect = Some((mag, col));
                if let Some(what) = what {
                    self.problem(what);
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
                        let again = line.insert(col0 + k as u32, (v.mag, v.flags)).is_some();
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

pub fn summary_text(dec: &Decoder) -> String {
    use std::fmt::Write;
    let mut o = String::new();
    for (k, s) in dec.scans.iter().enumerate() {
        let (with, without) = s.coverage();
        let _ = writeln!(
            o,
            "scan {}: firmware {}, {}x{} maps, {} rows x {} cols, threshold {}",
            k + 1,
            s.firmware,
            s.geometry.0,
            s.geometry.1,
            s.n_rows(),
            s.cols,
            fmt_num(s.threshold)
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
                "    row {:4} col {:4} score {:.6}",
                d.row, d.col, d.score
            );
        }
        if s.defects.len() > 20 {
            let _ = writeln!(o, "    ... {} more", s.defects.len() - 20);
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

/// The end line's key in JSON: `sat` is written out.
fn json_key(key: &str) -> &str {
    match key {
        "sat" => "saturated",
        k => k,
    }
}

/// `rows 300 frames 90000 ... dropped 0`: the end line's totals in its order.
fn totals_text(e: &EndInfo) -> String {
    let mut t = e.totals;
    let mut parts: Vec<String> = protocol::END_FIELDS
        .iter()
        .map(|(key, field)| format!("{} {}", json_key(key), field(&mut t)))
        .collect();
    parts.push(format!("{} {}", protocol::DROPPED, e.dropped));
    parts.join(" ")
}

/// One JSON object per scan (each with the stream's line errors and
/// whether the stream was damaged); a stream without any scan still gets
/// one object, with `"firmware": null`, so that its damage is never silent.
pub fn summary_json(dec: &Decoder) -> Vec<serde_json::Value> {
    let line_errors: Vec<serde_json::Value> = dec
        .errors
        .iter()
        .map(|p| serde_json::json!({"line": p.line, "what": p.what}))
        .collect();
    let damaged = !dec.damage().is_empty();
    if dec.scans.is_empty() {
        return vec![serde_json::json!({
            "firmware": null,
            "problems": [],
            "line_errors": line_errors,
            "line_error_count": dec.error_count(),
            "scans_skipped": dec.scans_skipped,
            "damaged": damaged,
        })];
    }
    dec.scans
        .iter()
        .map(|s| {
            let end = s.end.map(|e| {
                let mut t = e.totals;
                let mut m = serde_json::Map::new();
                for (key, field) in protocol::END_FIELDS {
                    m.insert(json_key(key).into(), (*field(&mut t)).into());
                }
                m.insert(protocol::DROPPED.into(), e.dropped.into());
                serde_json::Value::Object(m)
            });
            serde_json::json!({
                "version": s.version,
                "firmware": s.firmware,
                "full_scale": s.full_scale,
                "max_defect_lines": s.max_defect_lines,
                "reset_cause": s.reset_cause.map(|c| c.as_str()),
                "boots": s.boots,
                "geometry": [s.geometry.0, s.geometry.1],
                "rows": s.n_rows(),
                "cols": s.cols,
                "threshold": s.threshold,
                "defects": s.defects.iter().map(|d| serde_json::json!({"row": d.row, "col": d.col, "score": d.score})).collect::<Vec<_>>(),
                "totals": end,
                "problems": s.problems.iter().map(|p| serde_json::json!({"line": p.line, "what": p.what})).collect::<Vec<_>>(),
                "problem_count": s.problem_count(),
                "line_errors": line_errors,
                "line_error_count": dec.error_count(),
                "scans_skipped": dec.scans_skipped,
                "damaged": damaged,
            })
        })
        .collect()
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
    if let Some(out) = &args.output {
        if out.as_os_str() == "-" {
            bail!("-o -: standard output carries the summary; give the image a file name");
        }
        // Every name this run may write (OUT.npy, OUT_2.npy, ...) against the input.
        if let Some(input) = &args.input {
            for k in 0..max_scans {
                crate::out::refuse_inputs(&output_path(out, k), &[Path::new(input)])?;
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
    if let Some(out) = &args.output {
        if dec.scans.is_empty() {
            failures.push(format!(
                "no scan in the stream (no header line decoded); nothing written to {}",
                out.display()
            ));
        }
        for (k, s) in dec.scans.iter().enumerate() {
            let path = output_path(out, k);
            // The size comes from what the stream claims: refuse an image
            // that what arrived does not justify rather than exhaust
            // memory and disk.
            match image_refusal(s) {
                Some(why) => failures.push(format!(
                    "scan {} {why}; {} not written",
                    k + 1,
                    path.display()
                )),
                None => write_gradient(&path, s.n_rows(), s.cols, &s.image())?,
            }
        }
    }
    let text = if args.json {
        summary_json(&dec)
            .iter()
            .map(|v| format!("{v}\n"))
            .collect::<String>()
    } else {
        summary_text(&dec)
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
            ..Default::default()
        }
        .settings(&scorer, 10)
        .unwrap();
        // Two rows of ten columns: 2 row lines, 20 scores, 20 defects a scan.
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
            .map(|s| s.rows.len() + s.defects.len() + s.n_scores)
            .collect();
        // 42 each, until the budget of 100 runs out in the third scan.
        assert_eq!(held[..2], [42, 42]);
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
