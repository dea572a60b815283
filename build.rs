//! Picks the memory map and linker arguments for the selected board.
//!
//! cortex-m-rt's `link.x` does `INCLUDE memory.x`; each board's map is
//! `boards/<board>/memory.x` and only that folder goes on the linker's
//! search path. (There is deliberately no `memory.x` at the package root:
//! the linker looks in its working directory, the root, before the search
//! path, so a root file would shadow the other board's map.)
//! `defmt.x` is only passed when defmt is linked (the H743 board).

use std::env;
use std::fmt::Write as _;
use std::path::PathBuf;

fn main() {
    let h743 = env::var_os("CARGO_FEATURE_H743").is_some();
    let emulated = env::var_os("CARGO_FEATURE_EMULATED").is_some();
    let board = match (h743, emulated) {
        (true, false) => "h743",
        (false, true) => "mps2-an386",
        // main.rs turns these into a clear compile_error!; keep the build
        // script quiet so that message is the one the user sees.
        _ => return,
    };

    let root =
        PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let dir = root.join("boards").join(board);
    println!("cargo:rustc-link-search={}", dir.display());
    println!("cargo:rerun-if-changed=boards");
    println!("cargo:rerun-if-changed=build.rs");

    if h743 {
        let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
        let spec = env::var("CVM_H743_SCAN").unwrap_or_default();
        let cal = env::var_os("CVM_H743_CALIBRATION").map(PathBuf::from);
        if let Some(path) = &cal {
            println!("cargo:rerun-if-changed={}", path.display());
        }
        let consts = match h743_scan(&spec, cal.as_deref()) {
            Ok(c) => c,
            Err(e) => {
                println!("cargo:warning=CVM_H743_SCAN: {e}");
                std::process::exit(1);
            }
        };
        std::fs::write(out.join("h743_scan.rs"), consts).expect("writing OUT_DIR/h743_scan.rs");
        println!("cargo:rerun-if-env-changed=CVM_H743_SCAN");
        println!("cargo:rerun-if-env-changed=CVM_H743_CALIBRATION");
    }

    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    if h743 {
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
}

/// The H743 board's scan configuration as Rust constants (included by
/// `src/config.rs`). `CVM_H743_SCAN` overrides the defaults with
/// space-separated `key=value` pairs; `dmap twin` sets it to the
/// configuration of the scan it runs. See docs/firmware.md.
/// Keys: j1, j2, cols, rows, kernels (paper|square), b, weights
/// (uniform|unit), normalise, threshold, pthr (the power channel's
/// threshold, a contrast; `inf` turns it off), sthr (the spread channel's,
/// a share of the power; `inf`, the default, turns it off), scores, max_defect_lines,
/// fs (full scale), fw (the version in the header), reject (part|row:
/// REJECT's mode), pulse_us (its pulse width; 0 in part mode: held),
/// row_delay (row mode: rows between the closing row and the pulse).
///
/// `CVM_H743_CALIBRATION` names a calibration file (`dmap calibrate`): its
/// thresholds are compiled in (the spread channel's from version 5; off
/// before), after checking that it was made for this very configuration
/// (geometry, kernels, weights, normalisation, full scale); `threshold`,
/// `pthr` and `sthr` may then not be given.
fn h743_scan(spec: &str, calibration: Option<&std::path::Path>) -> Result<String, String> {
    let mut scan = Scan::parse(spec)?;
    if let Some(path) = calibration {
        if spec.split_whitespace().any(|p| {
            ["threshold=", "pthr=", "sthr="]
                .iter()
                .any(|k| p.starts_with(k))
        }) {
            return Err(
                "threshold, pthr and sthr come from CVM_H743_CALIBRATION; do not give them too"
                    .into(),
            );
        }
        let config = serde_json::json!({
            "j1": scan.j1,
            "j2": scan.j2,
            "kernels": scan.kernels,
            "b": scan.resolved_b(),
            "weights": scan.weights,
            "normalise": scan.normalise,
            "full_scale": scan.full_scale,
        });
        (scan.threshold, scan.pthr, scan.sthr) = calibration_thresholds(path, &config)?;
    }
    scan.check_thresholds()?;
    Ok(scan.rust(spec))
}

/// The values of `CVM_H743_SCAN`, each at its default until given.
struct Scan {
    j1: u8,
    j2: u8,
    cols: usize,
    rows: u32,
    kernels: String,
    b: Option<u8>,
    weights: String,
    normalise: bool,
    threshold: f64,
    pthr: f64,
    sthr: f64,
    scores: bool,
    max_defect_lines: u16,
    full_scale: u16,
    fw: Option<String>,
    reject_row: bool,
    pulse_us: u32,
    row_delay: u32,
}

fn num<T: std::str::FromStr>(k: &str, v: &str) -> Result<T, String> {
    v.parse()
        .map_err(|_| format!("{k}={v}: not a valid number"))
}

fn flag(k: &str, v: &str) -> Result<bool, String> {
    match v {
        "true" => Ok(true),
        "false" => Ok(false),
        _ => Err(format!("{k}={v}: expected true or false")),
    }
}

impl Scan {
    fn parse(spec: &str) -> Result<Scan, String> {
        let mut s = Scan {
            j1: 15,
            j2: 15,
            cols: 300,
            rows: 200,
            kernels: "paper".into(),
            b: None,
            weights: "uniform".into(),
            normalise: true,
            threshold: 0.5,
            pthr: 0.1,
            sthr: f64::INFINITY,
            scores: true,
            max_defect_lines: 0,
            full_scale: u16::MAX,
            fw: None,
            reject_row: false,
            pulse_us: 0,
            row_delay: 0,
        };
        for pair in spec.split_whitespace() {
            let (k, v) = pair
                .split_once('=')
                .ok_or_else(|| format!("{pair:?} is not key=value"))?;
            match k {
                "j1" => s.j1 = num(k, v)?,
                "j2" => s.j2 = num(k, v)?,
                "cols" => s.cols = num(k, v)?,
                "rows" => s.rows = num(k, v)?,
                "kernels" if v == "paper" || v == "square" => s.kernels = v.into(),
                "b" => s.b = Some(num(k, v)?),
                "weights" if v == "uniform" || v == "unit" => s.weights = v.into(),
                "normalise" => s.normalise = flag(k, v)?,
                "threshold" => s.threshold = num(k, v)?,
                "pthr" => s.pthr = num(k, v)?,
                "sthr" => s.sthr = num(k, v)?,
                "scores" => s.scores = flag(k, v)?,
                "max_defect_lines" => s.max_defect_lines = num(k, v)?,
                "fs" => s.full_scale = num(k, v)?,
                "reject" if v == "part" || v == "row" => s.reject_row = v == "row",
                "pulse_us" => s.pulse_us = num(k, v)?,
                "row_delay" => s.row_delay = num(k, v)?,
                // The version the header announces (`dmap twin` passes the
                // host's, so that its output compares byte for byte).
                "fw" if !v.is_empty()
                    && v.len() <= 32
                    && v.bytes()
                        .all(|b| b.is_ascii_graphic() && b != b',' && b != b'*') =>
                {
                    s.fw = Some(v.into())
                }
                _ => return Err(format!("unknown key or value in {pair:?}")),
            }
        }
        if !(1..=16).contains(&s.j1) || !(1..=16).contains(&s.j2) {
            return Err(format!("j1={} j2={}: each must be 1..=16", s.j1, s.j2));
        }
        if s.cols == 0 || s.rows == 0 {
            return Err("cols and rows must be at least 1".into());
        }
        Ok(s)
    }

    /// `b` as the kernels take it: the paper kernels' bound (0: the
    /// default), or the square kernels' size (default: the map's).
    fn resolved_b(&self) -> u8 {
        match (self.kernels.as_str(), self.b) {
            ("paper", b) => b.unwrap_or(0),
            (_, Some(k)) => k,
            (_, None) => self.j1.max(self.j2) - 1,
        }
    }

    fn check_thresholds(&self) -> Result<(), String> {
        let (t, p, s) = (self.threshold, self.pthr, self.sthr);
        if !t.is_finite() || t < 0.0 {
            return Err(format!("threshold={t}: must be finite and >= 0"));
        }
        if p.is_nan() || p < 0.0 {
            return Err(format!("pthr={p}: must be >= 0 (inf: off)"));
        }
        if s.is_nan() || s < 0.0 {
            return Err(format!("sthr={s}: must be >= 0 (inf: off)"));
        }
        Ok(())
    }

    /// The constants `src/config.rs` includes, and the `.cvm_config`
    /// section: what the ELF was built for, in a section that is not loaded
    /// (no flash), which `dmap twin --elf` reads to refuse a run it does
    /// not fit.
    fn rust(&self, spec: &str) -> String {
        let Scan {
            j1, j2, cols, rows, ..
        } = *self;
        let (threshold, pthr, sthr) = (self.threshold, self.pthr, self.sthr);
        let (scores, max_defect_lines, full_scale) =
            (self.scores, self.max_defect_lines, self.full_scale);
        let (kernels, weights, normalise) = (&self.kernels, &self.weights, self.normalise);
        let section_b = self.resolved_b();
        let built_for = format!(
            "j1={j1} j2={j2} cols={cols} rows={rows} kernels={kernels} b={section_b} weights={weights} normalise={normalise} threshold={threshold:?} pthr={pthr:?} sthr={sthr:?} scores={scores} max_defect_lines={max_defect_lines} fs={full_scale}"
        );
        let kernels = match (kernels.as_str(), self.b) {
            ("paper", b) => format!("Kernels::Paper {{ bmax: {} }}", b.unwrap_or(0)),
            (_, Some(k)) => format!("Kernels::Square {{ kmax: {k} }}"),
            (_, None) => "Kernels::square_default(GEOMETRY)".into(),
        };
        let weights = if weights == "unit" { "Unit" } else { "Uniform" };
        let f = |x: f64| {
            if x.is_infinite() {
                "f64::INFINITY".to_string()
            } else {
                format!("{x:?}")
            }
        };
        let mut s = String::new();
        let _ = writeln!(s, "// Generated by build.rs from CVM_H743_SCAN={spec:?}.");
        let _ = writeln!(s, "pub const J1: u8 = {j1};\npub const J2: u8 = {j2};");
        let _ = writeln!(
            s,
            "pub const COLS: usize = {cols};\npub const ROWS: u32 = {rows};"
        );
        let _ = writeln!(s, "pub const KERNELS: Kernels = {kernels};");
        let _ = writeln!(s, "pub const WEIGHTS: Weights = Weights::{weights};");
        let _ = writeln!(s, "pub const NORMALISE: bool = {normalise};");
        let _ = writeln!(s, "pub const THRESHOLD_UNITS: f64 = {threshold:?};");
        let _ = writeln!(s, "pub const POWER_THRESHOLD_UNITS: f64 = {};", f(pthr));
        let _ = writeln!(s, "pub const SPREAD_THRESHOLD_UNITS: f64 = {};", f(sthr));
        let _ = writeln!(s, "pub const SCORES: bool = {scores};");
        let _ = writeln!(
            s,
            "pub const MAX_DEFECT_LINES_PER_ROW: u16 = {max_defect_lines};"
        );
        let _ = writeln!(s, "pub const FULL_SCALE: u16 = {full_scale};");
        let _ = writeln!(s, "pub const REJECT_ROW: bool = {};", self.reject_row);
        let _ = writeln!(s, "pub const PULSE_US: u32 = {};", self.pulse_us);
        let _ = writeln!(s, "pub const ROW_DELAY: u32 = {};", self.row_delay);
        let _ = writeln!(
            s,
            "pub const FIRMWARE_VERSION_OVERRIDE: Option<&str> = {:?};",
            self.fw
        );
        let _ = writeln!(
            s,
            r##"core::arch::global_asm!(r#".pushsection .cvm_config,"",%progbits"#, r#".ascii "{built_for}""#, ".popsection");"##
        );
        s
    }
}

/// The CVM, power and spread thresholds (distance units, contrast, share
/// of the power) of a calibration file, refused unless it is a `dmap
/// calibrate` file of version 2 to 5 (the same thresholds; 3 is the
/// streaming rule's, 4 adds the tail fit and the rule's name, 5 the spread
/// channel, off in the earlier ones) made for `config`.
fn calibration_thresholds(
    path: &std::path::Path,
    config: &serde_json::Value,
) -> Result<(f64, f64, f64), String> {
    let p = path.display();
    let text = std::fs::read_to_string(path).map_err(|e| format!("{p}: {e}"))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| format!("{p}: not JSON: {e}"))?;
    if v["format"] != "dmap-calibration" {
        return Err(format!("{p}: not a dmap calibration file"));
    }
    let version = v["version"].as_u64().unwrap_or(0);
    if !(2..=5).contains(&version) {
        return Err(format!(
            "{p}: calibration file version {} (this firmware reads 2 to 5; run dmap calibrate again)",
            v["version"]
        ));
    }
    let Some(fields) = config.as_object() else {
        return Err("internal: configuration is not an object".into());
    };
    for (key, want) in fields {
        let got = &v["config"][key];
        if got != want {
            return Err(format!(
                "{p}: made for {key}={got}, this build has {key}={want} (CVM_H743_SCAN)"
            ));
        }
    }
    let units = |channel: &str| {
        v["channels"][channel]["threshold"]
            .as_f64()
            .filter(|t| t.is_finite() && *t >= 0.0)
            .ok_or_else(|| {
                format!("{p}: channels.{channel}.threshold missing or not a number >= 0")
            })
    };
    // Before version 5 the file has no spread channel: off.
    let spread = if version >= 5 {
        units("spread")?
    } else {
        f64::INFINITY
    };
    Ok((units("cvm")?, units("power")?, spread))
}
