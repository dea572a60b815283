//! `dmap listen`'s command-line arguments.

use super::decoder::{DEFAULT_MAX_SCANS, MAX_SCANS};
use clap::{ArgGroup, Args};
use std::path::PathBuf;

#[derive(Args, Clone, Debug)]
// One source, and a missing one names both (--input alone was named).
#[command(group(ArgGroup::new("source").args(["input", "port"]).required(true)))]
pub struct ListenArgs {
    /// Read lines from FILE ("-" for standard input)
    #[arg(long, value_name = "FILE")]
    pub input: Option<String>,
    /// Read lines from a serial port (e.g. /dev/ttyACM0, the ST-LINK virtual COM port)
    #[arg(long, value_name = "DEV")]
    pub port: Option<String>,
    /// Serial baud rate
    #[arg(long, default_value_t = 921600, value_parser = clap::value_parser!(u32).range(1..))]
    pub baud: u32,
    /// With --port: stop after this many scans have ended (0 = run until interrupted: Ctrl-C
    /// or SIGTERM ends the stream, the scans complete by then are reported and written, a
    /// scan under way is reported cut; a second Ctrl-C ends dmap at once)
    #[arg(long, default_value_t = 1)]
    pub scans: usize,
    /// Output score image (docs/method.md §2): float64, shape (rows, cols, 3), the
    /// magnitude in [..., 2] (distance units), NaN in [..., 0] and [..., 1] (the components
    /// do not travel) and where no score arrived; a second scan goes to OUT_2.npy, and so on
    #[arg(short, long, value_name = "OUT.npy")]
    pub output: Option<PathBuf>,
    /// Write the power channel's image (docs/method.md §6) in the same shape and layout as
    /// -o, so that dmap render and dmap eval read it alike: the power magnitude (a
    /// contrast, 0 to 1.41) in [..., 2], NaN in [..., 0] and [..., 1] and where no score
    /// arrived; a second scan goes to OUT_2.npy, and so on
    #[arg(long, value_name = "OUT.npy")]
    pub power_output: Option<PathBuf>,
    /// Scan pitch in µm (the same on both axes): object sizes in mm besides positions.
    /// An object's extent is one position wider on each side than its defect (Eq. 1
    /// compares a position's two neighbours); the defect size printed is the extent less
    /// 2 positions per axis, at least 1
    #[arg(long, value_name = "P", value_parser = positive_f64)]
    pub pitch_um: Option<f64>,
    /// Decode at most this many scans in one run; later scans are reported, not kept
    #[arg(long, default_value_t = DEFAULT_MAX_SCANS, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..=MAX_SCANS as i64))]
    pub max_scans: u32,
    /// Print the summary as one JSON document instead of text: {"objects", "totals"} of
    /// the last (or only) scan, "problems" of the whole stream, and "scans" (every scan's
    /// header, objects, defect lines, totals and problems); see docs/dmap.md
    #[arg(long)]
    pub json: bool,
}

/// A finite number above 0 (`--pitch-um`).
fn positive_f64(s: &str) -> Result<f64, String> {
    s.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && *v > 0.0)
        .ok_or_else(|| "expected a finite number above 0".to_string())
}
