//! One part as the console shows it: its header, its defect map filling in
//! row by row, its objects as they close, its verdict, and its lines (for
//! the page's download), each within a bound.

use crate::listen::{ScanResult, object_json, totals_json};
use cvm_core::flags;
use serde_json::{Value, json};

/// Positions a part's map holds (a larger scan is shown without its map).
pub const MAX_PIXELS: usize = 1 << 22;
/// Bytes of a part's lines kept for the download; beyond, the rest is
/// counted, not kept.
pub const MAX_LINES_BYTES: usize = 16 << 20;

/// The verdict the page shows for a part whose lines were damaged: the
/// firmware's own verdict may not be what it sent, so none is shown.
pub const DAMAGED: &str = "damaged";

pub struct Part {
    /// Parts since the console started, from 1.
    pub n: u64,
    /// When its header arrived (ms since the Unix epoch).
    pub started_ms: u64,
    pub header: Value,
    pub header_line: String,
    /// The header's `src=`: each setting's source, in the order of the settings table.
    pub src: String,
    pub rows: usize,
    pub cols: usize,
    /// Magnitude in distance units (NaN: nothing arrived), and the channels that fired.
    pub pixels: Vec<f32>,
    pub fired: Vec<u8>,
    /// Rows of which a line arrived (the map is filled up to here).
    pub rows_seen: usize,
    pub threshold: f64,
    pub objects: Vec<Value>,
    pub totals: Option<Value>,
    /// The end line's verdict, or [`DAMAGED`].
    pub verdict: Option<String>,
    pub problems: Vec<Value>,
    pub lines: Vec<u8>,
    pub lines_dropped: u64,
}

/// A header field of the raw `H` line (`src=...`).
fn field<'a>(line: &'a str, key: &str) -> &'a str {
    let body = line.split('*').next().unwrap_or("");
    body.split(',')
        .find_map(|f| f.strip_prefix(key).and_then(|v| v.strip_prefix('=')))
        .unwrap_or("")
}

pub fn now_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

impl Part {
    pub fn begin(n: u64, s: &ScanResult, header_line: &str, pitch_um: Option<f64>) -> Part {
        let rows = s.header_rows.unwrap_or(1).max(1) as usize;
        let cols = s.cols.max(1);
        let fits = rows.saturating_mul(cols) <= MAX_PIXELS;
        let header = crate::listen::scan_json(s, pitch_um)["header"].clone();
        Part {
            n,
            started_ms: now_ms(),
            header,
            header_line: header_line.trim_end().to_string(),
            src: field(header_line, "src").to_string(),
            rows,
            cols,
            pixels: if fits {
                vec![f32::NAN; rows * cols]
            } else {
                Vec::new()
            },
            fired: if fits {
                vec![0; rows * cols]
            } else {
                Vec::new()
            },
            rows_seen: 0,
            threshold: s.threshold,
            objects: Vec::new(),
            totals: None,
            verdict: None,
            problems: Vec::new(),
            lines: Vec::new(),
            lines_dropped: 0,
        }
    }

    /// Keeps `line` (and a newline) for the download.
    pub fn keep_line(&mut self, line: &[u8]) {
        if self.lines.len() + line.len() < MAX_LINES_BYTES {
            self.lines.extend_from_slice(line);
            self.lines.push(b'\n');
        } else {
            self.lines_dropped += 1;
        }
    }

    fn set(&mut self, row: usize, col: usize, value: f64, fired: u8) {
        if row >= self.rows || col >= self.cols {
            return;
        }
        let at = row * self.cols + col;
        if let (Some(p), Some(f)) = (self.pixels.get_mut(at), self.fired.get_mut(at)) {
            *p = value as f32;
            *f = fired & flags::DEFECT;
        }
    }

    pub fn saw_row(&mut self, row: u32) {
        self.rows_seen = self.rows_seen.max(row as usize + 1).min(self.rows);
    }

    /// Row `row`'s scores from column `col0` on, as the decoder holds them
    /// (a score line's).
    pub fn scores(&mut self, s: &ScanResult, row: u32, col0: u32) {
        self.saw_row(row);
        let Some(line) = s.scores.get(&row) else {
            return;
        };
        let scale = (-(s.q as f64)).exp2();
        for (&c, v) in line.range(col0..) {
            if v.flags & flags::NO_DATA == 0 {
                self.set(row as usize, c as usize, v.mag as f64 * scale, v.flags);
            }
        }
    }

    /// The decoder's last defect line (a scan without score lines shows its defects).
    pub fn defect(&mut self, s: &ScanResult) {
        if let Some(d) = s.defects.last() {
            self.saw_row(d.row);
            if !s.scores_enabled {
                self.set(d.row as usize, d.col as usize, d.score, d.flags);
            }
        }
    }

    pub fn object(&mut self, s: &ScanResult, pitch_um: Option<f64>) {
        if let Some(o) = s.objects.last() {
            self.objects.push(object_json(o, s, pitch_um));
        }
    }

    /// The scan ended (or was cut): its verdict, unless anything about it
    /// was damaged.
    pub fn end(&mut self, s: &ScanResult) {
        self.problems = s
            .problems
            .iter()
            .take(20)
            .map(|p| json!({"line": p.line, "kind": p.kind.name(), "what": p.what}))
            .collect();
        self.totals = s.end.as_ref().map(totals_json);
        self.rows_seen = self.rows;
        let whole = s.end.is_some() && s.problem_count() == 0;
        self.verdict = Some(match (&s.end, whole) {
            (Some(e), true) => e.verdict.as_str().to_string(),
            _ => DAMAGED.to_string(),
        });
    }

    /// The part for the page: what it is, and its map from `from_row` on
    /// (`None`: no map).
    pub fn json(&self, from_row: Option<usize>) -> Value {
        let mut v = json!({
            "n": self.n,
            "started_ms": self.started_ms,
            "rows": self.rows,
            "cols": self.cols,
            "rows_seen": self.rows_seen,
            "threshold": self.threshold,
            "header": self.header,
            "header_line": self.header_line,
            "src": self.src,
            "objects": self.objects,
            "totals": self.totals,
            "verdict": self.verdict,
            "problems": self.problems,
            "has_map": !self.pixels.is_empty(),
        });
        if let (Some(from), false) = (from_row, self.pixels.is_empty()) {
            let from = from.min(self.rows_seen);
            let (a, b) = (from * self.cols, self.rows_seen * self.cols);
            let values: Vec<Value> = self.pixels[a..b]
                .iter()
                .map(|&p| {
                    if p.is_nan() {
                        Value::Null
                    } else {
                        json!((f64::from(p) * 1e4).round() / 1e4)
                    }
                })
                .collect();
            v["map"] = json!({"from": from, "values": values, "fired": &self.fired[a..b]});
        }
        v
    }
}
