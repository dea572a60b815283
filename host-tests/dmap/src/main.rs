//! `dmap`: the host toolkit. Each subcommand is one variant of [`Command`]
//! and one module of the library; this file only parses and dispatches.

use clap::{Parser, Subcommand};
use std::io::Write;

#[derive(Parser)]
#[command(
    name = "dmap",
    version,
    about = "Deflection-map defect scoring toolkit"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

// Parsed once per run: the size of the largest variant does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
enum Command {
    /// Gradient image (Eq. 1) of a scan under a distance: cvm, cvm-fixed, emd, mean-dir
    Score(dmap::score::ScoreArgs),
    /// Simulate a scan (ray model of the scanner) and its ground-truth defect mask
    Simulate(dmap::simulate::SimulateArgs),
    /// Pseudo-colour PNG of gradient images with colour bars, side by side
    Render(dmap::render::RenderArgs),
    /// SNR, PSNR, CNR and defect sizes of a gradient image against a truth mask
    Eval(dmap::eval::EvalArgs),
    /// Defect threshold from defect-free reference scans, in the firmware's arithmetic (--calibration of stream, emulate, twin)
    Calibrate(dmap::calibrate::CalibrateArgs),
    /// Run the firmware's pipeline on the host and print its result lines
    Stream(dmap::stream::StreamArgs),
    /// Decode result lines (file, stdin or serial port) into a score image and a summary
    Listen(dmap::listen::ListenArgs),
    /// Run the firmware (emulated board, QEMU mps2-an386) over a scan and print its UART output
    Emulate(dmap::emulate::EmulateArgs),
    /// Run the H743 release firmware on the chip model (STM32H743 on Unicorn) over a scan, with injectable faults
    Twin(dmap::twin::TwinArgs),
    /// Talk to the sensor over its serial port: status, get, set, calibrate, save, defaults, reset
    Sensor(dmap::sensor::SensorArgs),
    /// A live console in the browser: the defect map, objects, verdicts, settings and the link's health
    Console(dmap::console::ConsoleArgs),
    /// Maps scored per second by each implementation (f64 brute/SAT/embedding, fixed point, EMD), one thread
    Bench(dmap::bench::BenchArgs),
    /// Write (or --check) the line protocol's conformance vectors: streams and their expected decode
    Vectors(dmap::vectors::VectorsArgs),
}

fn main() {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        // --help, --version, or no subcommand at all: clap's own text.
        Err(e)
            if !e.use_stderr()
                || e.kind() == clap::error::ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand =>
        {
            e.exit()
        }
        Err(e) => {
            // One line like every other error; clap's full usage text is
            // one `--help` away.
            let text = e.to_string();
            let what: Vec<&str> = text
                .lines()
                .take_while(|l| !l.starts_with("Usage:"))
                .map(|l| l.trim().trim_start_matches("error: "))
                // clap's own hint, which the one below replaces.
                .filter(|l| !l.is_empty() && !l.starts_with("For more information"))
                .collect();
            let _ = writeln!(
                std::io::stderr(),
                "dmap: error: {} (see dmap --help)",
                what.join(" ")
            );
            std::process::exit(2);
        }
    };
    let result: anyhow::Result<()> = match cli.command {
        Command::Score(args) => dmap::score::run(&args),
        Command::Simulate(args) => dmap::simulate::run(&args),
        Command::Render(args) => dmap::render::run(&args),
        Command::Eval(args) => dmap::eval::run(&args),
        Command::Calibrate(args) => dmap::calibrate::run(&args),
        Command::Stream(args) => dmap::stream::run(&args),
        Command::Listen(args) => dmap::listen::run(&args),
        Command::Emulate(args) => dmap::emulate::run(&args),
        Command::Twin(args) => dmap::twin::run(&args),
        Command::Bench(args) => dmap::bench::run(&args),
        Command::Sensor(args) => dmap::sensor::run(&args),
        Command::Console(args) => dmap::console::run(&args),
        Command::Vectors(args) => dmap::vectors::run(&args),
    };
    if let Err(e) = result {
        // A reader that closed the pipe (`dmap ... | head`) got what it
        // wanted: quiet, with the status of a tool killed by SIGPIPE.
        if dmap::out::is_stdout_closed(&e) {
            std::process::exit(dmap::out::EXIT_STDOUT_CLOSED);
        }
        // One line, no backtrace: users read this in a terminal or a CI log.
        let _ = writeln!(std::io::stderr(), "dmap: error: {e:#}");
        // `dmap sensor` tells refusals, timeouts and link errors apart.
        std::process::exit(dmap::sensor::exit_code(&e).unwrap_or(1));
    }
}
