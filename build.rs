//! The H743 firmware's build: its scan configuration from `CVM_H743_SCAN`
//! as Rust constants, and the linker arguments. cortex-m-rt's `link.x`
//! does `INCLUDE memory.x`, which the linker finds in its working
//! directory, the package's root (the emulated board is a package of its
//! own, `boards/mps2-an386`, with its map beside it). `defmt.x` places
//! the defmt log strings.

use cvm_core::command::{Capacity, Key, Kind};
use cvm_core::{Config, Geometry, Kernels, RejectMode, Scorer, Settings, Weights, power, spread};
use std::env;
use std::fmt::Write as _;
use std::path::PathBuf;

fn main() {
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let spec = env::var("CVM_H743_SCAN").unwrap_or_default();
    let consts = match h743_scan(&spec) {
        Ok(c) => c,
        Err(e) => {
            println!("cargo:warning=CVM_H743_SCAN: {e}");
            std::process::exit(1);
        }
    };
    std::fs::write(out.join("h743_scan.rs"), consts).expect("writing OUT_DIR/h743_scan.rs");
    println!("cargo:rerun-if-env-changed=CVM_H743_SCAN");
    // Named so that a build that still sets it fails instead of
    // silently compiling other thresholds than the file's.
    println!("cargo:rerun-if-env-changed=CVM_H743_CALIBRATION");
    if env::var_os("CVM_H743_CALIBRATION").is_some() {
        println!(
            "cargo:warning=CVM_H743_CALIBRATION is no longer read: give the calibration's thr, pthr and sthr in CVM_H743_SCAN (`dmap calibrate` prints them), or set them on the board (`dmap sensor set`, `save`)"
        );
        std::process::exit(1);
    }
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}

/// The H743 board's scan configuration as Rust constants (included by
/// `src/config.rs`). `CVM_H743_SCAN` overrides the defaults with
/// space-separated `key=value` pairs; `dmap twin` sets it to the
/// configuration of the scan it runs. See docs/firmware.md.
///
/// The build's own keys: j1, j2, cols and rows (the capacity, and the
/// defaults of the settings `cols` and `rows`), kernels (paper|square), b,
/// weights (uniform|unit), normalise (true|false), fs (full scale), fw
/// (the version in the header). Every other key is a runtime setting's
/// default, by its name and in its unit on the wire (`cvm_core::settings`'s
/// table: `thr`, `pthr`, `sthr`, `scores`, `dcap`, `area`, `peak`, `miss`,
/// `misp`, `mode`, `pulse`, `delay`, `ready`, `reject`).
fn h743_scan(spec: &str) -> Result<String, String> {
    Scan::parse(spec)?.rust(spec)
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
    full_scale: u16,
    fw: Option<String>,
    /// The runtime settings given, in the order given (a later one wins).
    set: Vec<(Key, u32)>,
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

/// The spelling a key had before the settings got one name and one unit
/// everywhere, and what to write now.
fn renamed(k: &str, v: &str) -> Option<&'static str> {
    Some(match k {
        "threshold" => "thr (an integer, as the header's thr: the magnitude times 2^q)",
        "max_defect_lines" => "dcap",
        "reject" if v == "part" || v == "row" => "mode=part|row (reject= is REJECT's level: low)",
        "pulse_us" => "pulse",
        "row_delay" => "delay",
        _ => return None,
    })
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
            full_scale: u16::MAX,
            fw: None,
            set: Vec::new(),
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
                "fs" => s.full_scale = num(k, v)?,
                // The version the header announces (`dmap twin` passes the
                // host's, so that its output compares byte for byte).
                "fw" if !v.is_empty()
                    && v.len() <= 32
                    && v.bytes()
                        .all(|b| b.is_ascii_graphic() && b != b',' && b != b'*') =>
                {
                    s.fw = Some(v.into())
                }
                _ => {
                    if let Some(now) = renamed(k, v) {
                        return Err(format!("{pair}: write {now} instead"));
                    }
                    let key = Key::from_name(k.as_bytes())
                        .ok_or_else(|| format!("unknown key or value in {pair:?}"))?;
                    let value = key.decode(v.as_bytes()).ok_or_else(|| {
                        format!(
                            "{pair}: not a value of {k} ({}, as on the wire)",
                            key.unit()
                        )
                    })?;
                    s.set.push((key, value));
                }
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

    /// The scorer's configuration, as `src/config.rs` builds it.
    fn config(&self) -> Result<Config, String> {
        let geometry = Geometry::new(self.j1, self.j2).map_err(|e| format!("{e:?}"))?;
        let kernels = match self.kernels.as_str() {
            "paper" => Kernels::Paper {
                bmax: self.resolved_b(),
            },
            _ => Kernels::Square {
                kmax: self.resolved_b(),
            },
        };
        let weights = if self.weights == "unit" {
            Weights::Unit
        } else {
            Weights::Uniform
        };
        Ok(Config {
            geometry,
            kernels,
            weights,
            normalise: self.normalise,
            full_scale: self.full_scale,
        })
    }

    /// The runtime settings' defaults: the firmware's (threshold 0.5 in
    /// distance units, a power contrast of 0.1, the spread channel off,
    /// score lines on, no `D` lines, the verdict's and outputs' defaults),
    /// then the given keys, each checked as the board checks a `set`.
    fn settings(&self, scorer: &Scorer) -> Result<Settings, String> {
        let mut s = Settings::new(
            self.cols as u32,
            self.rows,
            scorer.threshold_from_units(0.5),
            power::threshold_from_units(0.1),
        );
        s.scores = true;
        let cap = Capacity {
            max_cols: u16::try_from(self.cols).unwrap_or(u16::MAX),
            max_rows: u16::MAX,
            max_dcap: u16::MAX,
            max_pulse_us: u32::MAX,
        };
        for &(key, v) in &self.set {
            let (lo, hi) = key.range(&cap);
            if v < lo || v > hi || !key.set(&mut s, v) {
                return Err(format!("{}={v}: out of range {lo}..={hi}", key.name()));
            }
            if let Some(max) = key.off_above()
                && v > max
                && v != u32::MAX
            {
                return Err(format!(
                    "{}={v}: above {max} the channel is off; write {}=4294967295",
                    key.name(),
                    key.name()
                ));
            }
        }
        if cvm_core::command::conflict(&s) {
            return Err("mode=row needs a pulse width (pulse=US)".into());
        }
        Ok(s)
    }

    /// The constants `src/config.rs` includes, and the `.cvm_config`
    /// section: what the ELF was built for, in a section that is not loaded
    /// (no flash), which `dmap twin --elf` reads to refuse a run it does
    /// not fit. The thresholds go in as distance units, a contrast and a
    /// share, which the firmware's scorer turns back into exactly the
    /// integers given (every scale is a power of two).
    fn rust(&self, spec: &str) -> Result<String, String> {
        let scorer = Scorer::new(&self.config()?).map_err(|e| format!("{e:?}"))?;
        let st = self.settings(&scorer)?;
        let Scan {
            j1, j2, cols, rows, ..
        } = *self;
        let units = |v: u32, f: fn(u32) -> f64| {
            if v == u32::MAX {
                "f64::INFINITY".to_string()
            } else {
                format!("{:?}", f(v))
            }
        };
        let full_scale = self.full_scale;
        let (kernels, weights, normalise) = (&self.kernels, &self.weights, self.normalise);
        let section_b = self.resolved_b();
        let mut built_for = format!(
            "j1={j1} j2={j2} cols={cols} rows={rows} kernels={kernels} b={section_b} weights={weights} normalise={normalise} fs={full_scale}"
        );
        for key in Key::ALL {
            if !matches!(key, Key::Cols | Key::Rows) {
                let v = key.get(&st);
                let _ = match key.kind() {
                    Kind::Choice(words) => {
                        write!(built_for, " {}={}", key.name(), words[v as usize & 1])
                    }
                    _ => write!(built_for, " {}={v}", key.name()),
                };
            }
        }
        let kernels = match (kernels.as_str(), self.b) {
            ("paper", b) => format!("Kernels::Paper {{ bmax: {} }}", b.unwrap_or(0)),
            (_, Some(k)) => format!("Kernels::Square {{ kmax: {k} }}"),
            (_, None) => "Kernels::square_default(GEOMETRY)".into(),
        };
        let weights = if weights == "unit" { "Unit" } else { "Uniform" };
        let o = &st.outputs;
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
        let _ = writeln!(
            s,
            "pub const THRESHOLD_UNITS: f64 = {:?};",
            scorer.score_to_units(st.threshold)
        );
        let _ = writeln!(
            s,
            "pub const POWER_THRESHOLD_UNITS: f64 = {};",
            units(st.power_threshold, power::to_units)
        );
        let _ = writeln!(
            s,
            "pub const SPREAD_THRESHOLD_UNITS: f64 = {};",
            units(st.spread_threshold, spread::to_units)
        );
        let _ = writeln!(s, "pub const SCORES: bool = {};", st.scores);
        let _ = writeln!(
            s,
            "pub const MAX_DEFECT_LINES_PER_ROW: u16 = {};",
            st.max_defect_lines_per_row
        );
        let _ = writeln!(s, "pub const FULL_SCALE: u16 = {full_scale};");
        let _ = writeln!(
            s,
            "pub const REJECT_ROW: bool = {};",
            o.reject_mode == RejectMode::Row
        );
        let _ = writeln!(s, "pub const PULSE_US: u32 = {};", o.pulse_us);
        let _ = writeln!(s, "pub const ROW_DELAY: u32 = {};", o.row_delay);
        let _ = writeln!(s, "pub const MIN_AREA: u32 = {};", o.min_area);
        let _ = writeln!(s, "pub const MIN_PEAK: u32 = {};", o.min_strength);
        let _ = writeln!(s, "pub const MAX_MISSING: u32 = {};", o.max_missing);
        let _ = writeln!(s, "pub const MAX_MISPLACED: u32 = {};", o.max_misplaced);
        let _ = writeln!(
            s,
            "pub const FIRMWARE_VERSION_OVERRIDE: Option<&str> = {:?};",
            self.fw
        );
        let _ = writeln!(
            s,
            r##"core::arch::global_asm!(r#".pushsection .cvm_config,"",%progbits"#, r#".ascii "{built_for}""#, ".popsection");"##
        );
        Ok(s)
    }
}
