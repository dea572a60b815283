//! `dmap`: the host toolkit. Each subcommand is one variant of [`Command`]
//! and one module of the library; this file only parses and dispatches.

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "dmap", version, about = "Deflection-map defect scoring toolkit")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

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
}

fn main() {
    let cli = Cli::parse();
    let result: anyhow::Result<()> = match cli.command {
        Command::Score(args) => dmap::score::run(&args),
        Command::Simulate(args) => dmap::simulate::run(&args),
        Command::Render(args) => dmap::render::run(&args),
        Command::Eval(args) => dmap::eval::run(&args),
    };
    if let Err(e) = result {
        // One line, no backtrace: users read this in a terminal or a CI log.
        eprintln!("dmap: error: {e:#}");
        std::process::exit(1);
    }
}
