//! `dmap twin`: the H743 release firmware, unmodified, run on the chip
//! model in `host-tests/twin` (an STM32H743 on Unicorn, with a detector
//! model wired to its pins) over a scan.
//!
//! * The scan is read as `dmap emulate` reads it, its settings resolved by
//!   [`crate::settings::resolve`] (the same settings, errors and warnings
//!   as `dmap stream`) and written as the emulated board's scan file
//!   ([`crate::emulate::board_file`]); the H743 build configuration
//!   (`CVM_H743_SCAN`, read by the firmware's `build.rs`) is derived from
//!   that file's header: geometry, columns, rows, kernels, weights,
//!   normalisation, threshold, score lines and defect lines per row.
//! * The ELF is built with `cargo build --release` into `target/twin` and
//!   cached per configuration in `target/twin/elf/<hash>.elf`; a cached ELF
//!   is reused while it is newer than every firmware source. A new
//!   `target/twin` starts as a copy of the product build's dependencies
//!   ([`seed_from_product_build`]), so only the firmware crate compiles
//!   per configuration. `--elf` skips
//!   the build; the ELF's `.cvm_config` section (written by build.rs) must
//!   then agree with the run's configuration field by field
//!   ([`crate::twin::checks::check_built_for`]), and a damaged ELF is refused
//!   before the model starts ([`crate::elf::read`]).
//! * The model (`python3 -m h743twin`) reads the scan in its own format,
//!   written to a temporary file; its standard output (the bytes the
//!   firmware sent on USART3) is copied to standard output, and its
//!   standard error, whose last line is a JSON object of counters, is
//!   passed through. A model that fails or stops on something it does not
//!   model makes `dmap` fail with one line after that JSON.
//! * The model never outlives `dmap`: on every way out (an error, a closed
//!   pipe, a panic, SIGINT, SIGTERM or SIGHUP) it is killed and reaped
//!   before its scan file is removed; on SIGKILL, which `dmap` cannot
//!   catch, the kernel kills it ([`crate::child::dies_with_parent`]).
//! * A run whose end line never came (the firmware wedged, or the settle
//!   time ran out) fails, after the model's counters.

use crate::fmt::fmt_num;
use crate::options::{OutputArgs, ScoringArgs};
use crate::twin::checks::{check_built_for, check_fault, check_model_time};
use anyhow::{Context, Result, bail};
use clap::Args;
use cvm_core::{Kernels, Weights};
use cvm_fw_app::emufile::{HEADER_LEN, ScanHeader};
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{ChildStderr, Command, Stdio};
use std::time::SystemTime;

const FAULTS_HELP: &str = "\
Faults (--fault KIND@BEAM[:ARG...], repeatable; beams count from 0 in raster order):
  gap@B:MS         no DRDY for MS milliseconds before beam B
  burst@B:N:US     beams B..B+N-1 come US microseconds apart (faster than the SPI)
  sync-glitch@B    an extra LINE_SYNC on beam B (mid-row)
  sync-miss@B      no LINE_SYNC on beam B (a row start)
  overrun@B        the SPI loses a frame of beam B's read (OVR)
  dma-error@B      beam B's SPI DMA transfer fails with a transfer error
  dma-stall@B      beam B's SPI DMA requests are never served
  uart-busy@B:MS   the UART line is held busy for MS milliseconds from beam B
  halt@B:MS        a debugger halts the core for MS milliseconds at beam B
  wedge@B          the firmware wedges at beam B (interrupts off; the watchdog must reset it)
  drdy-miss@B      beam B raises no DRDY
  pin-reset@B      NRST is pulled at beam B (RCC_RSR: PINRSTF)
  bor@B            the supply dips below the brown-out threshold at beam B (BORRSTF, PINRSTF)
  hardfault@B      the core takes a bus fault at beam B (HardFault; counted in `hardfaults`)
  panic@B          the core is forced into core::panicking::panic at beam B (the firmware's
                   own panic handler runs; a forced entry, not a fault silicon makes)

A burst must end by the scan's last beam, a sync-miss falls on a row start, a
sync-glitch mid-row. A run's model time (--start-ms, the beams at --beam-us, the
faults' pauses, --settle-ms) is at most 600 s.

Standard output: the bytes the firmware sent on its UART, as they come. Standard error: the model's
counters as one JSON object (last line; `resets` lists the resets with their causes,
`clock_enable_drops` the register accesses lost to a clock enable not yet in effect). Needs python3
with unicorn 2.1.4 and pyelftools 0.33 (scripts/setup.sh installs them).";

#[derive(Args, Clone, Debug)]
#[command(after_help = FAULTS_HELP)]
pub struct TwinArgs {
    /// Scan .npy, shape (rows, cols, J1, J2), integer counts 0..=65535
    pub scan: PathBuf,
    #[command(flatten)]
    pub scoring: ScoringArgs,
    #[command(flatten)]
    pub output: OutputArgs,
    /// DRDY period: one beam every P microseconds
    #[arg(long, value_name = "P", default_value_t = 200.0)]
    pub beam_us: f64,
    /// Inject a detector or chip fault, KIND@BEAM[:ARG...] (kinds below)
    #[arg(long = "fault", value_name = "SPEC")]
    pub faults: Vec<String>,
    /// H743 ELF to run, built for this scan's configuration (default: build it, cached in target/twin/elf)
    #[arg(long)]
    pub elf: Option<PathBuf>,
    /// Run the model at most this many milliseconds after the last beam
    #[arg(long, value_name = "MS", default_value_t = 1500.0)]
    pub settle_ms: f64,
    /// The first beam comes this many milliseconds after reset (square
    /// kernels build their factor table at start-up: about 80 ms at 15x15)
    #[arg(long, value_name = "MS", default_value_t = 20.0)]
    pub start_ms: f64,
    /// A debugger is attached (the DBGMCU freeze bits apply while the core is halted)
    #[arg(long)]
    pub debugger: bool,
    /// The scan holds K parts, scanned one after the other without a
    /// pause: the firmware is built for rows/K rows (each part is one of
    /// its scans), and the run waits for K end lines
    #[arg(long, value_name = "K", default_value_t = 1,
          value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub parts: u32,
    #[command(flatten)]
    pub link: crate::twin::requests::TwinRequestArgs,
    #[command(flatten)]
    pub pins: crate::twin::pins::PinArgs,
    #[command(flatten)]
    pub repo: crate::repo::RepoArgs,
}

/// The compile-time part of the `CVM_H743_SCAN` value that builds the
/// H743 firmware for an emulated-board scan header (see the root
/// `build.rs`): what the firmware's tables and buffers are built for
/// (geometry, columns, kernels, weights, normalisation, full scale) and
/// the version it announces. One ELF serves every run of such a scan;
/// the rest reaches the firmware as a settings record
/// ([`crate::twin::record`]).
pub fn h743_build_config(h: &ScanHeader) -> Result<String> {
    let g = h.config.geometry;
    let (kernels, b) = match h.config.kernels {
        Kernels::Paper { bmax } => ("paper", bmax),
        Kernels::Square { kmax } => ("square", kmax),
    };
    let weights = match h.config.weights {
        Weights::Uniform => "uniform",
        Weights::Unit => "unit",
        Weights::Separable { .. } => bail!("the H743 build has no separable weights"),
    };
    let fw = h
        .version
        .get(..usize::from(h.version_len))
        .and_then(|v| std::str::from_utf8(v).ok())
        .filter(|v| {
            !v.is_empty()
                && v.bytes()
                    .all(|b| b.is_ascii_graphic() && b != b',' && b != b'*')
        })
        .context("the firmware version of the scan header is not a plain ASCII word")?;
    // The version the host announces, so that the header compares byte for
    // byte with `dmap stream`'s.
    Ok(format!(
        "j1={} j2={} cols={} kernels={kernels} b={b} weights={weights} normalise={} fs={} fw={fw}",
        g.j1, g.j2, h.cols, h.config.normalise, h.config.full_scale,
    ))
}

/// The whole `CVM_H743_SCAN` value for an emulated-board scan header:
/// [`h743_build_config`] and the scan's settings compiled in (rows, and the
/// settings `thr`, `pthr`, `sthr`, `scores`, `dcap` as integers, converted
/// as the firmware converts the scan file's units), for a run whose bank 2
/// is the user's (`--flash`).
pub fn h743_config(h: &ScanHeader) -> Result<String> {
    let scorer = cvm_core::Scorer::new(&h.config)
        .map_err(|e| anyhow::anyhow!("the scan's configuration: {e:?}"))?;
    Ok(format!(
        "{} rows={} thr={} pthr={} sthr={} scores={} dcap={}",
        h743_build_config(h)?,
        h.rows,
        scorer.threshold_from_units(h.threshold_units),
        cvm_core::power::threshold_from_units(h.power_threshold_units),
        cvm_core::spread::threshold_from_units(h.spread_threshold_units),
        u8::from(h.scores),
        h.max_defect_lines_per_row,
    ))
}

/// The model's scan file (`Scan.read_raw` in detector.py): `CVMTWIN1`,
/// rows, cols, J1, J2 as little-endian u32, then the samples as
/// little-endian u16 in raster order, each map in (J1, J2) order, from an
/// emulated-board scan file (the same samples in the same order).
pub fn twin_file(h: &ScanHeader, emufile: &[u8]) -> Result<Vec<u8>> {
    let g = h.config.geometry;
    let samples = emufile
        .get(HEADER_LEN..)
        .context("scan file shorter than its header")?;
    let expected = h.rows as usize * h.cols as usize * usize::from(g.j1) * usize::from(g.j2);
    if samples.len() != 2 * expected {
        bail!(
            "scan has {} samples, expected {expected}",
            samples.len() / 2
        );
    }
    let mut out = Vec::with_capacity(24 + samples.len());
    out.extend_from_slice(b"CVMTWIN1");
    for v in [h.rows, h.cols, u32::from(g.j1), u32::from(g.j2)] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(samples);
    Ok(out)
}

/// A stable 64-bit hash (FNV-1a) of a configuration, naming its cached ELF.
fn config_hash(config: &str) -> u64 {
    config.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The newest modification time of `path` and everything under it.
fn newest(path: &Path) -> Option<SystemTime> {
    let meta = std::fs::metadata(path).ok()?;
    let mut t = meta.modified().ok();
    if meta.is_dir() {
        for entry in std::fs::read_dir(path).ok()?.flatten() {
            t = t.max(newest(&entry.path()));
        }
    }
    t
}

/// The newest firmware source: what a cached ELF must be newer than.
fn newest_source(root: &Path) -> Option<SystemTime> {
    [
        "src",
        "cvm-core/src",
        "cvm-core/Cargo.toml",
        "fw-app/src",
        "fw-app/Cargo.toml",
        "memory.x",
        "build.rs",
        "Cargo.toml",
        "Cargo.lock",
        ".cargo/config.toml",
    ]
    .iter()
    .filter_map(|p| newest(&root.join(p)))
    .max()
}

/// [`build_elf_in`] the repository [`crate::repo::find`] finds.
pub fn build_elf(config: &str) -> Result<PathBuf> {
    build_elf_in(&crate::repo::find(None)?, config)
}

/// The H743 release ELF for `config` (a `CVM_H743_SCAN` value): the cached
/// copy in `target/twin/elf` of the repository `root` if it is newer than
/// every firmware source, else a fresh `cargo build --release --target-dir
/// target/twin`, copied there. A lock file keeps concurrent runs from
/// copying each other's build. The build ends with `dmap`
/// ([`crate::child::run_build`]).
pub fn build_elf_in(root: &Path, config: &str) -> Result<PathBuf> {
    let (target_dir, _lock) = lock_build_dir(root)?;
    let cache = target_dir.join("elf");
    let name = format!("{:016x}", config_hash(config));
    let elf = cache.join(format!("{name}.elf"));
    let built_at = std::fs::metadata(&elf).and_then(|m| m.modified()).ok();
    if let Some(t) = built_at
        && newest_source(root).is_some_and(|s| s < t)
    {
        return Ok(elf);
    }
    // The cached copy is dated from before the build, so that a source
    // edited while cargo runs makes it stale.
    let started = SystemTime::now();
    let mut cargo = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    cargo
        .current_dir(root)
        .args(["build", "--release", "--target-dir"])
        .arg(&target_dir)
        .env("CVM_H743_SCAN", config)
        .env_remove("CARGO_TARGET_DIR")
        .env_remove("CARGO_BUILD_TARGET")
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .stdout(Stdio::null());
    let status =
        crate::child::run_build(&mut cargo).context("running cargo to build the H743 firmware")?;
    if !status.success() {
        bail!(
            "building the H743 firmware with CVM_H743_SCAN=\"{config}\" failed (needs `rustup target add thumbv7em-none-eabihf`); see the cargo output above"
        );
    }
    let built = target_dir.join("thumbv7em-none-eabihf/release/cvm-fw");
    let tmp = cache.join(format!("{name}.elf.tmp"));
    std::fs::copy(&built, &tmp).with_context(|| format!("copying {}", built.display()))?;
    std::fs::File::options()
        .write(true)
        .open(&tmp)
        .and_then(|f| f.set_modified(started))
        .with_context(|| format!("dating {}", tmp.display()))?;
    std::fs::rename(&tmp, &elf).with_context(|| format!("renaming {}", tmp.display()))?;
    // The configuration beside its ELF, for whoever looks in the cache.
    let _ = std::fs::write(cache.join(format!("{name}.cfg")), format!("{config}\n"));
    Ok(elf)
}

/// The target folder of the chip model's firmware builds in the
/// repository `root`, `target/twin`, with the lock (`elf/.lock`) that
/// keeps concurrent builds from copying each other's ELF, held until the
/// returned file is dropped; seeded on first use
/// ([`seed_from_product_build`]).
pub fn lock_build_dir(root: &Path) -> Result<(PathBuf, std::fs::File)> {
    let target_dir = root.join("target/twin");
    let cache = target_dir.join("elf");
    std::fs::create_dir_all(&cache).with_context(|| format!("creating {}", cache.display()))?;
    let lock = std::fs::File::create(cache.join(".lock"))
        .with_context(|| format!("creating {}", cache.join(".lock").display()))?;
    lock.lock()
        .with_context(|| format!("locking {}", cache.join(".lock").display()))?;
    seed_from_product_build(root, &target_dir);
    Ok((target_dir, lock))
}

/// Fills an empty `target_dir` with the dependencies `cargo build
/// --release` compiled in the repository's own `target`: the same crates
/// in the same profile, only the firmware crate's `build.rs` reads
/// `CVM_H743_SCAN`. Cargo's fingerprints decide what is still fresh
/// (they hold no absolute path of the folder they were made in; `cp -a`
/// keeps the modification times they compare), so a stale or partial
/// copy costs a rebuild of what is stale, never a wrong ELF. The copy is
/// a convenience: on any failure the build simply starts cold.
fn seed_from_product_build(root: &Path, target_dir: &Path) {
    let product = root.join("target");
    let arch = "thumbv7em-none-eabihf";
    if target_dir.join(arch).exists() || !product.join(arch).join("release").is_dir() {
        return;
    }
    for (from, into) in [
        // The host side: build scripts and proc macros.
        (product.join("release"), target_dir.to_path_buf()),
        (product.join(arch).join("release"), target_dir.join(arch)),
    ] {
        if from.is_dir() && !into.join("release").exists() && std::fs::create_dir_all(&into).is_ok()
        {
            let _ = Command::new("cp")
                .arg("-a")
                .arg(&from)
                .arg(&into)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status();
        }
    }
}

/// Passes the model's standard error through as it comes, except its last
/// non-empty line (the JSON counters), which it returns unprinted so that
/// `dmap` can put its own messages before it.
fn pass_stderr(stderr: ChildStderr) -> std::thread::JoinHandle<String> {
    std::thread::spawn(move || {
        let mut held = String::new();
        let mut reader = BufReader::new(stderr);
        let mut line = Vec::new();
        while let Ok(n) = reader.read_until(b'\n', &mut line) {
            if n == 0 {
                break;
            }
            let text = String::from_utf8_lossy(&line);
            if text.trim().is_empty() {
                let _ = std::io::stderr().write_all(&line);
            } else {
                if !held.is_empty() {
                    let _ = writeln!(std::io::stderr(), "{held}");
                }
                held = text.trim_end().to_string();
            }
            line.clear();
        }
        held
    })
}

/// Runs the model on `elf` with the scan file `scan` (inside `dir`, removed
/// once the model is gone), handing the UART bytes to `out` and passing its
/// standard error through. Returns the model's JSON counters and their line
/// (the last of its standard error), which the caller prints; fails, after
/// printing that line, if the model fails or stops on something it does
/// not model.
pub fn run_model(
    root: &Path,
    elf: &Path,
    scan: &Path,
    dir: tempfile::TempDir,
    args: &TwinArgs,
    out: &mut dyn FnMut(&[u8]) -> Result<()>,
) -> Result<(serde_json::Value, String)> {
    let twin = root.join("host-tests/twin");
    let mut pythonpath = std::ffi::OsString::from(twin.as_os_str());
    if let Some(p) = std::env::var_os("PYTHONPATH").filter(|p| !p.is_empty()) {
        pythonpath.push(":");
        pythonpath.push(p);
    }
    let mut cmd = Command::new("python3");
    cmd.args(["-m", "h743twin"])
        .arg(elf)
        .arg("--scan")
        .arg(scan)
        .args(["--beam-us", &args.beam_us.to_string()])
        .args(["--settle-ms", &args.settle_ms.to_string()])
        .args(["--start-ms", &args.start_ms.to_string()])
        .args(["--scans", &args.parts.to_string()])
        .env("PYTHONPATH", pythonpath);
    for f in &args.faults {
        cmd.args(["--fault", f]);
    }
    if args.debugger {
        cmd.arg("--debugger");
    }
    args.link.apply(&mut cmd);
    // Killed and reaped on every way out, before its scan file is removed.
    let live = &args.link.live;
    cmd.stdin(if live.is_live() {
        Stdio::piped()
    } else {
        Stdio::null()
    })
    .stdout(Stdio::piped())
    .stderr(Stdio::piped());
    let model = crate::child::Supervised::spawn(&mut cmd, dir).context(
        "starting python3 (the chip model needs python3 with unicorn and pyelftools: scripts/setup.sh)",
    )?;
    let pipes = model
        .with_child(|c| (c.stdin.take(), c.stdout.take(), c.stderr.take()))
        .unwrap_or_default();
    if let Some(stdin) = pipes.0 {
        live.forward(stdin);
    }
    let (Some(mut stdout), Some(stderr)) = (pipes.1, pipes.2) else {
        bail!("the chip model's output pipes are missing");
    };
    let errors = pass_stderr(stderr);
    let mut buf = [0u8; 8192];
    loop {
        let n = match stdout.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e).context("reading the chip model's output"),
        };
        out(&buf[..n])?;
    }
    let status = model.wait().context("waiting for the chip model")?;
    drop(model);
    let last = errors.join().unwrap_or_default();
    let json: Option<serde_json::Value> = serde_json::from_str(&last)
        .ok()
        .filter(|v: &serde_json::Value| v.is_object());
    if let (Some(0), Some(j)) = (status.code(), &json)
        && j["status"] != "error"
    {
        return Ok((j.clone(), last));
    }
    // The model could not load the ELF or the scan: its one line is the
    // error.
    if status.code() == Some(4) && json.is_none() {
        bail!("{}", last.trim_start_matches("h743twin: "));
    }
    if !last.is_empty() {
        let _ = writeln!(std::io::stderr(), "{last}");
    }
    match (status.code(), json) {
        (_, Some(j)) if j["status"] == "error" => bail!(
            "the chip model stopped: {} (at {} ms of model time)",
            j["error"].as_str().unwrap_or("unknown error"),
            j["cycles"]
                .as_f64()
                .zip(j["clock_hz"].as_f64())
                .map_or("?".into(), |(c, hz)| fmt_num((c / hz * 1e3).round()))
        ),
        (Some(2), _) => bail!("the chip model refused its arguments; its message is above"),
        _ if last.contains("ModuleNotFoundError") => bail!(
            "the chip model failed ({status}): it needs python3 with unicorn 2.1.4 and pyelftools 0.33 (scripts/setup.sh installs them)"
        ),
        _ => bail!("the chip model failed ({status}); its message is above"),
    }
}

/// Refuses, before anything runs, an output over an input: `--pins` (a
/// file written) over the scan, `--flash`, `--requests`, `--calibration`
/// or `--elf`, and `--flash` (read and written back) over the others.
fn check_files(args: &TwinArgs) -> Result<()> {
    let mut inputs = vec![args.scan.as_path()];
    inputs.extend(args.link.requests.as_deref());
    inputs.extend(args.output.calibration.as_deref());
    inputs.extend(args.elf.as_deref());
    if let Some(flash) = &args.link.flash {
        crate::out::refuse_inputs(flash, &inputs)?;
    }
    if let Some(pins) = &args.pins.pins {
        crate::out::refuse_inputs(pins, &inputs)?;
        if let Some(flash) = &args.link.flash
            && crate::out::same_destination(pins, flash)
        {
            bail!(
                "--pins {} is the --flash file: refusing to overwrite it (choose another path)",
                pins.display()
            );
        }
    }
    Ok(())
}

pub fn run(args: &TwinArgs) -> Result<()> {
    run_to(args, &mut |bytes| crate::out::stdout(bytes))
}

/// [`run`] with the firmware's UART bytes handed to `out` as they come
/// (`dmap console` decodes them) instead of standard output.
pub fn run_to(args: &TwinArgs, out: &mut dyn FnMut(&[u8]) -> Result<()>) -> Result<()> {
    if !(args.beam_us.is_finite() && args.beam_us > 0.0) {
        bail!("--beam-us must be a positive number of microseconds");
    }
    if !(args.settle_ms.is_finite() && args.settle_ms >= 0.0) {
        bail!("--settle-ms must be a non-negative number of milliseconds");
    }
    if !(args.start_ms.is_finite() && args.start_ms >= 0.0) {
        bail!("--start-ms must be a non-negative number of milliseconds");
    }
    let root = args.repo.root()?;
    check_files(args)?;
    // Checked and locked before anything is read or built; written back
    // after the run.
    let flash = args.link.prepare_flash()?;
    // The emulated board's scan file: the same reading, validation,
    // settings and warnings as `dmap emulate` and `dmap stream`.
    let (run, emufile) =
        crate::emulate::resolved_board_file(&args.scan, &args.scoring, &args.output)?;
    let warnings = run.warnings;
    let header = ScanHeader::parse(&emufile).map_err(|e| anyhow::anyhow!(e.message()))?;
    let beams = u64::from(header.rows) * u64::from(header.cols);
    let mut faults_ms = 0.0;
    for f in &args.faults {
        faults_ms += check_fault(f, u64::from(header.rows), u64::from(header.cols))?;
    }
    // Read once: a pipe (`--requests <(...)`) cannot be read again.
    let requests = args.link.check(beams)?;
    check_model_time(
        beams,
        [args.start_ms, args.beam_us, faults_ms, args.settle_ms],
    )?;
    if header.rows % args.parts != 0 {
        bail!(
            "--parts {}: the scan's {} rows do not split into {} parts of equal rows",
            args.parts,
            header.rows,
            args.parts
        );
    }
    // Each part is one scan of the firmware.
    let part = ScanHeader {
        rows: header.rows / args.parts,
        ..header
    };
    let mut settings = run.settings;
    args.pins.apply(&mut settings)?;
    // The settings reach the firmware as a user's board holds them: in a
    // settings record in bank 2, for one ELF per compile-time
    // configuration. When bank 2 is the user's (`--flash`), they are
    // compiled in instead.
    let record = match &args.link.flash {
        Some(_) => None,
        None => Some(crate::twin::record::settings_record(&settings, &part)?),
    };
    let config = match &record {
        Some(_) => h743_build_config(&part)?,
        None => h743_config(&part)? + &crate::twin::pins::build_keys(&settings),
    };
    let file = twin_file(&header, &emufile)?;
    drop(emufile);
    for w in &warnings {
        crate::out::warn(w);
    }
    let elf = match &args.elf {
        Some(p) => p.clone(),
        None => build_elf_in(&root, &config)?,
    };
    let image = crate::elf::read(&elf)?;
    check_built_for(&elf, &image, &config)?;
    drop(image);
    let dir = tempfile::Builder::new()
        .prefix("dmap-twin-")
        .tempdir()
        .context("creating a temporary directory")?;
    let scan_path = dir.path().join("scan.twin");
    std::fs::write(&scan_path, &file)
        .with_context(|| format!("writing {}", scan_path.display()))?;
    let planned = args.link.planned(beams)?;
    let mut link =
        args.link
            .for_model(&planned, requests.as_deref(), dir.path(), flash.as_ref())?;
    if let Some(image) = &record {
        let bank = dir.path().join("bank2.bin");
        std::fs::write(&bank, image).with_context(|| format!("writing {}", bank.display()))?;
        link.flash = Some(bank);
    }
    let for_model = TwinArgs {
        link,
        ..args.clone()
    };
    let mut uart = Vec::new();
    let ran = run_model(&root, &elf, &scan_path, dir, &for_model, &mut |bytes| {
        uart.extend_from_slice(bytes);
        out(bytes)
    });
    // The bank as the run left it, even a failed run's (the model saves it
    // whatever stopped it).
    let saved = flash.as_ref().map_or(Ok(()), |f| f.write_back());
    let (stats, line) = ran?;
    saved?;
    crate::twin::pins::report(&args.pins, &stats, &uart)?;
    for l in crate::sensor::twin::summary(&planned, &uart) {
        let _ = writeln!(std::io::stderr(), "dmap: {l}");
    }
    // The counters stay the last line the model prints, before dmap's
    // own verdict.
    let _ = writeln!(std::io::stderr(), "{line}");
    if let Some(n) = args.link.power_cut
        && stats["status"] != "power cut"
    {
        bail!(
            "--power-cut {n}: no power cut happened: the run made {} flash operations (erases and programs)",
            stats["flash_operations"]
        );
    }
    if stats["status"] == "time" {
        bail!(
            "the firmware sent no complete end line within --settle-ms {} after the last beam: the scan did not finish",
            fmt_num(args.settle_ms)
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_hash_is_stable() {
        // FNV-1a 64 check values: the cache names must not change between
        // toolchains.
        assert_eq!(config_hash(""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(config_hash("a"), 0xaf63_dc4c_8601_ec8c);
    }
}
