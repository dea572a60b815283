//! What the console knows: counters and the history of the last parts
//! (never dropped, whatever a client misses), the part under way and the
//! last one, the sensor's settings and calibration, and the link's health.

use super::part::{DAMAGED, Part, now_ms};
use crate::listen::ScanResult;
use crate::sensor::{Answer, show_value, source_text};
use cvm_core::command::{Capacity, Key, Kind};
use cvm_core::settings::Source;
use serde_json::{Value, json};
use std::collections::{BTreeMap, VecDeque};

/// Parts in the history, line errors listed in the health panel.
pub const HISTORY: usize = 50;
pub const RECENT_ERRORS: usize = 20;

#[derive(Default)]
pub struct Counters {
    pub parts: u64,
    pub rejects: u64,
    pub faults: u64,
    pub damaged: u64,
    pub line_errors: u64,
    pub missing: u64,
    pub lines: u64,
    pub replies: u64,
}

pub struct Calibrating {
    pub id: u32,
    pub scans: u16,
    /// Parts ended when the sensor accepted, and the one under way then
    /// (the calibration takes the scans that start after it).
    pub from_part: u64,
    pub result: Option<Value>,
    pub refused: Option<String>,
}

#[derive(Default)]
pub struct State {
    /// Bumped at every change the page may show.
    pub version: u64,
    pub source: String,
    /// Whether the source takes requests (a recording does not).
    pub requests: bool,
    pub pitch_um: Option<f64>,
    pub counters: Counters,
    pub verdicts: BTreeMap<String, u64>,
    pub history: VecDeque<Value>,
    pub kinds: BTreeMap<&'static str, u64>,
    pub recent_errors: VecDeque<Value>,
    pub current: Option<Part>,
    pub last: Option<Part>,
    pub settings: BTreeMap<usize, (u32, Source)>,
    pub status: Option<Value>,
    pub capacity: Option<Capacity>,
    pub calibration: Option<Calibrating>,
    /// The last request's outcome, for every viewer.
    pub last_request: Option<Value>,
    /// What ended the source, if it ended.
    pub source_end: Option<String>,
    /// Seconds from the first line to the source's end.
    pub decode_seconds: Option<f64>,
    /// A `status` request is due at the next header (at start, after a
    /// reset, a save or `defaults`).
    pub want_status: bool,
}

impl State {
    pub fn line_error(&mut self, kind: &'static str, line: usize, what: &str) {
        self.counters.line_errors += 1;
        *self.kinds.entry(kind).or_default() += 1;
        if self.recent_errors.len() == RECENT_ERRORS {
            self.recent_errors.pop_front();
        }
        self.recent_errors
            .push_back(json!({"line": line, "kind": kind, "what": what, "at_ms": now_ms()}));
    }

    pub fn begin(&mut self, s: &ScanResult, header_line: &str) {
        let n = self.counters.parts + 1;
        self.current = Some(Part::begin(n, s, header_line, self.pitch_um));
    }

    /// A scan ended or was cut: its part's verdict, counted, in the history.
    pub fn end(&mut self, s: &ScanResult) {
        let Some(mut p) = self.current.take() else {
            return;
        };
        p.end(s);
        for e in &s.problems {
            *self.kinds.entry(e.kind.name()).or_default() += 1;
        }
        let c = &mut self.counters;
        c.parts += 1;
        let verdict = p.verdict.clone().unwrap_or_else(|| DAMAGED.into());
        match s.end.as_ref().map(|e| e.verdict) {
            _ if verdict == DAMAGED => c.damaged += 1,
            Some(v) => {
                c.rejects += u64::from(v.rejects());
                c.faults += u64::from(v.is_fault());
            }
            None => {}
        }
        if let Some(e) = &s.end {
            c.missing += u64::from(e.totals.missing);
        }
        *self.verdicts.entry(verdict.clone()).or_default() += 1;
        if self.history.len() == HISTORY {
            self.history.pop_back();
        }
        self.history.push_front(json!({
            "n": p.n, "verdict": verdict, "objects": p.objects.len(),
            "ended_ms": now_ms(), "problems": s.problem_count(),
        }));
        self.last = Some(p);
    }

    /// A reply to request `id`, whoever asked.
    pub fn answer(&mut self, id: Option<u32>, a: &Answer) {
        self.counters.replies += 1;
        match a {
            Answer::Status(s) => {
                self.capacity = Some(Capacity {
                    max_cols: s.max_cols,
                    max_rows: s.max_rows,
                    ..crate::sensor::WIDEST
                });
                self.status = Some(json!({
                    "firmware": s.firmware, "detector": format!("{}x{}", s.j1, s.j2),
                    "capacity": format!("{}x{}", s.max_cols, s.max_rows),
                    "store": s.store.word(), "reset_cause": s.reset_cause.as_str(),
                    "boots": s.boots,
                }));
            }
            Answer::Value { key, value, source } => {
                self.settings.insert(key.index(), (*value, *source));
            }
            Answer::Calibrating(n) => {
                self.calibration = Some(Calibrating {
                    id: id.unwrap_or(0),
                    scans: *n,
                    from_part: self.counters.parts + u64::from(self.current.is_some()),
                    result: None,
                    refused: None,
                });
            }
            Answer::Calibrated(c) => {
                if let Some(cal) = &mut self.calibration {
                    cal.result = Some(json!({
                        "scans": c.scans, "positions": c.positions, "thr": c.threshold,
                        "pthr": c.power_threshold, "sthr": c.spread_threshold,
                        "rate_ppm": c.rate_ppm,
                    }));
                }
            }
            Answer::Saved | Answer::Defaults | Answer::Resetting => self.want_status = true,
            // Never routed as an answer (`sensor::answer` keeps neither).
            Answer::Refused(_) | Answer::OtherKey { .. } => {}
        }
    }

    /// A refusal with this id: a calibration's end without a result.
    pub fn refused(&mut self, id: Option<u32>, why: &str) {
        if let Some(cal) = &mut self.calibration
            && id == Some(cal.id)
            && cal.result.is_none()
        {
            cal.refused = Some(why.to_string());
        }
    }

    fn settings_json(&self) -> Vec<Value> {
        let cap = self.capacity.unwrap_or(crate::sensor::WIDEST);
        let scan_src = self
            .current
            .as_ref()
            .or(self.last.as_ref())
            .map(|p| p.src.clone());
        Key::ALL
            .iter()
            .map(|&k| {
                let (value, source) = match self.settings.get(&k.index()) {
                    Some(&(v, s)) => (
                        Some(show_value(k, v)),
                        Some(json!({"letter": (s.as_char() as char).to_string(), "text": source_text(s)})),
                    ),
                    None => (None, None),
                };
                let range = match k.kind() {
                    // The words the board takes (`ready`: `high` only).
                    Kind::Choice(_) => {
                        let (a, b) = k.range(&cap);
                        json!((a..=b).map(|v| show_value(k, v)).collect::<Vec<_>>())
                    }
                    Kind::Flag => json!(["0", "1"]),
                    Kind::Number => {
                        let (a, b) = k.range(&cap);
                        json!([a.to_string(), b.to_string()])
                    }
                };
                let in_scan = scan_src
                    .as_deref()
                    .and_then(|s| s.get(k.index()..k.index() + 1))
                    .map(str::to_string);
                json!({"key": k.name(), "value": value, "source": source, "range": range,
                       "number": matches!(k.kind(), Kind::Number), "scan_source": in_scan})
            })
            .collect()
    }

    fn calibration_json(&self) -> Value {
        match &self.calibration {
            None => Value::Null,
            Some(c) => json!({
                "id": c.id, "scans": c.scans,
                "done": self.counters.parts.saturating_sub(c.from_part).min(u64::from(c.scans)),
                "result": c.result, "refused": c.refused,
            }),
        }
    }

    /// Everything but the parts' maps: what every event carries in full.
    pub fn summary(&self) -> Value {
        let c = &self.counters;
        let protocol = self
            .current
            .as_ref()
            .or(self.last.as_ref())
            .map(|p| p.header["version"].clone());
        let outputs = self
            .last
            .as_ref()
            .and_then(|p| p.verdict.as_deref())
            .map(|v| {
                let (ready, reject) = match v {
                    "good" => (true, false),
                    "obj" => (true, true),
                    _ => (false, true),
                };
                json!({"ready": ready, "reject": reject, "trusted": v != DAMAGED})
            });
        json!({
            "version": self.version,
            "source": self.source,
            "requests": self.requests,
            "pitch_um": self.pitch_um,
            "counters": {
                "parts": c.parts, "rejects": c.rejects, "faults": c.faults, "damaged": c.damaged,
                "line_errors": c.line_errors, "missing": c.missing, "lines": c.lines,
                "replies": c.replies,
            },
            "verdicts": self.verdicts,
            "history": self.history,
            "outputs": outputs,
            "health": {
                "kinds": self.kinds, "recent": self.recent_errors, "protocol": protocol,
                "header_line": self.current.as_ref().or(self.last.as_ref()).map(|p| p.header_line.clone()),
                "source_end": self.source_end, "decode_seconds": self.decode_seconds,
            },
            "status": self.status,
            "settings": self.settings_json(),
            "calibration": self.calibration_json(),
            "last_request": self.last_request,
        })
    }
}
