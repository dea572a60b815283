//! `dmap emulate`: the firmware itself, built for the emulated board, run
//! under QEMU (`mps2-an386`) over a scan. The scan is written in the
//! board's input format (`cvm_fw_app::emufile`), the firmware reads it over
//! semihosting, and exactly the bytes its UART sends are copied to stdout.
//! The firmware's own diagnostics (counts, instructions per beam) go to
//! stderr.

use crate::npy::{Scan, read_scan};
use crate::options::{OutputArgs, ScoringArgs};
use crate::settings::{RunSettings, resolve};
use anyhow::{Context, Result, bail};
use clap::Args;
use cvm_fw_app::emufile::ScanHeader;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// Most columns the emulated board's row buffers hold.
pub const MAX_COLS: usize = 1024;

#[derive(Args, Clone, Debug)]
pub struct EmulateArgs {
    /// Scan .npy, shape (rows, cols, J1, J2), integer counts 0..=65535
    pub scan: PathBuf,
    #[command(flatten)]
    pub scoring: ScoringArgs,
    #[command(flatten)]
    pub output: OutputArgs,
    /// Firmware ELF to run (default: build the emulated board at the repository root)
    #[arg(long)]
    pub elf: Option<PathBuf>,
    /// Count instructions (QEMU -icount shift=0); the firmware reports instructions per beam on stderr
    #[arg(long)]
    pub icount: bool,
    #[command(flatten)]
    pub repo: crate::repo::RepoArgs,
}

/// [`build_elf_in`] the repository [`crate::repo::find`] finds.
pub fn build_elf() -> Result<PathBuf> {
    build_elf_in(&crate::repo::find(None)?)
}

/// Builds the emulated board of the repository `root` (incremental, so
/// cheap when up to date) into its own target directory, apart from the
/// H743 build. The build ends with `dmap` ([`crate::child::run_build`]).
pub fn build_elf_in(root: &Path) -> Result<PathBuf> {
    let target_dir = root.join("target/emulated");
    let mut cargo = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    // Its own package (`boards/mps2-an386`), built where its memory map is.
    cargo
        .current_dir(root.join("boards/mps2-an386"))
        .args(["build", "--release", "--target-dir"])
        .arg(&target_dir)
        .env_remove("CARGO_TARGET_DIR")
        .env_remove("CARGO_BUILD_TARGET")
        .env_remove("RUSTFLAGS")
        .stdout(Stdio::null());
    let status = crate::child::run_build(&mut cargo)
        .context("running cargo to build the emulated firmware")?;
    if !status.success() {
        bail!(
            "building the emulated firmware failed (needs `rustup target add thumbv7em-none-eabihf`); \
             see the cargo output above"
        );
    }
    Ok(target_dir.join("thumbv7em-none-eabihf/release/cvm-fw"))
}

/// The scan file the emulated board reads; the warnings about the
/// configuration (as `dmap stream` gives them) go to stderr.
pub fn scan_file(args: &EmulateArgs) -> Result<Vec<u8>> {
    let (file, warnings) = scan_file_and_warnings(args)?;
    for w in &warnings {
        crate::out::warn(w);
    }
    Ok(file)
}

/// [`scan_file`], with the warnings returned instead of printed, for the
/// caller to print once the run has succeeded.
pub fn scan_file_and_warnings(args: &EmulateArgs) -> Result<(Vec<u8>, Vec<String>)> {
    let (run, file) = resolved_board_file(&args.scan, &args.scoring, &args.output)?;
    if run.settings.outputs != cvm_core::settings::Outputs::DEFAULT {
        bail!(
            "the emulated board's scan file carries thr, pthr, sthr, scores and dcap; the verdict's and the outputs' settings (area, peak, miss, misp, mode, pulse, delay) are not in it"
        );
    }
    Ok((file, run.warnings))
}

/// The scan at `path` read, its settings resolved with the same
/// validation, settings and warnings as `dmap stream`, and the emulated
/// board's scan file of it (`dmap emulate`'s input, and `dmap twin`'s
/// before it becomes the chip model's).
pub fn resolved_board_file(
    path: &Path,
    scoring: &crate::options::ScoringArgs,
    output: &crate::options::OutputArgs,
) -> Result<(RunSettings, Vec<u8>)> {
    let scan = read_scan(path)?;
    let (j1, j2) = (scan.geometry.j1(), scan.geometry.j2());
    let run = resolve(scoring, output, (j1, j2), (scan.rows, scan.cols))?;
    let file = board_file(path, &scan, &run)?;
    Ok((run, file))
}

/// The emulated board's scan file of `scan` (read from `path`) under the
/// settings `run`: its header carries the configuration and thresholds
/// the firmware starts from, then the samples.
pub fn board_file(path: &Path, scan: &Scan, run: &RunSettings) -> Result<Vec<u8>> {
    if scan.cols > MAX_COLS {
        bail!(
            "scan has {} columns; the emulated board holds at most {MAX_COLS}",
            scan.cols
        );
    }
    if scan.rows == 0 || scan.rows > u32::MAX as usize {
        bail!("scan has {} rows", scan.rows);
    }
    let settings = &run.settings;
    // The version a host run announces (the board's own start).
    let version = cvm_core::VERSION.as_bytes();
    let mut v = [0u8; cvm_core::protocol::MAX_FW];
    if version.len() > v.len() {
        bail!("firmware version string longer than {} bytes", v.len());
    }
    v[..version.len()].copy_from_slice(version);
    let header = ScanHeader {
        config: run.config,
        cols: settings.cols,
        rows: scan.rows as u32,
        threshold_units: run.threshold_units,
        power_threshold_units: run.power_threshold_units,
        spread_threshold_units: run.spread_threshold_units,
        scores: settings.scores,
        max_defect_lines_per_row: settings.max_defect_lines_per_row,
        version_len: version.len() as u8,
        version: v,
    };
    let data = scan
        .to_u16()
        .with_context(|| format!("{}", path.display()))?;
    let mut out = Vec::with_capacity(cvm_fw_app::emufile::HEADER_LEN + 2 * data.len());
    out.extend_from_slice(&header.encode());
    // Native samples, as the H743's 16-bit SPI frames leave them in memory.
    for s in data {
        out.extend_from_slice(&s.to_le_bytes());
    }
    Ok(out)
}

/// Runs QEMU on `elf` with `scan_path`, copying the UART to `out`
/// (standard output if `None`). `dir`, if given, is removed once QEMU is
/// gone. QEMU never outlives the call: on every way out (an error writing
/// the output, a closed pipe, a panic, a termination signal) it is killed
/// and reaped.
pub fn run_qemu(
    elf: &Path,
    scan_path: &Path,
    icount: bool,
    dir: Option<tempfile::TempDir>,
    out: &mut dyn FnMut(&[u8]) -> Result<()>,
) -> Result<()> {
    let path = scan_path.to_str().context("scan file path is not UTF-8")?;
    if path.contains(' ') {
        bail!(
            "scan file path {path:?} contains a space, which the semihosting command line cannot carry"
        );
    }
    // QEMU option values escape commas by doubling them.
    let semihosting = format!(
        "enable=on,target=native,arg=cvm-fw,arg={}",
        path.replace(',', ",,")
    );
    let mut cmd = Command::new("qemu-system-arm");
    cmd.args([
        "-M",
        "mps2-an386",
        "-nographic",
        "-monitor",
        "none",
        "-serial",
        "stdio",
    ])
    .args(["-semihosting-config", &semihosting])
    .arg("-kernel")
    .arg(elf)
    .stdin(Stdio::null())
    .stdout(Stdio::piped())
    .stderr(Stdio::inherit());
    if icount {
        cmd.args(["-icount", "shift=0"]);
    }
    // Killed and reaped on every way out, before its scan file is removed.
    let qemu = crate::child::Supervised::spawn(&mut cmd, dir)
        .context("starting qemu-system-arm (install it: apt-get install -y qemu-system-arm)")?;
    let stdout = qemu
        .with_child(|c| c.stdout.take())
        .flatten()
        .context("qemu stdout")?;
    copy_uart(stdout, out)?;
    // The UART closed: QEMU's status.
    let status = qemu.wait().context("waiting for qemu-system-arm")?;
    if !status.success() {
        bail!("the emulated firmware failed ({status}); its message, if any, is above");
    }
    Ok(())
}

fn copy_uart(mut uart: impl Read, out: &mut dyn FnMut(&[u8]) -> Result<()>) -> Result<()> {
    let mut buf = [0u8; 8192];
    loop {
        let n = match uart.read(&mut buf) {
            Ok(0) => return Ok(()),
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e).context("reading the emulated UART"),
        };
        out(&buf[..n])?;
    }
}

pub fn run(args: &EmulateArgs) -> Result<()> {
    let (file, warnings) = scan_file_and_warnings(args)?;
    let elf = match &args.elf {
        Some(p) => p.clone(),
        None => build_elf_in(&args.repo.root()?)?,
    };
    // QEMU given a damaged ELF dumps its registers, or waits forever.
    crate::elf::read(&elf)?;
    let dir = tempfile::Builder::new()
        .prefix("dmap-emulate-")
        .tempdir()
        .context("creating a temporary directory")?;
    let scan_path = dir.path().join("scan.cvmscan");
    std::fs::write(&scan_path, &file)
        .with_context(|| format!("writing {}", scan_path.display()))?;
    run_qemu(&elf, &scan_path, args.icount, Some(dir), &mut |bytes| {
        crate::out::stdout(bytes)
    })?;
    for w in &warnings {
        crate::out::warn(w);
    }
    Ok(())
}
