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
enum Command {}

fn main() {
    let cli = Cli::parse();
    let result: anyhow::Result<()> = match cli.command {};
    if let Err(e) = result {
        // One line, no backtrace: users read this in a terminal or a CI log.
        eprintln!("dmap: error: {e:#}");
        std::process::exit(1);
    }
}
