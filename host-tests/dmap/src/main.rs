//! `dmap`: the host toolkit. Its command line is the library's `cli`; this
//! file only parses, dispatches and turns an error into a line and a status.

use clap::Parser;
use dmap::cli::Cli;
use std::io::Write;

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
    let result = dmap::cli::run(cli.command);
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
