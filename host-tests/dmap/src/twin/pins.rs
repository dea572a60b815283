//! `dmap twin --pins FILE`: the timeline of the H743's READY and REJECT
//! outputs (and the LEDs that mirror them) as the chip model recorded it,
//! and the summary of every scan's verdict beside the pins' edges.

use anyhow::Result;
use clap::Args;
use std::io::Write;
use std::path::PathBuf;

#[derive(Args, Clone, Debug)]
pub struct PinArgs {
    /// Write the output pins' timeline to FILE (CSV:
    /// us,pin,level,beam,row,read_end_us,read_beam; level 0, 1 or z
    /// (Hi-Z: not configured as an output); each edge with its
    /// model time in µs, the last beam whose DRDY came before it, and the
    /// end of the last frame read before it and its beam; -1 before the
    /// first)
    #[arg(long = "pins", value_name = "FILE")]
    pub pins: Option<PathBuf>,
    // The settings `mode`, `pulse` and `delay` by their former names, kept
    // hidden so that no script breaks: `--set mode=row --set pulse=US
    // --set delay=ROWS` is the one spelling.
    #[arg(long, value_name = "MODE", value_parser = ["part", "row"], hide = true)]
    pub reject: Option<String>,
    #[arg(long, value_name = "US", hide = true)]
    pub pulse_us: Option<u32>,
    #[arg(long, value_name = "ROWS", hide = true)]
    pub row_delay: Option<u32>,
}

impl PinArgs {
    /// Puts the outputs' options that were given into `s` (after `--set`),
    /// checked as the H743 board checks them: a pulse fits TIM14's 16 bits
    /// of µs, and row mode needs a pulse.
    pub fn apply(&self, s: &mut cvm_core::Settings) -> Result<()> {
        use cvm_core::settings::RejectMode;
        if let Some(mode) = &self.reject {
            s.outputs.reject_mode = if mode == "row" {
                RejectMode::Row
            } else {
                RejectMode::Part
            };
        }
        if let Some(us) = self.pulse_us {
            s.outputs.pulse_us = us;
        }
        if let Some(rows) = self.row_delay {
            s.outputs.row_delay = rows;
        }
        if s.outputs.pulse_us > 65_536 {
            anyhow::bail!("pulse: at most 65536 µs (TIM14 counts 16 bits of µs)");
        }
        if cvm_core::command::conflict(s) {
            anyhow::bail!("mode=row needs a pulse width: --set pulse=US");
        }
        Ok(())
    }
}

/// The `CVM_H743_SCAN` keys of the verdict's and the outputs' settings in
/// `s` that differ from their defaults (none for the defaults, so that the
/// default build stays the one cached), by their names on the wire.
pub fn build_keys(s: &cvm_core::Settings) -> String {
    use cvm_core::command::{Key, Kind};
    let mut default = *s;
    default.outputs = cvm_core::Outputs::DEFAULT;
    let mut keys = String::new();
    for key in Key::ALL {
        let v = key.get(s);
        if v != key.get(&default) {
            let value = match key.kind() {
                Kind::Choice(words) => words[(v != 0) as usize].to_string(),
                _ => v.to_string(),
            };
            keys += &format!(" {}={value}", key.name());
        }
    }
    keys
}

/// A pin's level as the chip model records it: driven low, driven high,
/// or Hi-Z (`"z"` in the counters: analog or input mode, every pin's state
/// from a reset until the firmware makes it an output; what a PLC input
/// then reads is its own pull).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    Low,
    High,
    HiZ,
}

impl Level {
    /// From the counters' `level`: 0, 1 or "z".
    pub fn from_json(v: &serde_json::Value) -> Option<Level> {
        match (v.as_u64(), v.as_str()) {
            (Some(0), _) => Some(Level::Low),
            (Some(1), _) => Some(Level::High),
            (_, Some("z")) => Some(Level::HiZ),
            _ => None,
        }
    }

    /// As the timeline file writes it: 0, 1 or z.
    pub fn as_str(self) -> &'static str {
        match self {
            Level::Low => "0",
            Level::High => "1",
            Level::HiZ => "z",
        }
    }
}

/// One recorded change of an output pin.
#[derive(Clone, Debug, PartialEq)]
pub struct Edge {
    pub us: f64,
    pub pin: String,
    pub level: Level,
    pub beam: i64,
    pub row: i64,
    /// When the last frame read before the edge ended (its last sample
    /// clocked), in µs, and its beam (-1 before the first).
    pub read_end_us: f64,
    pub read_beam: i64,
}

impl Edge {
    /// From the end of the last frame read to the edge: the firmware's
    /// own latency (the read itself takes a frame time, which at the
    /// SPI limit is the whole beam period).
    pub fn after_read_us(&self) -> Option<f64> {
        (self.read_beam >= 0).then_some(self.us - self.read_end_us)
    }
}

/// The edges of the model's counters (`pins`).
pub fn edges(counters: &serde_json::Value) -> Vec<Edge> {
    counters["pins"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|e| {
                    Some(Edge {
                        us: e["us"].as_f64()?,
                        pin: e["pin"].as_str()?.to_string(),
                        level: Level::from_json(&e["level"])?,
                        beam: e["beam"].as_i64()?,
                        row: e["row"].as_i64()?,
                        read_end_us: e["read_end_us"].as_f64()?,
                        read_beam: e["read_beam"].as_i64()?,
                    })
                })
                .collect()
        })
        .unwrap_or_default()
}

/// The timeline as the file holds it.
pub fn timeline_csv(edges: &[Edge]) -> String {
    let mut s = String::from("us,pin,level,beam,row,read_end_us,read_beam\n");
    for e in edges {
        s += &format!(
            "{:.3},{},{},{},{},{:.3},{}\n",
            e.us,
            e.pin,
            e.level.as_str(),
            e.beam,
            e.row,
            e.read_end_us,
            e.read_beam
        );
    }
    s
}

/// The verdict of every end line in the firmware's output, in order.
pub fn verdicts(uart: &[u8]) -> Vec<String> {
    String::from_utf8_lossy(uart)
        .lines()
        .filter(|l| l.starts_with("E,"))
        .filter_map(|l| {
            let body = l.rsplit_once('*').map_or(l, |(b, _)| b);
            body.rsplit(',')
                .find_map(|f| f.strip_prefix("verdict="))
                .map(str::to_string)
        })
        .collect()
}

/// Writes the timeline (with `--pins`) and prints the summary on
/// standard error: each scan's verdict, then each edge of READY and REJECT.
pub fn report(args: &PinArgs, counters: &serde_json::Value, uart: &[u8]) -> Result<()> {
    let edges = edges(counters);
    if let Some(path) = &args.pins {
        // The output rule (checked against the inputs before the run).
        let csv = timeline_csv(&edges);
        crate::out::write_file(path, |w| Ok(w.write_all(csv.as_bytes())?))?;
    }
    let mut err = std::io::stderr();
    for (k, v) in verdicts(uart).iter().enumerate() {
        let _ = writeln!(err, "scan {}: verdict {v}", k + 1);
    }
    for e in edges
        .iter()
        .filter(|e| e.pin == "READY" || e.pin == "REJECT")
    {
        let read = e
            .after_read_us()
            .map(|d| format!(", {d:.1} us after beam {}'s read", e.read_beam))
            .unwrap_or_default();
        // What a PLC input that reads low when undriven makes of it:
        // READY active high, REJECT active low (docs/firmware.md).
        let reads_high = e.level == Level::High;
        let meaning = match (e.pin.as_str(), reads_high) {
            ("READY", true) => "ready",
            ("READY", false) => "not ready",
            (_, true) => "pass",
            (_, false) => "reject",
        };
        let _ = writeln!(
            err,
            "pin {} {} ({meaning}) at {:.3} us after beam {} (row {}){read}",
            e.pin,
            match e.level {
                Level::High => "high",
                Level::Low => "low",
                Level::HiZ => "Hi-Z",
            },
            e.us,
            e.beam,
            e.row
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Options {
        #[command(flatten)]
        pins: PinArgs,
    }

    fn applied(args: &[&str]) -> Result<cvm_core::Settings> {
        let o = Options::try_parse_from([&["twin"][..], args].concat())?;
        let mut s = cvm_core::Settings::new(12, 6, 0, 0);
        o.pins.apply(&mut s)?;
        Ok(s)
    }

    /// The former spellings still reach the settings, as the keys `mode`,
    /// `pulse` and `delay` set them, and are refused as the board refuses.
    #[test]
    fn former_output_options_are_the_settings_mode_pulse_and_delay() {
        use cvm_core::command::Key;
        let s = applied(&["--reject", "row", "--pulse-us", "500", "--row-delay", "2"]).unwrap();
        let mut want = cvm_core::Settings::new(12, 6, 0, 0);
        for (key, v) in [(Key::Pulse, 500), (Key::RejectMode, 1), (Key::RowDelay, 2)] {
            assert!(key.set(&mut want, v));
        }
        assert_eq!(s.outputs, want.outputs);
        assert_eq!(applied(&[]).unwrap().outputs, cvm_core::Outputs::DEFAULT);
        let e = applied(&["--reject", "row"]).unwrap_err().to_string();
        assert!(e.contains("needs a pulse width"), "{e}");
        let e = applied(&["--pulse-us", "65537"]).unwrap_err().to_string();
        assert!(e.contains("at most 65536"), "{e}");
        assert!(applied(&["--pulse-us", "65536"]).is_ok());
    }

    #[test]
    fn hi_z_is_a_level_of_its_own() {
        let edge = |us: f64, level: serde_json::Value| {
            serde_json::json!({"us": us, "pin": "READY", "level": level, "beam": -1,
                               "row": -1, "read_end_us": -1, "read_beam": -1})
        };
        let c = serde_json::json!({"pins": [edge(0.0, "z".into()), edge(535.4, 1.into()),
                                            edge(900.0, 0.into()), edge(901.0, "x".into())]});
        let e = edges(&c);
        let levels: Vec<Level> = e.iter().map(|e| e.level).collect();
        assert_eq!(
            levels,
            [Level::HiZ, Level::High, Level::Low],
            "an unknown level is skipped"
        );
        let csv = timeline_csv(&e);
        assert!(csv.contains("\n0.000,READY,z,-1,"), "{csv}");
        assert!(csv.contains("\n535.400,READY,1,-1,"), "{csv}");
    }
}
