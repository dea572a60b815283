//! What `dmap twin` hands the chip model besides the scan: the bytes a
//! host sends on the board's serial link and at which beams, bank 2 of
//! the flash kept between runs (a second run is a reboot of the same
//! image with its flash), and a power cut at a chosen flash operation.
//! The chip model's side is `host-tests/twin/h743twin/usart_rx.py` and
//! `flash.py`; this file checks the options before anything runs, reads
//! `--requests` once and hands the model a copy with the `--command`
//! requests (`crate::sensor::twin`) after it, and keeps `--flash` to the
//! output rule through a copy ([`FlashFile`]).

use crate::sensor::twin::{Planned, bursts, plan};
use anyhow::{Context, Result, bail};
use clap::Args;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::mpsc::Receiver;
use std::sync::{Arc, Mutex};

/// Bytes a live host sends while the model runs (`dmap console`): handed
/// to the model's standard input as they come (its `--stdin-requests`),
/// which puts them on USART3's line at the model time it reads them.
#[derive(Clone, Debug, Default)]
pub struct LiveRequests(pub Arc<Mutex<Option<Receiver<Vec<u8>>>>>);

impl LiveRequests {
    pub fn new(rx: Receiver<Vec<u8>>) -> Self {
        LiveRequests(Arc::new(Mutex::new(Some(rx))))
    }

    pub fn is_live(&self) -> bool {
        self.0.lock().map(|r| r.is_some()).unwrap_or(false)
    }

    /// Forwards every burst to `stdin` on a thread of its own until the
    /// sender or the model is gone.
    pub fn forward(&self, mut stdin: std::process::ChildStdin) {
        let Some(rx) = self.0.lock().ok().and_then(|mut r| r.take()) else {
            return;
        };
        std::thread::spawn(move || {
            for bytes in rx {
                if stdin
                    .write_all(&bytes)
                    .and_then(|()| stdin.flush())
                    .is_err()
                {
                    return;
                }
            }
        });
    }
}

#[derive(Args, Clone, Debug, Default)]
pub struct TwinRequestArgs {
    /// Bytes the host sends on USART3 while the scan runs: one burst a
    /// line, `BEAM HEX [KIND@INDEX ...]`, sent from beam BEAM's DRDY on at
    /// the board's baud rate; KIND@INDEX marks the INDEX-th byte of the
    /// burst as received with a framing error (fe), noise (ne) or a
    /// parity error (pe); `#` starts a comment. Read once (a pipe works),
    /// at most 64 MiB; a file without a burst is refused
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
    /// erased), written back when the run ends (beside FILE, renamed into
    /// place), so that the next run with the same FILE boots with what this
    /// one left there. FILE must be a writable bank 2 image or a new name
    /// in an existing folder; one run at a time may use it
    #[arg(long, value_name = "FILE")]
    pub flash: Option<PathBuf>,
    /// Cut the power at the N-th flash operation (sector erase or
    /// flash-word program, from 1): the operation is left half done and
    /// the run ends there (status `power cut`); a run that made fewer
    /// than N operations fails, after its counters
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub power_cut: Option<u32>,
    /// A live host's bytes (`dmap console`), not an option of `dmap twin`.
    #[arg(skip)]
    pub live: LiveRequests,
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
        if self.live.is_live() {
            cmd.arg("--stdin-requests");
        }
    }

    /// The `--command` requests, checked (their beams against the scan's).
    pub fn planned(&self, beams: u64) -> Result<Vec<Planned>> {
        plan(&self.commands, beams)
    }

    /// The arguments the model gets: the requests (the `--requests`
    /// file's text, read once by [`Self::check`], then the `--command`
    /// requests) written into a file in `dir`, which the model reads
    /// instead of the user's (a pipe can be read only once), and bank 2 as
    /// the copy `flash` keeps.
    pub fn for_model(
        &self,
        planned: &[Planned],
        requests: Option<&str>,
        dir: &Path,
        flash: Option<&FlashFile>,
    ) -> Result<TwinRequestArgs> {
        let mut model = TwinRequestArgs {
            commands: Vec::new(),
            requests: None,
            flash: flash.map(|f| f.copy.clone()),
            ..self.clone()
        };
        if requests.is_none() && planned.is_empty() {
            return Ok(model);
        }
        let path = dir.join("requests.txt");
        let mut text = requests.unwrap_or_default().to_string();
        if !text.is_empty() && !text.ends_with('\n') {
            text.push('\n');
        }
        for (beam, bytes) in bursts(planned) {
            let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
            text += &format!("{beam} {hex}\n");
        }
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
        model.requests = Some(path);
        Ok(model)
    }

    /// Reads the `--requests` file once (at most [`MAX_REQUESTS_BYTES`])
    /// and refuses one whose bursts start at no beam of the scan, or that
    /// holds none, before the firmware is built. Returns its text.
    pub fn check(&self, beams: u64) -> Result<Option<String>> {
        self.planned(beams)?;
        let Some(path) = &self.requests else {
            return Ok(None);
        };
        let p = path.display();
        let mut bytes = Vec::new();
        std::fs::File::open(path)
            .and_then(|f| f.take(MAX_REQUESTS_BYTES + 1).read_to_end(&mut bytes))
            .with_context(|| format!("reading the requests file {p}"))?;
        if bytes.len() as u64 > MAX_REQUESTS_BYTES {
            bail!(
                "{p}: larger than {} MiB: not a requests file (a scan's link carries far less)",
                MAX_REQUESTS_BYTES >> 20
            );
        }
        let text = String::from_utf8(bytes)
            .map_err(|_| anyhow::anyhow!("{p}: not text (a requests file is `BEAM HEX` lines)"))?;
        let mut bursts = 0;
        for (n, line) in text.lines().enumerate() {
            let body = line.split('#').next().unwrap_or("");
            let Some(beam) = body.split_whitespace().next() else {
                continue;
            };
            match beam.parse::<u64>() {
                Ok(b) if b < beams => bursts += 1,
                _ => bail!(
                    "{}:{}: `{beam}` is not a beam of this scan (0..{beams})",
                    path.display(),
                    n + 1
                ),
            }
        }
        if bursts == 0 {
            // An empty pipe, or a file of comments: the run would send nothing.
            bail!("{p}: holds no burst (`BEAM HEX` lines): nothing would be sent");
        }
        Ok(Some(text))
    }

    /// Checks `--flash` before anything runs and locks it for the run
    /// ([`FlashFile`]).
    pub fn prepare_flash(&self) -> Result<Option<FlashFile>> {
        self.flash.as_deref().map(FlashFile::prepare).transpose()
    }
}

/// Most bytes of a `--requests` file: 600 s of model time at 921 600
/// baud carry 55 MB; a file beyond this is not one.
pub const MAX_REQUESTS_BYTES: u64 = 64 << 20;

/// The chip model's bank 2 image (`flash.py`): 1 MiB of cells, then one
/// byte per 32-byte flash word.
pub const FLASH_IMAGE_BYTES: u64 = (1 << 20) + (1 << 20) / 32;

/// `--flash FILE` for one run. Checked before anything runs: an existing
/// FILE must be a regular, writable file of a bank 2 image's size (a
/// folder, a FIFO, a device, another size or a read-only file are
/// refused), a new one's folder must exist and take a new file. The
/// model works on a copy; once it is done the copy is written back as
/// every output is ([`crate::out::write_file`]: beside FILE, renamed into
/// place). A lock held from the check to the write-back refuses a second
/// `dmap twin` run with the same FILE meanwhile, which would otherwise
/// overwrite this one's flash with its own.
pub struct FlashFile {
    user: PathBuf,
    copy: PathBuf,
    _dir: tempfile::TempDir,
    _lock: std::fs::File,
}

impl FlashFile {
    fn prepare(path: &Path) -> Result<FlashFile> {
        use std::os::unix::fs::FileTypeExt;
        let p = path.display();
        let meta = match std::fs::metadata(path) {
            Ok(m) => Some(m),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => bail!("--flash {p}: {e}"),
        };
        if let Some(m) = &meta {
            let t = m.file_type();
            if t.is_dir() {
                bail!("--flash {p}: is a directory, not a bank 2 image");
            }
            if t.is_fifo() || t.is_socket() || t.is_char_device() || t.is_block_device() {
                bail!("--flash {p}: not a regular file (bank 2 is read from it and written back)");
            }
            if m.len() != FLASH_IMAGE_BYTES {
                bail!(
                    "--flash {p}: not a bank 2 image ({} bytes; one holds {FLASH_IMAGE_BYTES})",
                    m.len()
                );
            }
            if m.permissions().readonly() {
                bail!("--flash {p}: is read-only, so the run's bank 2 could not be written back");
            }
        }
        let target = crate::out::resolve_links(path)?;
        let folder = match target.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        // Writing back makes a file beside FILE: try it now.
        tempfile::tempfile_in(&folder).map_err(|e| {
            anyhow::anyhow!(
                "--flash {p}: cannot write in its folder {}: {e}",
                folder.display()
            )
        })?;
        let lock = lock_file(&folder, &target)?;
        lock.try_lock().map_err(|_| {
            anyhow::anyhow!(
                "--flash {p}: in use by another dmap twin run (two runs on one flash file would each overwrite the other's); wait for it to end"
            )
        })?;
        let dir = tempfile::Builder::new()
            .prefix("dmap-flash-")
            .tempdir()
            .context("creating a temporary directory")?;
        let copy = dir.path().join("bank2.bin");
        if meta.is_some() {
            let bytes = std::fs::read(path).with_context(|| format!("--flash {p}: reading"))?;
            if bytes.len() as u64 != FLASH_IMAGE_BYTES {
                bail!("--flash {p}: changed while being read");
            }
            std::fs::write(&copy, bytes).with_context(|| format!("writing {}", copy.display()))?;
        }
        Ok(FlashFile {
            user: path.to_path_buf(),
            copy,
            _dir: dir,
            _lock: lock,
        })
    }

    /// The bank as the model left it, written over FILE (nothing when the
    /// model saved none: it failed before the end of its run).
    pub fn write_back(&self) -> Result<()> {
        let Ok(bytes) = std::fs::read(&self.copy) else {
            return Ok(());
        };
        crate::out::write_file(&self.user, |w| Ok(w.write_all(&bytes)?))
    }
}

/// The lock file of a flash file: outside its folder (which is left as
/// the user keeps it), named by the file's absolute path, so that it stays
/// the same whether FILE exists yet or has been replaced.
fn lock_file(folder: &Path, target: &Path) -> Result<std::fs::File> {
    let folder = folder
        .canonicalize()
        .with_context(|| format!("--flash: its folder {}", folder.display()))?;
    let name = folder.join(target.file_name().unwrap_or_default());
    let hash = name
        .as_os_str()
        .as_encoded_bytes()
        .iter()
        .fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
            (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
        });
    let path = std::env::temp_dir().join(format!("dmap-flash-{hash:016x}.lock"));
    std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .with_context(|| format!("creating the lock file {}", path.display()))
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
            live: Default::default(),
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
