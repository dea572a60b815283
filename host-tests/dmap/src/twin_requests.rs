//! What `dmap twin` hands the chip model besides the scan: the bytes a
//! host sends on the board's serial link and at which beams, bank 2 of
//! the flash kept between runs (a second run is a reboot of the same
//! image with its flash), and a power cut at a chosen flash operation.
//! The chip model's side is `host-tests/twin/h743twin/usart_rx.py` and
//! `flash.py`; this file only carries the options through, and writes the
//! `--command` requests (`crate::sensor::twin`) into a requests file.

use crate::sensor::twin::{Planned, bursts, plan};
use anyhow::{Context, Result, bail};
use clap::Args;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

#[derive(Args, Clone, Debug, Default)]
pub struct TwinRequestArgs {
    /// Bytes the host sends on USART3 while the scan runs: one burst a
    /// line, `BEAM HEX [KIND@INDEX ...]`, sent from beam BEAM's DRDY on at
    /// the board's baud rate; KIND@INDEX marks the INDEX-th byte of the
    /// burst as received with a framing error (fe), noise (ne) or a
    /// parity error (pe); `#` starts a comment
    #[arg(long, value_name = "FILE")]
    pub requests: Option<PathBuf>,
    /// Send REQUEST, in the words of `dmap sensor`'s actions, from beam
    /// BEAM's DRDY on (repeatable; e.g. 0:status, 5:"set thr=100",
    /// 9:"calibrate --scans 2"): ids 1, 2, 3, ... in the order given, one
    /// per request (a set of two keys takes two); sent after the
    /// --requests file's bursts at the same beam. The replies are
    /// summarised on stderr, one line per request
    #[arg(long = "command", value_name = "BEAM:REQUEST")]
    pub commands: Vec<String>,
    /// Bank 2 of the chip's flash: read from FILE when it exists (else
    /// erased), written back when the run ends, so that the next run with
    /// the same FILE boots with what this one left there
    #[arg(long, value_name = "FILE")]
    pub flash: Option<PathBuf>,
    /// Cut the power at the N-th flash operation (sector erase or
    /// flash-word program, from 1): the operation is left half done and
    /// the run ends there (status `power cut`)
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub power_cut: Option<u32>,
}

impl TwinRequestArgs {
    /// Adds the chip model's options for these arguments.
    pub fn apply(&self, cmd: &mut Command) {
        if let Some(p) = &self.requests {
            cmd.arg("--requests").arg(p);
        }
        if let Some(p) = &self.flash {
            cmd.arg("--flash").arg(p);
        }
        if let Some(n) = self.power_cut {
            cmd.args(["--power-cut", &n.to_string()]);
        }
    }

    /// The `--command` requests, checked (their beams against the scan's).
    pub fn planned(&self, beams: u64) -> Result<Vec<Planned>> {
        plan(&self.commands, beams)
    }

    /// With `--command`: these arguments with the commands written into a
    /// requests file in `dir` (after the `--requests` file's bursts), which
    /// the model reads instead.
    pub fn with_commands(&self, planned: &[Planned], dir: &Path) -> Result<TwinRequestArgs> {
        if planned.is_empty() {
            return Ok(self.clone());
        }
        let path = dir.join("requests.txt");
        let mut text = match &self.requests {
            Some(p) => std::fs::read_to_string(p)
                .with_context(|| format!("reading the requests file {}", p.display()))?,
            None => String::new(),
        };
        if !text.is_empty() && !text.ends_with('\n') {
            text.push('\n');
        }
        for (beam, bytes) in bursts(planned) {
            let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
            text += &format!("{beam} {hex}\n");
        }
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
        Ok(TwinRequestArgs {
            requests: Some(path),
            commands: Vec::new(),
            ..self.clone()
        })
    }

    /// Refuses a requests file whose bursts start at no beam of the scan,
    /// before the firmware is built.
    pub fn check(&self, beams: u64) -> Result<()> {
        self.planned(beams)?;
        let Some(path) = &self.requests else {
            return Ok(());
        };
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading the requests file {}", path.display()))?;
        for (n, line) in text.lines().enumerate() {
            let body = line.split('#').next().unwrap_or("");
            let Some(beam) = body.split_whitespace().next() else {
                continue;
            };
            match beam.parse::<u64>() {
                Ok(b) if b < beams => {}
                _ => bail!(
                    "{}:{}: `{beam}` is not a beam of this scan (0..{beams})",
                    path.display(),
                    n + 1
                ),
            }
        }
        Ok(())
    }
}

/// Writes a requests file: each burst at its beam, as hex.
pub fn write_requests(path: &Path, bursts: &[(u64, &[u8])]) -> Result<()> {
    let mut f = std::fs::File::create(path)
        .with_context(|| format!("creating the requests file {}", path.display()))?;
    for (beam, bytes) in bursts {
        let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
        writeln!(f, "{beam} {hex}").with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_reach_the_model_and_files_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let req = dir.path().join("req.txt");
        write_requests(&req, &[(0, b"S,1\n"), (7, &[0x00, 0xFF])]).unwrap();
        assert_eq!(
            std::fs::read_to_string(&req).unwrap(),
            "0 532c310a\n7 00ff\n"
        );
        let args = TwinRequestArgs {
            requests: Some(req.clone()),
            flash: Some(dir.path().join("bank2.bin")),
            power_cut: Some(3),
            commands: Vec::new(),
        };
        assert!(args.check(8).is_ok());
        assert!(args.check(7).is_err(), "beam 7 of a 7-beam scan");
        let mut cmd = Command::new("python3");
        args.apply(&mut cmd);
        let got: Vec<String> = cmd
            .get_args()
            .map(|a| a.to_string_lossy().into_owned())
            .collect();
        assert_eq!(got[0], "--requests");
        assert_eq!(got[2], "--flash");
        assert_eq!(got[4..], ["--power-cut", "3"]);
        let none = TwinRequestArgs::default();
        let mut cmd = Command::new("python3");
        none.apply(&mut cmd);
        assert_eq!(cmd.get_args().count(), 0);
    }
}
