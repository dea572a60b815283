//! `dmap console`'s command-line arguments.

use clap::{ArgGroup, Args};
use std::net::SocketAddr;
use std::path::PathBuf;

/// How fast a recorded stream is replayed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Rate {
    /// As it came over the link: 10 bit times a byte at `--baud`.
    Link,
    /// As fast as it decodes.
    Full,
    /// This many lines a second.
    Lines(f64),
}

fn rate(s: &str) -> Result<Rate, String> {
    match s {
        "link" => Ok(Rate::Link),
        "full" => Ok(Rate::Full),
        _ => s
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v > 0.0)
            .map(Rate::Lines)
            .ok_or_else(|| "expected `link`, `full` or a number of lines a second above 0".into()),
    }
}

#[derive(Args, Clone, Debug)]
#[command(group(ArgGroup::new("source").args(["port", "twin", "emulate", "input"]).required(true)))]
pub struct ConsoleArgs {
    /// The sensor's serial port (e.g. /dev/ttyACM0): its result lines are decoded while the
    /// page's requests go out on the same link
    #[arg(long, value_name = "DEV")]
    pub port: Option<String>,
    /// Serial baud rate (the firmware's: 921600); with --input --pace link, the recorded rate
    #[arg(long, default_value_t = 921_600, value_parser = clap::value_parser!(u32).range(1..))]
    pub baud: u32,
    /// Run the H743 release firmware on the chip model over these scans, one part each, again
    /// and again (the scans must have one shape); the page's requests reach it live
    #[arg(long, value_name = "SCAN.npy", num_args = 1..)]
    pub twin: Vec<PathBuf>,
    /// Run the emulated board (QEMU mps2-an386) over these scans, one part each, again and
    /// again; it has no command channel, so it takes no requests
    #[arg(long, value_name = "SCAN.npy", num_args = 1..)]
    pub emulate: Vec<PathBuf>,
    /// Replay a recorded stream of result lines (`dmap listen`'s input); it takes no requests
    #[arg(long, value_name = "FILE")]
    pub input: Option<PathBuf>,
    /// --input's pace: `link` (as recorded: 10 bit times a byte at --baud), `full` (as fast
    /// as it decodes) or N lines a second
    #[arg(long = "pace", alias = "rate", value_name = "PACE", default_value = "link", value_parser = rate)]
    pub rate: Rate,
    /// Where to serve the page. Another address than the loopback serves the line's network:
    /// then changes of settings need the token (--token)
    #[arg(long, value_name = "ADDR:PORT", default_value = "127.0.0.1:8048")]
    pub listen: SocketAddr,
    /// The token that changes of settings need (`auto`: a fresh one, printed at start);
    /// required with a --listen address other than the loopback
    #[arg(long, value_name = "TOKEN")]
    pub token: Option<String>,
    /// Scan pitch in µm (the same on both axes): the map's axes and the objects' sizes in mm
    #[arg(long, value_name = "P", value_parser = positive)]
    pub pitch_um: Option<f64>,
    /// --twin: parts the chip model scans in one run before it is started again (its flash
    /// kept: settings that were saved stay, changed ones are lost as at a power cycle)
    #[arg(long, value_name = "K", default_value_t = 100,
          value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub parts: u32,
    /// --twin: more options of `dmap twin` (e.g. --twin-option=--beam-us=300), repeatable
    #[arg(
        long = "twin-option",
        value_name = "OPTION",
        allow_hyphen_values = true
    )]
    pub twin_options: Vec<String>,
    /// --twin: bank 2 of the chip's flash, kept between runs (as `dmap twin --flash`;
    /// default: a temporary file)
    #[arg(long, value_name = "FILE")]
    pub flash: Option<PathBuf>,
}

fn positive(s: &str) -> Result<f64, String> {
    s.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && *v > 0.0)
        .ok_or_else(|| "expected a finite number above 0".into())
}
