//! `dmap`'s command line: one variant of [`Command`] per subcommand, each
//! one module of the library. Here (not in the binary) so that a test can
//! walk the whole tree of subcommands and their options.

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "dmap",
    version,
    about = "Deflection-map defect scoring toolkit"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

// Parsed once per run: the size of the largest variant does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Gradient image (Eq. 1) of a scan under a distance: cvm, cvm-fixed, emd, mean-dir
    Score(crate::score::ScoreArgs),
    /// Simulate a scan (ray model of the scanner) and its ground-truth defect mask
    Simulate(crate::simulate::SimulateArgs),
    /// Pseudo-colour PNG of gradient images with colour bars, side by side
    Render(crate::render::RenderArgs),
    /// SNR, PSNR, CNR and defect sizes of a gradient image against a truth mask
    Eval(crate::eval::EvalArgs),
    /// Defect threshold from defect-free reference scans, in the firmware's arithmetic (--calibration of stream, emulate, twin)
    Calibrate(crate::calibrate::CalibrateArgs),
    /// Run the firmware's pipeline on the host and print its result lines
    Stream(crate::stream::StreamArgs),
    /// Decode result lines (file, stdin or serial port) into a score image and a summary
    Listen(crate::listen::ListenArgs),
    /// Run the firmware (emulated board, QEMU mps2-an386) over a scan and print its UART output
    Emulate(crate::emulate::EmulateArgs),
    /// Run the H743 release firmware on the chip model (STM32H743 on Unicorn) over a scan, with injectable faults
    Twin(crate::twin::TwinArgs),
    /// Talk to the sensor over its serial port: status, get, set, calibrate, save, defaults, reset
    Sensor(crate::sensor::SensorArgs),
    /// A live console in the browser: the defect map, objects, verdicts, settings and the link's health
    Console(crate::console::ConsoleArgs),
    /// Maps scored per second by each implementation (f64 brute/SAT/embedding, fixed point, EMD), one thread
    Bench(crate::bench::BenchArgs),
    /// Write (or --check) the line protocol's conformance vectors: streams and their expected decode
    Vectors(crate::vectors::VectorsArgs),
}

/// Runs the subcommand.
pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Score(args) => crate::score::run(&args),
        Command::Simulate(args) => crate::simulate::run(&args),
        Command::Render(args) => crate::render::run(&args),
        Command::Eval(args) => crate::eval::run(&args),
        Command::Calibrate(args) => crate::calibrate::run(&args),
        Command::Stream(args) => crate::stream::run(&args),
        Command::Listen(args) => crate::listen::run(&args),
        Command::Emulate(args) => crate::emulate::run(&args),
        Command::Twin(args) => crate::twin::run(&args),
        Command::Bench(args) => crate::bench::run(&args),
        Command::Sensor(args) => crate::sensor::run(&args),
        Command::Console(args) => crate::console::run(&args),
        Command::Vectors(args) => crate::vectors::run(&args),
    }
}
