//! Where the console's lines come from and where its requests go: a
//! serial port (both ways on one link), the H743 firmware on the chip
//! model (its UART output in, the requests to its receiver, live), or a
//! recorded stream replayed at the link's rate, a chosen one, or in full.

use super::args::{ConsoleArgs, Rate};
use super::hub::Writer;
use anyhow::{Context, Result, bail};
use std::io::Read;
use std::path::PathBuf;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

pub struct Opened {
    pub reader: Box<dyn Read + Send>,
    pub writer: Writer,
    pub name: String,
    /// How long a reply may take.
    pub reply_timeout: Duration,
}

/// Bytes handed over by another thread, read as a stream.
struct Chunks {
    rx: Receiver<Vec<u8>>,
    held: Vec<u8>,
    at: usize,
}

impl Read for Chunks {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        while self.at == self.held.len() {
            match self.rx.recv() {
                Ok(b) => (self.held, self.at) = (b, 0),
                Err(_) => return Ok(0),
            }
        }
        let n = out.len().min(self.held.len() - self.at);
        out[..n].copy_from_slice(&self.held[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

/// A recording: a file opened at once, a FIFO when it is first read (so
/// that the page is served while the writer has yet to come).
enum Input {
    File(std::fs::File),
    Fifo(PathBuf),
}

impl Input {
    fn open(path: &std::path::Path) -> Result<Input> {
        use std::os::unix::fs::FileTypeExt;
        let meta =
            std::fs::metadata(path).with_context(|| format!("cannot open {}", path.display()))?;
        if meta.file_type().is_fifo() {
            return Ok(Input::Fifo(path.to_path_buf()));
        }
        Ok(Input::File(std::fs::File::open(path).with_context(
            || format!("cannot open {}", path.display()),
        )?))
    }
}

impl Read for Input {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        if let Input::Fifo(p) = self {
            *self = Input::File(std::fs::File::open(&*p)?);
        }
        match self {
            Input::File(f) => f.read(out),
            Input::Fifo(_) => Ok(0),
        }
    }
}

/// A recording read at a pace: `bytes_per_s` or `lines_per_s`.
struct Paced<R> {
    inner: R,
    start: Instant,
    done: f64,
    per_s: f64,
    lines: bool,
}

impl<R: Read> Read for Paced<R> {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        let due = self.start + Duration::from_secs_f64(self.done / self.per_s);
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        let want = if self.lines { 1 } else { out.len().min(256) };
        let n = if self.lines {
            // One line at a time.
            let mut k = 0;
            while k < out.len() {
                let m = self.inner.read(&mut out[k..k + want])?;
                if m == 0 {
                    break;
                }
                k += 1;
                if out[k - 1] == b'\n' {
                    break;
                }
            }
            self.done += 1.0;
            k
        } else {
            let n = self.inner.read(&mut out[..want])?;
            self.done += n as f64;
            n
        };
        Ok(n)
    }
}

pub fn open(args: &ConsoleArgs, note: Arc<dyn Fn(String) + Send + Sync>) -> Result<Opened> {
    if let Some(dev) = &args.port {
        let port = serialport::new(dev, args.baud)
            .timeout(Duration::from_millis(50))
            .open()
            .with_context(|| format!("cannot open serial port {dev} at {} baud", args.baud))?;
        let _ = port.clear(serialport::ClearBuffer::Input);
        let writer = port.try_clone().context("sharing the serial port")?;
        return Ok(Opened {
            reader: Box::new(port),
            writer: Writer::Port(writer),
            name: format!("serial port {dev} at {} baud", args.baud),
            reply_timeout: Duration::from_secs(2),
        });
    }
    if let Some(path) = &args.input {
        let f = Input::open(path)?;
        let (reader, pace): (Box<dyn Read + Send>, String) = match args.rate {
            Rate::Full => (Box::new(f), "in full".into()),
            Rate::Link => (
                Box::new(Paced {
                    inner: f,
                    start: Instant::now(),
                    done: 0.0,
                    per_s: f64::from(args.baud) / 10.0,
                    lines: false,
                }),
                format!("at the link's {} baud", args.baud),
            ),
            Rate::Lines(n) => (
                Box::new(Paced {
                    inner: std::io::BufReader::new(f),
                    start: Instant::now(),
                    done: 0.0,
                    per_s: n,
                    lines: true,
                }),
                format!("at {n} lines a second"),
            ),
        };
        return Ok(Opened {
            reader,
            writer: Writer::None,
            name: format!("recording {} replayed {pace}", path.display()),
            reply_timeout: Duration::from_secs(2),
        });
    }
    if !args.emulate.is_empty() {
        return emulate(args, note);
    }
    if args.twin.is_empty() {
        bail!("give --port DEV, --twin SCAN.npy, --emulate SCAN.npy or --input FILE");
    }
    twin(args, note)
}

/// The emulated board: each scan a run of QEMU, one part, round and round.
fn emulate(args: &ConsoleArgs, note: Arc<dyn Fn(String) + Send + Sync>) -> Result<Opened> {
    #[derive(clap::Parser)]
    struct Emulate {
        #[command(flatten)]
        args: crate::emulate::EmulateArgs,
    }
    let mut files = Vec::new();
    for scan in &args.emulate {
        let words = ["emulate", &scan.display().to_string(), "--scores"];
        let a = <Emulate as clap::Parser>::try_parse_from(words)?.args;
        files.push(crate::emulate::scan_file(&a)?);
    }
    let root = crate::repo::find(None)?;
    let (tx, rx) = channel::<Vec<u8>>();
    std::thread::spawn(move || {
        let dir = tempfile::Builder::new().prefix("dmap-console-").tempdir();
        let run = || -> Result<()> {
            let dir = dir.as_ref().map_err(|e| anyhow::anyhow!("{e}"))?;
            let elf = crate::emulate::build_elf_in(&root)?;
            let mut paths = Vec::new();
            for (k, f) in files.iter().enumerate() {
                let p = dir.path().join(format!("scan{k}.cvmscan"));
                std::fs::write(&p, f)?;
                paths.push(p);
            }
            for p in paths.iter().cycle() {
                crate::emulate::run_qemu(&elf, p, false, None, &mut |b| {
                    tx.send(b.to_vec())
                        .map_err(|_| anyhow::anyhow!("the console stopped"))
                })?;
            }
            Ok(())
        };
        if let Err(e) = run() {
            note(format!("the emulated board failed: {e:#}"));
        }
    });
    Ok(Opened {
        reader: Box::new(Chunks {
            rx,
            held: Vec::new(),
            at: 0,
        }),
        writer: Writer::None,
        name: format!(
            "emulated board (QEMU): {}",
            args.emulate
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
        reply_timeout: Duration::from_secs(2),
    })
}

/// The scans, each one part, repeated to `parts` parts in one `.npy`.
fn parts_file(scans: &[PathBuf], parts: u32, dir: &std::path::Path) -> Result<PathBuf> {
    let mut data = Vec::new();
    let mut shape = None;
    let read: Vec<_> = scans
        .iter()
        .map(|p| crate::npy::read_scan(p))
        .collect::<Result<_>>()?;
    for (k, s) in read.iter().cycle().take(parts as usize).enumerate() {
        let this = (s.rows, s.cols, s.geometry);
        match shape {
            None => shape = Some(this),
            Some(sh) if sh != this => bail!(
                "--twin {}: another shape than {} (the firmware is built for one)",
                scans[k % scans.len()].display(),
                scans[0].display()
            ),
            _ => {}
        }
        data.extend(s.to_u16()?);
    }
    let (rows, cols, g) = shape.context("no scan")?;
    let path = dir.join("parts.npy");
    crate::npy::write_scan_u16(&path, rows * parts as usize, cols, g, &data)?;
    Ok(path)
}

fn twin(args: &ConsoleArgs, note: Arc<dyn Fn(String) + Send + Sync>) -> Result<Opened> {
    let dir = tempfile::Builder::new()
        .prefix("dmap-console-")
        .tempdir()
        .context("creating a temporary directory")?;
    let scan = parts_file(&args.twin, args.parts, dir.path())?;
    let flash = args
        .flash
        .clone()
        .unwrap_or_else(|| dir.path().join("bank2.bin"));
    #[derive(clap::Parser)]
    struct Twin {
        #[command(flatten)]
        args: crate::twin::TwinArgs,
    }
    let mut words: Vec<String> = vec!["twin".into(), scan.display().to_string()];
    words.extend(["--scores".into(), "--parts".into(), args.parts.to_string()]);
    words.extend(["--flash".into(), flash.display().to_string()]);
    words.extend(args.twin_options.iter().cloned());
    let base = <Twin as clap::Parser>::try_parse_from(&words)
        .map_err(|e| {
            anyhow::anyhow!(
                "--twin-option: {}",
                e.to_string().lines().next().unwrap_or("")
            )
        })?
        .args;
    let (tx, rx) = channel::<Vec<u8>>();
    let (req_tx, req_rx) = channel::<Vec<u8>>();
    let requests: Arc<Mutex<Sender<Vec<u8>>>> = Arc::new(Mutex::new(req_tx));
    let mut first = Some(req_rx);
    let shared = Arc::clone(&requests);
    let name = format!(
        "H743 firmware on the chip model, {} part(s) a run: {}",
        args.parts,
        args.twin
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    std::thread::spawn(move || {
        let _dir = dir;
        for run in 1u64.. {
            // Each run of the model takes the requests from a channel of its own.
            let rx = first.take().unwrap_or_else(|| {
                let (t, r) = channel();
                *shared.lock().unwrap_or_else(|e| e.into_inner()) = t;
                r
            });
            let mut a = base.clone();
            a.link.live = crate::twin::requests::LiveRequests::new(rx);
            let sent = crate::twin::run_to(&a, &mut |b| {
                tx.send(b.to_vec())
                    .map_err(|_| anyhow::anyhow!("the console stopped"))
            });
            if let Err(e) = sent {
                note(format!("the chip model's run {run} failed: {e:#}"));
                return;
            }
        }
    });
    Ok(Opened {
        reader: Box::new(Chunks {
            rx,
            held: Vec::new(),
            at: 0,
        }),
        writer: Writer::Twin(requests),
        name,
        // The model runs some sixty times slower than silicon.
        reply_timeout: Duration::from_secs(30),
    })
}
