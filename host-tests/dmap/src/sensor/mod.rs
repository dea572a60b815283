//! `dmap sensor`: a client of the board's command channel (docs/commands.md;
//! docs/dmap.md, "dmap sensor") on its serial port. One action a run: its requests
//! go out one at a time, each with its own id (the first random unless
//! `--id`, then counting up), and each waits for its reply among the result
//! lines the board keeps sending. `words` turns the action into checked
//! requests, `link` reads the replies, `show` prints them, `failure` maps
//! what went wrong to an exit status, and `twin` is the same actions for
//! the chip model (`dmap twin --command`).

mod failure;
mod link;
mod show;
pub mod twin;
mod words;

pub use failure::{
    EXIT_LINK, EXIT_OTHER, EXIT_REFUSED, EXIT_TIMEOUT, EXIT_USAGE, Failure, exit_code,
};
pub use link::{Answer, Link, answer};
pub use show::{Done, source_text};
pub use words::{Action, Ask, WIDEST, key_names, show_value};

use crate::fmt::fmt_num;
use anyhow::Result;
use clap::Args;
use cvm_core::command::{Key, Request};
use std::io::{Read, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// The settings part of `dmap sensor --help`, from the core's table of
/// settings ([`cvm_core::command::SETTINGS`]), so that a new key shows here
/// by itself.
fn settings_help() -> String {
    let mut s = String::from(
        "Settings (KEY; the board refuses a value outside its own range with that range):\n",
    );
    for key in cvm_core::command::Key::ALL {
        s += &format!("  {:<7} {} [{}]\n", key.name(), key.about(), key.unit());
    }
    s
}

const SENSOR_HELP: &str = "\
Examples:
  dmap sensor --port /dev/ttyACM0 status
  dmap sensor --port /dev/ttyACM0 set thr=4194304 scores=1
  dmap sensor --port /dev/ttyACM0 calibrate --scans 5
  dmap sensor --port /dev/ttyACM0 save

Sources: `compiled default` (built into the firmware), `flash` (the settings
record read at start-up, or just saved), `changed, not saved` (set,
defaults or calibrate since start-up; lost at the next restart unless saved).
A change takes effect when the next scan starts (the H line shows the values in
effect and their sources). Result lines arriving
meanwhile are not printed (--pass-through keeps them); a reply line with a
bad checksum or another request's id is reported on stderr and skipped.
";

#[derive(Args, Clone, Debug)]
#[command(subcommand_value_name = "ACTION", subcommand_help_heading = "Actions")]
#[command(after_help = format!("{}\n{SENSOR_HELP}\n{}", settings_help(), failure::EXIT_HELP))]
pub struct SensorArgs {
    /// The sensor's serial port (e.g. /dev/ttyACM0, the NUCLEO's ST-LINK virtual COM port)
    #[arg(long, value_name = "DEV", global = true)]
    pub port: Option<String>,
    /// Serial baud rate (the firmware's: 921600)
    #[arg(long, default_value_t = 921_600, global = true,
          value_parser = clap::value_parser!(u32).range(1..))]
    pub baud: u32,
    /// Wait at most SECS for each reply
    #[arg(long, value_name = "SECS", default_value_t = 2.0, global = true,
          value_parser = words::positive_secs)]
    pub timeout: f64,
    /// Print one JSON document instead of text: {"action", "replies" (each with its "id"),
    /// "result_lines", "skipped_replies", "error"}
    #[arg(long, global = true)]
    pub json: bool,
    /// Copy the lines that are not replies (the result lines arriving meanwhile) to FILE
    /// (begun once the port is open, put in place when the run ends, also on a signal)
    #[arg(long, value_name = "FILE", global = true)]
    pub pass_through: Option<PathBuf>,
    /// Id of the first request, the next ones counting up (default: a random one)
    #[arg(long, value_name = "ID", global = true)]
    pub id: Option<u32>,
    #[command(subcommand)]
    pub action: Action,
}

/// An id unlikely to be the last run's, so that a late reply to that run
/// is not taken for this one's.
fn random_id() -> u32 {
    use std::hash::BuildHasher;
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    std::collections::hash_map::RandomState::new().hash_one((t, std::process::id())) as u32
}

/// Seconds for a message.
fn secs(d: Duration) -> String {
    fmt_num(d.as_secs_f64())
}

/// One run's requests against one link.
pub struct Session<'a, P> {
    pub link: &'a mut Link<P>,
    pub next_id: u32,
    pub timeout: Duration,
    pub done: Vec<Done>,
}

impl<P: Read + Write> Session<'_, P> {
    fn no_reply(&self, words: &str, within: Duration) -> Failure {
        Failure::timeout(format!(
            "{words}: no reply within {} s ({})",
            secs(within),
            self.link.hint
        ))
    }

    /// The first answer to request `id` that `pick` takes, before `deadline`;
    /// other answers to it are reported and skipped.
    fn wait<T>(
        &mut self,
        id: u32,
        words: &str,
        deadline: Instant,
        mut pick: impl FnMut(&Answer) -> Option<T>,
    ) -> Result<Option<T>, Failure> {
        while let Some(a) = self.link.reply(id, words, deadline)? {
            if let Some(t) = pick(&a) {
                return Ok(Some(t));
            }
            self.link.skipped += 1;
            crate::out::warn(&format!("skipped an unexpected reply to {words}: {a:?}"));
        }
        Ok(None)
    }

    /// Sends each request in turn and waits for its replies; stops at the
    /// first that fails. `scan_timeout` is calibrate's wait per scan.
    pub fn perform(&mut self, asks: &[Ask], scan_timeout: Duration) -> Result<(), Failure> {
        for ask in asks {
            let id = self.next_id;
            self.next_id = self.next_id.wrapping_add(1);
            self.link.send(id, ask)?;
            let w = ask.words.as_str();
            let within = match ask.request {
                // Writing may erase a flash sector first.
                Request::Save => self.timeout * 5,
                _ => self.timeout,
            };
            let deadline = Instant::now() + within;
            let late = |s: &Self| s.no_reply(w, within);
            let done = match ask.request {
                Request::Status => {
                    let status = self.wait(id, w, deadline, |a| match a {
                        Answer::Status(s) => Some(s.clone()),
                        _ => None,
                    })?;
                    let status = status.ok_or_else(|| late(self))?;
                    let mut values = Vec::new();
                    for k in Key::ALL {
                        let v = self.wait(id, w, deadline, |a| match *a {
                            Answer::Value { key, value, source } if key == k => {
                                Some((key, value, source))
                            }
                            _ => None,
                        })?;
                        values.push(v.ok_or_else(|| late(self))?);
                    }
                    Done::Status { id, status, values }
                }
                Request::Get(k) | Request::Set(k, _) => {
                    let v = self.wait(id, w, deadline, |a| match *a {
                        Answer::Value { key, value, source } if key == k => Some((value, source)),
                        _ => None,
                    })?;
                    let (value, source) = v.ok_or_else(|| late(self))?;
                    Done::Value {
                        id,
                        key: k,
                        value,
                        source,
                    }
                }
                Request::Calibrate { scans, rate_ppm } => {
                    self.calibrate(id, w, deadline, scan_timeout, (scans, rate_ppm))?
                }
                Request::Save | Request::Defaults | Request::Reset => {
                    let want = match ask.request {
                        Request::Save => Answer::Saved,
                        Request::Defaults => Answer::Defaults,
                        _ => Answer::Resetting,
                    };
                    let got = self.wait(id, w, deadline, |a| (*a == want).then_some(()))?;
                    got.ok_or_else(|| late(self))?;
                    match want {
                        Answer::Saved => Done::Saved { id },
                        Answer::Defaults => Done::Defaults { id },
                        _ => Done::Resetting { id },
                    }
                }
            };
            self.done.push(done);
        }
        Ok(())
    }

    fn calibrate(
        &mut self,
        id: u32,
        w: &str,
        deadline: Instant,
        per_scan: Duration,
        (scans, rate_ppm): (u16, u32),
    ) -> Result<Done, Failure> {
        let n = self.wait(id, w, deadline, |a| match *a {
            Answer::Calibrating(n) => Some(n),
            _ => None,
        })?;
        let n = n.ok_or_else(|| self.no_reply(w, self.timeout))?;
        // A reply that is not for what was asked (a board that read the
        // request otherwise) must not pass for its result.
        if n != scans {
            return Err(Failure::other(format!(
                "{w}: the sensor answered that it calibrates on {n} scans, not the {scans} asked for"
            )));
        }
        let within = per_scan * u32::from(n);
        let _ = writeln!(
            std::io::stderr(),
            "dmap: the sensor calibrates on its next {n} scans (defect-free reference parts); waiting up to {} s for the result",
            secs(within)
        );
        let c = self.wait(id, w, Instant::now() + within, |a| match *a {
            Answer::Calibrated(c) => Some(c),
            _ => None,
        })?;
        let c = c.ok_or_else(|| {
            Failure::timeout(format!(
                "{w}: accepted, but no result within {} s ({n} scans of at most {} s: --scan-timeout; are parts being scanned?)",
                secs(within),
                secs(per_scan)
            ))
        })?;
        if (c.scans, c.rate_ppm) != (scans, rate_ppm) {
            let per_part = |ppm: u32| fmt_num(f64::from(ppm) / 1e6);
            return Err(Failure::other(format!(
                "{w}: the sensor's result is for {} scans at {} false positions per part, not the {scans} at {} asked for",
                c.scans,
                per_part(c.rate_ppm),
                per_part(rate_ppm)
            )));
        }
        Ok(Done::Calibrated { id, c })
    }
}

/// Records which of SIGINT, SIGTERM and SIGHUP arrived first; the link's
/// wait ends on it. A second signal ends `dmap` at once.
fn watch_signals() -> Result<std::sync::Arc<std::sync::atomic::AtomicUsize>> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, AtomicUsize};
    let seen = Arc::new(AtomicBool::new(false));
    let which = Arc::new(AtomicUsize::new(0));
    for sig in [SIGINT, SIGTERM, SIGHUP] {
        signal_hook::flag::register_conditional_default(sig, Arc::clone(&seen))?;
        signal_hook::flag::register(sig, Arc::clone(&seen))?;
        // Only the first signal is kept (a store would overwrite it).
        let which = Arc::clone(&which);
        // SAFETY: the handler only does an atomic compare-exchange.
        unsafe {
            signal_hook::low_level::register(sig, move || {
                let _ = which.compare_exchange(
                    0,
                    sig as usize,
                    std::sync::atomic::Ordering::Relaxed,
                    std::sync::atomic::Ordering::Relaxed,
                );
            })?;
        }
    }
    Ok(which)
}

pub fn run(args: &SensorArgs) -> Result<()> {
    // Every key and value is checked before the port is even opened.
    let asks = args.action.asks()?;
    let scan_timeout = match args.action {
        Action::Calibrate { scan_timeout, .. } => scan_timeout.unwrap_or(60.0),
        _ => 60.0,
    };
    let Some(dev) = &args.port else {
        return Err(Failure::usage(
            "give the sensor's serial port: --port DEV (e.g. /dev/ttyACM0)".into(),
        )
        .into());
    };
    if let Some(p) = &args.pass_through {
        crate::out::refuse_inputs(p, &[std::path::Path::new(dev)])
            .map_err(|e| Failure::usage(e.to_string()))?;
    }
    // The handlers go in before the port opens, so that no signal between
    // the two ends `dmap` without the --pass-through file written.
    let signal = watch_signals().map_err(|e| Failure::other(e.to_string()))?;
    // A short read timeout: the session keeps its own deadlines.
    let port = serialport::new(dev, args.baud)
        .timeout(Duration::from_millis(20))
        .open()
        .map_err(|e| {
            Failure::link(format!(
                "cannot open serial port {dev} at {} baud: {e}",
                args.baud
            ))
        })?;
    // Only once the port is open is the --pass-through file begun (as the
    // output rule writes every file: beside it, renamed into place at the
    // end, whatever the end), so that a port that fails leaves it whole.
    let pass = match &args.pass_through {
        Some(p) => Some(crate::out::OutFile::create(p).map_err(|e| Failure::other(e.to_string()))?),
        None => None,
    };
    // Bytes already waiting are older output: no reply to this run.
    let _ = port.clear(serialport::ClearBuffer::Input);
    let mut link = Link::new(port, dev, args.baud, pass);
    link.signal = signal;
    let mut session = Session {
        link: &mut link,
        next_id: args.id.unwrap_or_else(random_id),
        timeout: Duration::from_secs_f64(args.timeout),
        done: Vec::new(),
    };
    let result = session.perform(&asks, Duration::from_secs_f64(scan_timeout));
    let done = std::mem::take(&mut session.done);
    // The file is put in place even when the session failed or was
    // interrupted: the lines received so far are the board's.
    let finished = link.finish();
    let result = result.and(finished);
    let action = args.action.name();
    let text = if args.json {
        let error = result.as_ref().err().map(|f| f.message.as_str());
        let counts = (link.result_lines, link.skipped);
        format!("{}\n", show::json(action, &done, counts, error))
    } else {
        show::text(&done)
    };
    crate::out::stdout(text.as_bytes())?;
    Ok(result?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{Args, Command};

    #[test]
    fn help_describes_every_key() {
        let help = SensorArgs::augment_args(Command::new("sensor"))
            .render_long_help()
            .to_string();
        for k in Key::ALL {
            let row = format!("\n  {:<8}", k.name());
            assert!(help.contains(&row), "no `{}` row in:\n{help}", k.name());
        }
        assert!(help.contains("3 the sensor refused a request"), "{help}");
    }
}
