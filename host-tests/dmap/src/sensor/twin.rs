//! `dmap sensor`'s actions for the chip model: `dmap twin --command
//! BEAM:REQUEST` sends REQUEST (in `dmap sensor`'s words: `status`,
//! `set thr=100 scores=1`, `calibrate --scans 5`, ...) from beam BEAM's
//! DRDY on, encoded as `dmap sensor` encodes it. Ids are 1, 2, 3, ... in
//! the order the commands are given, one per request (a `set` of two
//! keys takes two). After the run, the replies found in the firmware's
//! output are summarised, one line per request.

use super::link::printable;
use super::show::source_text;
use super::words::{Action, Ask, show_value};
use anyhow::{Result, anyhow};
use clap::Parser;
use cvm_core::command::{Reply, parse_reply};
use std::collections::BTreeMap;

/// A request in the words of `dmap sensor`'s actions.
#[derive(Parser, Debug)]
#[command(
    name = "REQUEST",
    no_binary_name = true,
    disable_help_subcommand = true
)]
struct Words {
    #[command(subcommand)]
    action: Action,
}

/// What a request is, for messages.
const ACTIONS: &str = "one of: status, get KEY, set KEY=VALUE..., calibrate --scans N [--rate RATE], save, defaults, reset";

/// A request of a `--command`: its beam, its id and its words.
#[derive(Clone, Debug, PartialEq)]
pub struct Planned {
    pub beam: u64,
    pub id: u32,
    pub ask: Ask,
}

/// Reads `--command` values, `BEAM:REQUEST`, into requests with ids from
/// 1 on, checked as `dmap sensor` checks them; every beam below `beams`.
pub fn plan(commands: &[String], beams: u64) -> Result<Vec<Planned>> {
    let mut out = Vec::new();
    let mut id = 1u32;
    for spec in commands {
        let bad = |why: String| anyhow!("--command {spec}: {why}");
        let (beam, request) = spec.split_once(':').ok_or_else(|| {
            bad("expected BEAM:REQUEST, e.g. 0:status or 5:\"set thr=100\"".into())
        })?;
        let beam: u64 = match beam.trim().parse() {
            Ok(b) if b < beams => b,
            _ => {
                return Err(bad(format!(
                    "`{beam}` is not a beam of this scan (0..{beams})"
                )));
            }
        };
        if request.trim().is_empty() {
            return Err(bad(format!("no request after `{beam}:` ({ACTIONS})")));
        }
        for ask in asks_of(request).map_err(bad)? {
            out.push(Planned { beam, id, ask });
            id += 1;
        }
    }
    Ok(out)
}

/// The requests that `request`, in the words of `dmap sensor`'s actions
/// (`set thr=100`, `calibrate --scans 2`), stands for, each checked as
/// `dmap sensor` checks it; the error is one line (`dmap twin --command`,
/// `dmap console`).
pub fn asks_of(request: &str) -> Result<Vec<Ask>, String> {
    if request.trim().is_empty() {
        return Err(format!("no request ({ACTIONS})"));
    }
    let words = Words::try_parse_from(request.split_whitespace()).map_err(|e| {
        use clap::error::ErrorKind;
        match e.kind() {
            // Help is no answer to a request: say what a request is.
            ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
                format!("`{}` is not a request ({ACTIONS})", request.trim())
            }
            // The message up to the usage, on one line: it names what
            // is missing or wrong ("... not provided: <KEY=VALUE>...").
            _ => {
                let text = e.to_string();
                let said: Vec<&str> = text
                    .lines()
                    .take_while(|l| !l.trim().is_empty() && !l.starts_with("Usage"))
                    .map(str::trim)
                    .collect();
                said.join(" ").trim_start_matches("error: ").to_string()
            }
        }
    })?;
    if let Action::Calibrate {
        scan_timeout: Some(_),
        ..
    } = words.action
    {
        return Err(
            "--scan-timeout is for dmap sensor (the model runs to the scan's end)".to_string(),
        );
    }
    words.action.asks().map_err(|f| f.message)
}

/// The bytes to send at each beam: the requests of a beam back to back,
/// in the order given.
pub fn bursts(planned: &[Planned]) -> Vec<(u64, Vec<u8>)> {
    let mut at: BTreeMap<u64, Vec<u8>> = BTreeMap::new();
    for p in planned {
        let mut sink = Collect(Vec::new());
        cvm_core::command::encode_request(p.id, &p.ask.request, &mut sink);
        at.entry(p.beam).or_default().extend_from_slice(&sink.0);
    }
    at.into_iter().collect()
}

struct Collect(Vec<u8>);

impl cvm_core::protocol::LineSink for Collect {
    fn line(&mut self, line: &[u8], _: cvm_core::protocol::Priority) {
        self.0.extend_from_slice(line);
    }
}

/// What one reply says, in words; a `status` reply's values (`compact`)
/// as `key=value:source`.
fn said(r: &Reply<'_>, compact: bool) -> String {
    match r {
        Reply::Status(s) => format!(
            "status: firmware {}, detector {}x{}, capacity {}x{}, store {}, start {} ({}), last {}/{}/{}/{}; settings:",
            s.firmware,
            s.j1,
            s.j2,
            s.max_cols,
            s.max_rows,
            s.store.word(),
            s.boots,
            s.reset_cause.as_str(),
            s.last.scans,
            s.last.defects,
            s.last.objects,
            s.last.verdict.map_or("none", |v| v.as_str())
        ),
        Reply::Value { key, value, source } if compact => format!(
            "{}={}:{}",
            key.name(),
            show_value(*key, *value),
            char::from(source.as_char())
        ),
        Reply::Value { key, value, source } => format!(
            "{}={} ({})",
            key.name(),
            show_value(*key, *value),
            source_text(*source)
        ),
        Reply::Calibrating(n) => format!("calibrating on the next {n} scans"),
        Reply::Calibrated(c) => format!(
            "calibrated on {} scans ({} positions){}: thr={} (median {}, MAD {}), pthr={} (median {}, MAD {}), sthr={} (median {}, MAD {})",
            c.scans,
            c.positions,
            super::show::target(c.rate_ppm),
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
        Reply::Saved => "saved".into(),
        Reply::Defaults => "compiled values from the next scan".into(),
        Reply::Resetting => "restarting".into(),
        Reply::OtherKey { key, value, .. } => format!(
            "{}={} (a setting this dmap does not know)",
            String::from_utf8_lossy(key),
            String::from_utf8_lossy(value)
        ),
        Reply::Refused(why) => format!("refused: {why}"),
    }
}

/// One line per request of `planned` with what its replies in `uart`
/// said (`no reply` when none came), then one per reply line that answers
/// none of them (another id, `-`, or damaged).
pub fn summary(planned: &[Planned], uart: &[u8]) -> Vec<String> {
    // Per id: whether a status reply came (its values follow), and the words.
    let mut by_id: BTreeMap<u32, (bool, Vec<String>)> = BTreeMap::new();
    let mut others = Vec::new();
    for line in uart.split_inclusive(|&b| b == b'\n') {
        if !line.starts_with(b"A,") {
            continue;
        }
        match parse_reply(line) {
            Ok((Some(id), r)) if planned.iter().any(|p| p.id == id) => {
                let (status, words) = by_id.entry(id).or_default();
                words.push(said(&r, *status));
                *status |= matches!(r, Reply::Status(_));
            }
            Ok((id, r)) => others.push(format!(
                "reply {}: {}",
                id.map_or("-".to_string(), |i| i.to_string()),
                said(&r, false)
            )),
            Err(e) => others.push(format!("damaged reply line ({e}): {}", printable(line))),
        }
    }
    let mut out: Vec<String> = planned
        .iter()
        .map(|p| {
            let replies = by_id
                .get(&p.id)
                .map_or("no reply".to_string(), |(_, r)| r.join(" "));
            format!("request {} ({}:{}): {replies}", p.id, p.beam, p.ask.words)
        })
        .collect();
    out.extend(others);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use cvm_core::command::{Key, Request};

    fn specs(s: &[&str]) -> Vec<String> {
        s.iter().map(|x| x.to_string()).collect()
    }

    #[test]
    fn commands_get_ids_in_order_and_the_sensors_checks() {
        let p = plan(
            &specs(&[
                "0:status",
                "5:set thr=100 mode=row",
                "5:calibrate --scans 3 --rate 0.0001",
            ]),
            10,
        )
        .unwrap();
        let got: Vec<(u64, u32, Request)> =
            p.iter().map(|p| (p.beam, p.id, p.ask.request)).collect();
        assert_eq!(
            got,
            [
                (0, 1, Request::Status),
                (5, 2, Request::Set(Key::Threshold, 100)),
                (5, 3, Request::Set(Key::RejectMode, 1)),
                (
                    5,
                    4,
                    Request::Calibrate {
                        scans: 3,
                        rate_ppm: 100
                    }
                ),
            ]
        );
        // Beam 5's three requests in one burst, in the order given.
        let b = bursts(&p);
        assert_eq!(b.len(), 2);
        assert_eq!(b[0].0, 0);
        let text = String::from_utf8(b[1].1.clone()).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3);
        assert!(lines[0].starts_with("C,2,set,thr=100*"), "{text}");
        assert!(lines[1].starts_with("C,3,set,mode=row*"), "{text}");
        assert!(lines[2].starts_with("C,4,calibrate,3,100*"), "{text}");

        for (bad, why) in [
            ("10:status", "not a beam of this scan (0..10)"),
            ("status", "expected BEAM:REQUEST"),
            ("0:set thr=x", "value of the wrong type"),
            ("0:get nope", "unknown setting `nope`"),
            ("0:frobnicate", "frobnicate"),
            ("0:calibrate --scans 101", "101"),
            ("0:calibrate --scans 2 --scan-timeout 5", "--scan-timeout"),
            ("0:calibrate --scans 2 --rate 3", "--rate must be"),
        ] {
            let e = plan(&specs(&[bad]), 10).unwrap_err().to_string();
            assert!(
                e.contains(why) && e.starts_with(&format!("--command {bad}")),
                "{bad}: {e}"
            );
        }
    }
}
