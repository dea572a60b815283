//! `dmap emulate`: the firmware itself, built for the emulated board, run
//! under QEMU (`mps2-an386`) over a scan. The scan is written in the
//! board's input format (`cvm_fw_app::emufile`), the firmware reads it over
//! semihosting, and exactly the bytes its UART sends are copied to stdout.
//! The firmware's own diagnostics (counts, instructions per beam) go to
//! stderr.

use crate::npy::read_scan;
use crate::options::ScoringArgs;
use crate::stream::OutputArgs;
use anyhow::{Context, Result, bail};
use clap::Args;
use cvm_fw_app::emufile::ScanHeader;
use std::io::{Read, Write};
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
}

/// The repository root (this crate lives in host-tests/dmap).
fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Builds the emulated board (incremental, so cheap when up to date) into
/// its own target directory, apart from the H743 build.
pub fn build_elf() -> Result<PathBuf> {
    let root = repo_root();
    let target_dir = root.join("target/emulated");
    let status = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()))
        .current_dir(&root)
        .args([
            "build",
            "--release",
            "--no-default-features",
            "--features",
            "emulated",
            "--target-dir",
        ])
        .arg(&target_dir)
        .env_remove("CARGO_TARGET_DIR")
        .env_remove("CARGO_BUILD_TARGET")
        .env_remove("RUSTFLAGS")
        .stdout(Stdio::null())
        .status()
        .context("running cargo to build the emulated firmware")?;
    if !status.success() {
        bail!(
            "building the emulated firmware failed (needs `rustup target add thumbv7em-none-eabihf`); \
             see the cargo output above"
        );
    }
    Ok(target_dir.join("thumbv7em-none-eabihf/release/cvm-fw"))
}

/// The scan file the emulated board reads.
pub fn scan_file(args: &EmulateArgs) -> Result<Vec<u8>> {
    let scan = read_scan(&args.scan)?;
    let (j1, j2) = (scan.geometry.j1(), scan.geometry.j2());
    let scorer = args.scoring.scorer(j1, j2)?;
    // Same validation and settings as `dmap stream`.
    let settings = args.output.settings(&scorer, scan.cols)?;
    if scan.cols > MAX_COLS {
        bail!(
            "scan has {} columns; the emulated board holds at most {MAX_COLS}",
            scan.cols
        );
    }
    if scan.rows == 0 || scan.rows > u32::MAX as usize {
        bail!("scan has {} rows", scan.rows);
    }
    let version = settings.firmware_version.as_bytes();
    let mut v = [0u8; cvm_core::protocol::MAX_FW];
    if version.len() > v.len() {
        bail!("firmware version string longer than {} bytes", v.len());
    }
    v[..version.len()].copy_from_slice(version);
    let header = ScanHeader {
        config: args.scoring.core_config(j1, j2)?,
        cols: settings.cols,
        rows: scan.rows as u32,
        threshold_units: args.output.threshold,
        scores: settings.scores,
        max_defect_lines_per_row: settings.max_defect_lines_per_row,
        version_len: version.len() as u8,
        version: v,
    };
    let data = scan
        .to_u16()
        .with_context(|| format!("{}", args.scan.display()))?;
    let mut out = Vec::with_capacity(cvm_fw_app::emufile::HEADER_LEN + 2 * data.len());
    out.extend_from_slice(&header.encode());
    for s in data {
        out.extend_from_slice(&s.to_be_bytes());
    }
    Ok(out)
}

/// Runs QEMU on `elf` with `scan_path`, copying the UART to `out`.
pub fn run_qemu(elf: &Path, scan_path: &Path, icount: bool, out: &mut impl Write) -> Result<()> {
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
    let mut child = cmd
        .spawn()
        .context("starting qemu-system-arm (install it: apt-get install -y qemu-system-arm)")?;
    let mut stdout = child.stdout.take().context("qemu stdout")?;
    let mut buf = [0u8; 8192];
    loop {
        let n = stdout.read(&mut buf).context("reading the emulated UART")?;
        if n == 0 {
            break;
        }
        out.write_all(&buf[..n]).context("writing to stdout")?;
    }
    out.flush().context("writing to stdout")?;
    let status = child.wait().context("waiting for qemu-system-arm")?;
    if !status.success() {
        bail!("the emulated firmware failed ({status}); its message, if any, is above");
    }
    Ok(())
}

pub fn run(args: &EmulateArgs) -> Result<()> {
    let file = scan_file(args)?;
    let elf = match &args.elf {
        Some(p) => p.clone(),
        None => build_elf()?,
    };
    if !elf.is_file() {
        bail!("firmware ELF {} not found", elf.display());
    }
    let dir = std::env::temp_dir().join(format!("dmap-emulate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let scan_path = dir.join("scan.cvmscan");
    std::fs::write(&scan_path, &file)
        .with_context(|| format!("writing {}", scan_path.display()))?;
    let result = run_qemu(&elf, &scan_path, args.icount, &mut std::io::stdout().lock());
    let _ = std::fs::remove_dir_all(&dir);
    result
}
