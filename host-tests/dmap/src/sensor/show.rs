//! What `dmap sensor` prints of the replies: text for a person (the
//! `status` settings as a table with their sources spelled out), or one
//! JSON document (`--json`).

use super::words::show_value;
use cvm_core::command::Status;
use cvm_core::command::{Calibration, Key, Kind};
use cvm_core::protocol::ResetCause;
use cvm_core::settings::{Source, Store};
use serde_json::{Map, Value, json};

/// A request the sensor carried out, with what it answered.
#[derive(Clone, Debug, PartialEq)]
pub enum Done {
    Status {
        id: u32,
        status: Status<String>,
        values: Vec<(Key, u32, Source)>,
    },
    /// The answer to `get`, and to each `set`.
    Value {
        id: u32,
        key: Key,
        value: u32,
        source: Source,
    },
    Calibrated {
        id: u32,
        c: Calibration,
    },
    Saved {
        id: u32,
    },
    Defaults {
        id: u32,
    },
    Resetting {
        id: u32,
    },
}

/// The target a calibration's thresholds were set for, in words (none
/// for a rule without one, `rate_ppm` 0).
pub fn target(rate_ppm: u32) -> String {
    match rate_ppm {
        0 => String::new(),
        r => format!(
            ", for {} false positions per part and channel",
            f64::from(r) / 1e6
        ),
    }
}

/// A source in words.
pub fn source_text(s: Source) -> &'static str {
    match s {
        Source::Default => "compiled default",
        Source::Flash => "flash",
        Source::Changed => "changed, not saved",
    }
}

fn source_word(s: Source) -> &'static str {
    match s {
        Source::Default => "default",
        Source::Flash => "flash",
        Source::Changed => "changed",
    }
}

fn store_text(s: Store) -> &'static str {
    match s {
        Store::Empty => "none in flash (compiled values in use)",
        Store::Loaded => "read from flash",
        Store::Foreign => {
            "made by another build (settings layout, geometry, kernels or full scale): ignored, compiled values in use"
        }
        Store::Unreadable => "unreadable: compiled values in use",
    }
}

fn cause_text(c: ResetCause) -> &'static str {
    match c {
        ResetCause::PowerOn => "power-on",
        ResetCause::Watchdog => "the watchdog",
        ResetCause::Software => "a software reset",
        ResetCause::Pin => "the reset pin",
        ResetCause::Other => "another cause",
    }
}

fn status_text(s: &Status<String>, values: &[(Key, u32, Source)]) -> String {
    let mut t = format!(
        "firmware {}, command protocol {}, detector {}x{}, capacity {} columns x {} rows\n",
        s.firmware,
        cvm_core::command::VERSION,
        s.j1,
        s.j2,
        s.max_cols,
        s.max_rows
    );
    t += &format!("settings record: {}\n", store_text(s.store));
    t += &format!(
        "started by {} (start {} since power-on)\n",
        cause_text(s.reset_cause),
        s.boots
    );
    let l = &s.last;
    t += &match l.verdict {
        None if l.scans == 0 => "last scan: none since start-up\n".to_string(),
        v => format!(
            "last scan: {} defective positions, {} objects, verdict {} ({} scans since start-up)\n",
            l.defects,
            l.objects,
            v.map_or("none", |v| v.as_str()),
            l.scans
        ),
    };
    t += &format!("{:<8}{:>12}  source\n", "key", "value");
    for &(k, v, src) in values {
        t += &format!(
            "{:<8}{:>12}  {}\n",
            k.name(),
            show_value(k, v),
            source_text(src)
        );
    }
    t
}

/// The text of what was done, one block per request.
pub fn text(done: &[Done]) -> String {
    let mut t = String::new();
    for d in done {
        t += &match d {
            Done::Status { status, values, .. } => status_text(status, values),
            Done::Value {
                key, value, source, ..
            } => format!(
                "{} = {} ({})\n",
                key.name(),
                show_value(*key, *value),
                source_text(*source)
            ),
            Done::Calibrated { c, .. } => format!(
                "calibrated on {} scans ({} positions with data){}\n\
                 thr  = {:>10}  magnitudes: median {}, MAD {}\n\
                 pthr = {:>10}  power magnitudes: median {}, MAD {}\n\
                 sthr = {:>10}  spread magnitudes: median {}, MAD {}\n\
                 all three in effect from the next scan (changed, not saved: save keeps them)\n",
                c.scans,
                c.positions,
                target(c.rate_ppm),
                c.threshold,
                c.median,
                c.mad,
                c.power_threshold,
                c.power_median,
                c.power_mad,
                c.spread_threshold,
                c.spread_median,
                c.spread_mad
            ),
            Done::Saved { .. } => "settings saved to flash\n".to_string(),
            Done::Defaults { .. } => {
                "compiled values in effect from the next scan (not saved)\n".to_string()
            }
            Done::Resetting { .. } => "the sensor restarts\n".to_string(),
        };
    }
    t
}

fn value_json(k: Key, v: u32) -> Value {
    match k.kind() {
        Kind::Choice(_) => json!(show_value(k, v)),
        Kind::Flag | Kind::Number => json!(v),
    }
}

fn setting_json(k: Key, v: u32, src: Source) -> Value {
    json!({"value": value_json(k, v), "source": source_word(src)})
}

fn done_json(d: &Done) -> Value {
    match d {
        Done::Status {
            id,
            status: s,
            values,
        } => {
            let mut settings = Map::new();
            for &(k, v, src) in values {
                settings.insert(k.name().to_string(), setting_json(k, v, src));
            }
            json!({
                "id": id, "reply": "status", "pv": cvm_core::command::VERSION,
                "firmware": s.firmware, "detector": [s.j1, s.j2],
                "capacity": {"cols": s.max_cols, "rows": s.max_rows},
                "store": s.store.word(), "reset_cause": s.reset_cause.as_str(), "boots": s.boots,
                "last": {"scans": s.last.scans, "defects": s.last.defects,
                         "objects": s.last.objects,
                         "verdict": s.last.verdict.map(|v| v.as_str())},
                "settings": settings,
            })
        }
        Done::Value {
            id,
            key,
            value,
            source,
        } => json!({
            "id": id, "reply": "value", "key": key.name(),
            "value": value_json(*key, *value), "source": source_word(*source),
        }),
        Done::Calibrated { id, c } => json!({
            "id": id, "reply": "calibrated", "scans": c.scans, "positions": c.positions,
            "thr": c.threshold, "pthr": c.power_threshold, "med": c.median, "mad": c.mad,
            "pmed": c.power_median, "pmad": c.power_mad,
            "sthr": c.spread_threshold, "smed": c.spread_median, "smad": c.spread_mad,
            "rate_ppm": c.rate_ppm,
        }),
        Done::Saved { id } => json!({"id": id, "reply": "save"}),
        Done::Defaults { id } => json!({"id": id, "reply": "defaults"}),
        Done::Resetting { id } => json!({"id": id, "reply": "reset"}),
    }
}

/// One JSON document: every reply, the lines ignored meanwhile, and the
/// failure that ended the run, if one did.
pub fn json(action: &str, done: &[Done], counts: (u64, u64), error: Option<&str>) -> Value {
    json!({
        "action": action,
        "replies": done.iter().map(done_json).collect::<Vec<_>>(),
        "result_lines": counts.0,
        "skipped_replies": counts.1,
        "error": error,
    })
}
