//! The actions of `dmap sensor` (and of `dmap twin --command`) in the
//! user's words, turned into the command channel's requests. Every key
//! and value is checked here, before anything is sent, with the codec's
//! own rules (`Key::from_name`, `Key::parse_value`) at the widest capacity
//! a board can report: what passes may still be out of the board's own
//! range, which the board refuses with its range.

use super::failure::Failure;
use clap::Subcommand;
use cvm_core::calibration::rule::DEFAULT_RATE_PPM;
use cvm_core::command::{Capacity, Key, Kind, MAX_CALIBRATION_SCANS, Request};

/// The widest capacity the `status` reply can carry (`cap=` and `dcap`
/// at most 65535) and the widest pulse a value can hold.
pub const WIDEST: Capacity = Capacity {
    max_cols: u16::MAX,
    max_rows: u16::MAX,
    max_dcap: u16::MAX,
    max_pulse_us: u32::MAX,
};

/// What to ask the sensor.
#[derive(Subcommand, Clone, Debug, PartialEq)]
pub enum Action {
    /// Firmware and protocol version, detector and capacity, what became of
    /// the settings record in flash, why and how often the board started,
    /// the last scan, and every setting with its value and source
    Status,
    /// One setting's value and source (KEY: cols rows thr pthr sthr scores
    /// dcap area peak miss misp mode pulse delay ready reject)
    Get {
        #[arg(value_name = "KEY")]
        key: String,
    },
    /// Change settings for the next scan, not saved (save keeps them): one
    /// request per KEY=VALUE, in the order given, stopping at the first
    /// refusal; every KEY=VALUE is checked before the first is sent
    Set {
        #[arg(value_name = "KEY=VALUE", required = true)]
        pairs: Vec<String>,
    },
    /// Calibrate the three thresholds on the next N scans (defect-free
    /// reference parts): waits for the board to accept, then for its result
    /// after the N-th scan; the thresholds are in effect from the next scan,
    /// not saved
    Calibrate {
        /// Scans to calibrate on, 1..=100
        #[arg(long, value_name = "N",
              value_parser = clap::value_parser!(u16).range(1..=MAX_CALIBRATION_SCANS as i64))]
        scans: u16,
        /// Target false positions per part, per channel, that the
        /// thresholds are set for (the tail rule's, as `dmap calibrate
        /// --rate`; default 0.001: one in 1000 parts; a multiple of
        /// 0.000001 in (0, 1])
        #[arg(long, value_name = "RATE")]
        rate: Option<f64>,
        /// Wait at most SECS per scan for the result, after the board
        /// accepted (default 60: N scans of up to a minute each)
        #[arg(long, value_name = "SECS", value_parser = positive_secs)]
        scan_timeout: Option<f64>,
    },
    /// Write the settings in effect to flash (they become source `flash`);
    /// waits up to 5 x --timeout, since writing may erase a flash sector first
    Save,
    /// Back to the compiled values from the next scan (not saved)
    Defaults,
    /// Restart the board (the settings in flash are loaded again)
    Reset,
}

/// A request with the words that asked for it (`set thr=100`), which the
/// messages about it quote.
#[derive(Clone, Debug, PartialEq)]
pub struct Ask {
    pub words: String,
    pub request: Request,
}

/// A number of seconds above 0 (`--timeout`, `--scan-timeout`).
pub fn positive_secs(s: &str) -> Result<f64, String> {
    s.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && *v > 0.0 && *v <= 1e6)
        .ok_or_else(|| "expected a number of seconds above 0 (at most 1e6)".to_string())
}

/// Every key's name, in the order of the `status` reply.
pub fn key_names() -> String {
    Key::ALL.map(|k| k.name()).join(", ")
}

fn key(name: &str) -> Result<Key, Failure> {
    Key::from_name(name.as_bytes()).ok_or_else(|| {
        Failure::usage(format!(
            "unknown setting `{name}` (the settings: {})",
            key_names()
        ))
    })
}

/// What a key takes, for a message: `a number 0..=4294967295`, `part or row`.
pub fn takes(k: Key) -> String {
    match k.kind() {
        Kind::Choice([a, b]) => format!("{a} or {b}"),
        Kind::Flag => "0 or 1".to_string(),
        Kind::Number => {
            let (min, max) = k.range(&WIDEST);
            match k {
                Key::Cols | Key::Rows | Key::DefectCap | Key::Pulse => format!(
                    "a number {min}..={max} at most, within the board's capacity (see status)"
                ),
                _ => format!("a number {min}..={max}"),
            }
        }
    }
}

/// A value as the wire and `status` write it: the word of a choice, else
/// the number.
pub fn show_value(k: Key, v: u32) -> String {
    match k.kind() {
        Kind::Choice(words) => words[usize::from(v != 0)].to_string(),
        Kind::Flag | Kind::Number => v.to_string(),
    }
}

fn set(pair: &str) -> Result<Ask, Failure> {
    let (name, value) = pair.split_once('=').ok_or_else(|| {
        Failure::usage(format!(
            "`{pair}`: expected KEY=VALUE (the settings: {})",
            key_names()
        ))
    })?;
    let k = key(name)?;
    let v = k
        .parse_value(value.as_bytes(), &WIDEST)
        .map_err(|why| Failure::usage(format!("`{pair}`: {why} ({name} takes {})", takes(k))))?;
    Ok(Ask {
        words: format!("set {name}={value}"),
        request: Request::Set(k, v),
    })
}

impl Action {
    /// The action's name, as typed.
    pub fn name(&self) -> &'static str {
        match self {
            Action::Status => "status",
            Action::Get { .. } => "get",
            Action::Set { .. } => "set",
            Action::Calibrate { .. } => "calibrate",
            Action::Save => "save",
            Action::Defaults => "defaults",
            Action::Reset => "reset",
        }
    }

    /// The requests this action sends, in order, every one checked.
    pub fn asks(&self) -> Result<Vec<Ask>, Failure> {
        let one = |words: &str, request| {
            Ok(vec![Ask {
                words: words.to_string(),
                request,
            }])
        };
        match self {
            Action::Status => one("status", Request::Status),
            Action::Get { key: name } => one(&format!("get {name}"), Request::Get(key(name)?)),
            Action::Set { pairs } => pairs.iter().map(|p| set(p)).collect(),
            Action::Calibrate { scans, rate, .. } => {
                let rate_ppm = match rate {
                    None => DEFAULT_RATE_PPM,
                    Some(r) => crate::calibrate::rule::rate_ppm(*r).ok_or_else(|| {
                        Failure::usage(format!(
                            "--rate must be a multiple of 0.000001 in (0, 1] false positions per part, got {}",
                            crate::fmt::fmt_num(*r)
                        ))
                    })?,
                };
                let words = match rate {
                    None => format!("calibrate {scans}"),
                    Some(r) => format!("calibrate {scans} at {} per part", crate::fmt::fmt_num(*r)),
                };
                one(
                    &words,
                    Request::Calibrate {
                        scans: *scans,
                        rate_ppm,
                    },
                )
            }
            Action::Save => one("save", Request::Save),
            Action::Defaults => one("defaults", Request::Defaults),
            Action::Reset => one("reset", Request::Reset),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn asks(a: Action) -> Result<Vec<Request>, String> {
        a.asks()
            .map(|v| v.into_iter().map(|a| a.request).collect())
            .map_err(|f| f.to_string())
    }

    fn set(pairs: &[&str]) -> Action {
        Action::Set {
            pairs: pairs.iter().map(|s| s.to_string()).collect(),
        }
    }

    #[test]
    fn values_are_read_as_the_board_reads_them() {
        assert_eq!(
            asks(set(&["thr=100", "mode=row", "ready=high", "scores=1"])),
            Ok(vec![
                Request::Set(Key::Threshold, 100),
                Request::Set(Key::RejectMode, 1),
                Request::Set(Key::ReadyLevel, 1),
                Request::Set(Key::Scores, 1),
            ])
        );
        // The largest 32-bit value, and leading zeros, as the protocol allows.
        assert_eq!(
            asks(set(&["pthr=4294967295", "cols=0065535"])),
            Ok(vec![
                Request::Set(Key::PowerThreshold, u32::MAX),
                Request::Set(Key::Cols, 65535)
            ])
        );
    }

    #[test]
    fn bad_keys_and_values_are_refused_with_what_fits() {
        let e = asks(set(&["thr=1", "frobs=2"])).unwrap_err();
        assert!(e.contains("unknown setting `frobs`"), "{e}");
        assert!(e.contains(&key_names()), "{e}");
        let e = asks(set(&["thr=4294967296"])).unwrap_err();
        assert!(e.contains("value out of range 0..=4294967295"), "{e}");
        let e = asks(set(&["cols=0"])).unwrap_err();
        assert!(e.contains("value out of range 1..=65535"), "{e}");
        let e = asks(set(&["thr=-1"])).unwrap_err();
        assert!(e.contains("value of the wrong type"), "{e}");
        let e = asks(set(&["mode=both"])).unwrap_err();
        assert!(e.contains("mode takes part or row"), "{e}");
        let e = asks(set(&["scores=2"])).unwrap_err();
        assert!(e.contains("scores takes 0 or 1"), "{e}");
        let e = asks(set(&["thr"])).unwrap_err();
        assert!(e.contains("expected KEY=VALUE"), "{e}");
        let e = asks(Action::Get { key: "THR".into() }).unwrap_err();
        assert!(e.contains("unknown setting `THR`"), "{e}");
    }

    #[test]
    fn every_key_shows_as_it_parses() {
        for k in Key::ALL {
            let (min, max) = k.range(&WIDEST);
            for v in [min, max] {
                let shown = show_value(k, v);
                assert_eq!(
                    k.parse_value(shown.as_bytes(), &WIDEST),
                    Ok(v),
                    "{}={shown}",
                    k.name()
                );
            }
        }
    }
}
