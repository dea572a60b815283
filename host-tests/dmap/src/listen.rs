//! `dmap listen`: decodes the firmware's result lines (from a file, stdin or
//! a serial port), checks every CRC, reports damaged lines by number and
//! keeps going, and rebuilds each scan's score image and summary.

use crate::npy::write_gradient;
use anyhow::{Context, Result, bail};
use clap::Args;
use cvm_core::flags;
use cvm_core::protocol::{self, EndInfo, Line, ParseError};
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
    /// Write the score image of design.md §2 (magnitude in [..., 2], NaN where no
    /// score arrived); a second scan goes to OUT_2.npy, and so on
    #[arg(short, long, value_name = "OUT.npy")]
    pub output: Option<PathBuf>,
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
    pub firmware: String,
    pub geometry: (u8, u8),
    pub cols: usize,
    /// Score format: integer scores are `s / 2^q` distance units.
    pub q: i32,
    pub threshold: f64,
    pub scores_enabled: bool,
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
    /// Problems found while decoding this scan (beyond damaged lines).
    pub problems: Vec<LineError>,
}

impl ScanResult {
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

    /// The image of design.md §2: only the magnitude travels over the link,
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

/// The stream decoder: feed it lines, collect scans and errors.
#[derive(Default)]
pub struct Decoder {
    line_no: usize,
    current: Option<ScanResult>,
    pub scans: Vec<ScanResult>,
    /// Damaged lines and lines outside any scan.
    pub errors: Vec<LineError>,
}

impl Decoder {
    pub fn new() -> Self {
        Self::default()
    }

    /// Scans that have ended (an end line arrived).
    pub fn ended(&self) -> usize {
        self.scans.iter().filter(|s| s.end.is_some()).count()
    }

    fn error(&mut self, what: impl Into<String>) {
        self.errors.push(LineError {
            line: self.line_no,
            what: what.into(),
        });
    }

    fn problem(&mut self, what: impl Into<String>) {
        let e = LineError {
            line: self.line_no,
            what: what.into(),
        };
        match &mut self.current {
            Some(s) => s.problems.push(e),
            None => self.errors.push(e),
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
        if trimmed.len() > protocol::MAX_LINE {
            self.error(format!(
                "line of {} bytes is longer than any valid line",
                trimmed.len()
            ));
            return;
        }
        let line = match protocol::parse(trimmed) {
            Ok(l) => l,
            Err(e) => {
                let what = match e {
                    ParseError::NoChecksum => "no checksum (truncated or garbled line)",
                    ParseError::Checksum => "checksum mismatch (corrupted line)",
                    ParseError::Format => "malformed fields",
                    ParseError::Type => "unknown line type",
                };
                self.error(what);
                return;
            }
        };
        match line {
            Line::Header(h) => {
                if let Some(prev) = self.current.take() {
                    self.errors.push(LineError {
                        line: self.line_no,
                        what: "new scan header before the previous scan's end line".into(),
                    });
                    self.scans.push(prev);
                }
                let mut s = ScanResult {
                    firmware: h.firmware.to_string(),
                    geometry: (h.j1, h.j2),
                    cols: h.cols as usize,
                    q: h.q,
                    scores_enabled: h.scores,
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
                s.unlisted_defects += (summary.defects - listed.min(summary.defects)) as u64;
                s.rows.insert(summary.row, summary);
            }
            Line::Defect {
                row,
                col,
                mag,
                flags,
            } => {
                let Some(s) = self.current.as_mut() else {
                    return self.error("defect line outside a scan (header lost?)");
                };
                let score = s.units(mag);
                s.defects.push(Defect {
                    row,
                    col,
                    score,
                    flags,
                });
            }
            Line::Scores { row, col0, chars } => {
                let Some(s) = self.current.as_mut() else {
                    return self.error("score line outside a scan (header lost?)");
                };
                let cols = s.cols;
                let n = chars.len() / protocol::SCORE_CHARS;
                if col0 as usize + n > cols {
                    return self
                        .problem(format!("score line for row {row} runs past column {cols}"));
                }
                let line = s.scores.entry(row).or_default();
                let mut dup = false;
                for (k, c) in chars.chunks(protocol::SCORE_CHARS).enumerate() {
                    // In range: `col0 + n <= cols` was checked above.
                    if let Some(v) = protocol::decode_score(c) {
                        dup |= line.insert(col0 + k as u32, v).is_some();
                    }
                }
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
                self.check_complete(&mut s);
                self.scans.push(s);
            }
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
            s.problems.push(LineError {
                line: self.line_no,
                what: format!("no row line for {count} row(s): {}", ranges(&missing)),
            });
        }
        let listed: u64 =
            s.rows.values().map(|r| r.defects as u64).sum::<u64>() - s.unlisted_defects;
        if listed != s.defects.len() as u64 {
            s.problems.push(LineError {
                line: self.line_no,
                what: format!(
                    "row lines list {listed} defect line(s), {} arrived",
                    s.defects.len()
                ),
            });
        }
        let misplaced = s.end.map_or(0, |e| e.totals.misplaced);
        if misplaced > 0 {
            s.problems.push(LineError {
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
                s.problems.push(LineError {
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
            self.errors.push(LineError {
                line: self.line_no,
                what: "stream ended before the scan's end line".into(),
            });
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

/// Decodes every line of `reader`, stopping early after `stop_after` ended
/// scans (0: read to the end).
pub fn decode(reader: impl Read, stop_after: usize) -> Result<Decoder> {
    let mut dec = Decoder::new();
    let mut r = BufReader::new(reader);
    let mut buf = Vec::new();
    loop {
        buf.clear();
        let n = match r.read_until(b'\n', &mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e).context("reading the result stream"),
        };
        if n == 0 {
            break;
        }
        dec.feed(&buf);
        if stop_after > 0 && dec.ended() >= stop_after {
            break;
        }
    }
    dec.finish();
    Ok(dec)
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
            "scan {}: firmware {}, {}x{} maps, {} rows x {} cols, threshold {:.6}",
            k + 1,
            s.firmware,
            s.geometry.0,
            s.geometry.1,
            s.n_rows(),
            s.cols,
            s.threshold
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
                let t = &e.totals;
                let _ = writeln!(
                    o,
                    "  totals: rows {} frames {} missing {} dark {} saturated {} defects {} rejected {} extra {} bad {} clipped {} misplaced {} dropped {}",
                    t.rows,
                    t.frames,
                    t.missing,
                    t.dark,
                    t.saturated,
                    t.defects,
                    t.rejected,
                    t.extra,
                    t.bad,
                    t.clipped,
                    t.misplaced,
                    e.dropped
                );
            }
            None => {
                let _ = writeln!(o, "  totals: none (no end line)");
            }
        }
        for p in &s.problems {
            let _ = writeln!(o, "  problem at line {}: {}", p.line, p.what);
        }
    }
    let _ = writeln!(o, "line errors: {}", dec.errors.len());
    for e in dec.errors.iter().take(50) {
        let _ = writeln!(o, "  line {}: {}", e.line, e.what);
    }
    if dec.errors.len() > 50 {
        let _ = writeln!(o, "  ... {} more", dec.errors.len() - 50);
    }
    o
}

pub fn summary_json(dec: &Decoder) -> Vec<serde_json::Value> {
    dec.scans
        .iter()
        .map(|s| {
            let end = s.end.map(|e| {
                let t = e.totals;
                serde_json::json!({"rows": t.rows, "frames": t.frames, "missing": t.missing, "dark": t.dark,
                    "saturated": t.saturated, "defects": t.defects, "rejected": t.rejected, "extra": t.extra,
                    "bad": t.bad, "clipped": t.clipped, "misplaced": t.misplaced, "dropped": e.dropped})
            });
            serde_json::json!({
                "firmware": s.firmware,
                "geometry": [s.geometry.0, s.geometry.1],
                "rows": s.n_rows(),
                "cols": s.cols,
                "threshold": s.threshold,
                "defects": s.defects.iter().map(|d| serde_json::json!({"row": d.row, "col": d.col, "score": d.score})).collect::<Vec<_>>(),
                "totals": end,
                "problems": s.problems.iter().map(|p| serde_json::json!({"line": p.line, "what": p.what})).collect::<Vec<_>>(),
                "line_errors": dec.errors.iter().map(|p| serde_json::json!({"line": p.line, "what": p.what})).collect::<Vec<_>>(),
            })
        })
        .collect()
}

/// Largest score image `dmap listen -o` writes (about 800 MB of f64).
pub const MAX_IMAGE_POSITIONS: usize = 1 << 25;

pub fn run(args: &ListenArgs) -> Result<()> {
    let dec = match (&args.input, &args.port) {
        (Some(p), _) if p == "-" => decode(std::io::stdin().lock(), 0)?,
        (Some(p), _) => {
            let f = std::fs::File::open(p).with_context(|| format!("cannot open {p}"))?;
            decode(f, 0)?
        }
        (None, Some(dev)) => {
            let port = serialport::new(dev, args.baud)
                .timeout(std::time::Duration::from_secs(3600))
                .open()
                .with_context(|| format!("cannot open serial port {dev} at {} baud", args.baud))?;
            decode(port, args.scans)?
        }
        (None, None) => bail!("give --input FILE (or -) or --port DEV"),
    };
    if let Some(out) = &args.output {
        if dec.scans.is_empty() {
            bail!(
                "no scan in the stream (no header line decoded); nothing written to {}",
                out.display()
            );
        }
        for (k, s) in dec.scans.iter().enumerate() {
            // The size comes from what the stream claims: refuse an image
            // no scan of this product can have rather than exhaust memory.
            let positions = s
                .n_rows()
                .checked_mul(s.cols)
                .filter(|&p| p <= MAX_IMAGE_POSITIONS);
            if positions.is_none() {
                bail!(
                    "scan {} claims {} rows x {} columns, more than the {MAX_IMAGE_POSITIONS} positions an image may hold; nothing written",
                    k + 1,
                    s.n_rows(),
                    s.cols
                );
            }
            write_gradient(&output_path(out, k), s.n_rows(), s.cols, &s.image())?;
        }
    }
    if args.json {
        for v in summary_json(&dec) {
            println!("{v}");
        }
    } else {
        print!("{}", summary_text(&dec));
    }
    Ok(())
}
