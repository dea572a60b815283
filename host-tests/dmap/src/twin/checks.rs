//! What `dmap twin` checks before it starts the chip model: the faults
//! against the scan (kinds, beams, and faults that would do nothing), the
//! run's model time, and that an `--elf` was built for the run.

use crate::fmt::fmt_num;
use anyhow::{Context, Result, bail};
use std::path::Path;

/// The fault kinds of the detector model and how many numbers follow the
/// beam in each (`host-tests/twin/h743twin/detector.py`).
pub const FAULT_KINDS: [(&str, usize); 15] = [
    ("gap", 1),
    ("burst", 2),
    ("sync-glitch", 0),
    ("sync-miss", 0),
    ("overrun", 0),
    ("dma-error", 0),
    ("dma-stall", 0),
    ("uart-busy", 1),
    ("halt", 1),
    ("wedge", 0),
    ("drdy-miss", 0),
    ("pin-reset", 0),
    ("bor", 0),
    ("hardfault", 0),
    ("panic", 0),
];

/// The most model time a run may take, in milliseconds: far beyond any
/// scan the product makes (300 x 300 beams at the SPI limit take about
/// 18 s), and short of the hours a mistyped number would run for.
pub const MAX_MODEL_MS: f64 = 600_000.0;

/// Checks a `--fault` against the model's kinds and a scan of `rows x
/// cols` beams (the model would refuse it only after the build, or
/// inject it to no effect); returns the model time it adds, in ms.
pub fn check_fault(spec: &str, rows: u64, cols: u64) -> Result<f64> {
    let beams = rows * cols;
    let (kind, rest) = spec
        .split_once('@')
        .with_context(|| format!("--fault {spec:?}: expected KIND@BEAM[:ARG...]"))?;
    let Some(&(_, nargs)) = FAULT_KINDS.iter().find(|(k, _)| *k == kind) else {
        let kinds: Vec<&str> = FAULT_KINDS.iter().map(|(k, _)| *k).collect();
        bail!(
            "--fault {spec:?}: unknown kind {kind:?} (one of {})",
            kinds.join(", ")
        );
    };
    let mut parts = rest.split(':');
    let beam: u64 = parts
        .next()
        .and_then(|b| b.parse().ok())
        .with_context(|| format!("--fault {spec:?}: the beam must be a number from 0"))?;
    if beam >= beams {
        bail!(
            "--fault {spec:?}: beam {beam} is past the scan's last beam ({})",
            beams - 1
        );
    }
    let args: Vec<&str> = parts.collect();
    if args.len() != nargs {
        bail!("--fault {spec:?}: {kind} takes {nargs} number(s) after the beam");
    }
    let mut values = Vec::with_capacity(nargs);
    for a in args {
        match a.parse::<f64>() {
            Ok(v) if v.is_finite() && v >= 0.0 => values.push(v),
            _ => bail!("--fault {spec:?}: {a:?} is not a non-negative number"),
        }
    }
    // Faults that would be injected to no effect are refused like a beam
    // past the end: the run would claim a test it did not make.
    match (kind, values.as_slice()) {
        ("burst", &[n, _]) => {
            if n < 1.0 || n.fract() != 0.0 {
                bail!("--fault {spec:?}: the burst's N must be a whole number of beams from 1");
            }
            if beam as f64 + n > beams as f64 {
                bail!(
                    "--fault {spec:?}: the burst runs past the scan's last beam ({})",
                    beams - 1
                );
            }
        }
        ("sync-miss", _) if !beam.is_multiple_of(cols) => bail!(
            "--fault {spec:?}: beam {beam} is not a row start (rows start at multiples of {cols})"
        ),
        ("sync-glitch", _) if beam.is_multiple_of(cols) => bail!(
            "--fault {spec:?}: beam {beam} is a row start; a glitch is an extra LINE_SYNC mid-row"
        ),
        _ => {}
    }
    Ok(match (kind, values.as_slice()) {
        ("gap" | "uart-busy" | "halt", &[ms]) => ms,
        _ => 0.0,
    })
}

/// Refuses a run whose model time would pass [`MAX_MODEL_MS`].
/// `times`: --start-ms, --beam-us, the faults' pauses (ms), --settle-ms.
pub fn check_model_time(beams: u64, times: [f64; 4]) -> Result<()> {
    let [start_ms, beam_us, faults_ms, settle_ms] = times;
    let total = start_ms + beams as f64 * beam_us / 1e3 + faults_ms + settle_ms;
    if total > MAX_MODEL_MS {
        bail!(
            "this run would take {} s of model time (--start-ms, {beams} beams at --beam-us, the faults' pauses, --settle-ms), more than the limit of {} s",
            fmt_num((total / 1e3).round()),
            fmt_num(MAX_MODEL_MS / 1e3)
        );
    }
    Ok(())
}

/// The fields of a configuration string (`key=value` words).
fn fields(config: &str) -> Vec<(&str, &str)> {
    config
        .split_whitespace()
        .filter_map(|w| w.split_once('='))
        .collect()
}

/// Refuses an ELF built for another configuration than the run's
/// (`config`, a `CVM_H743_SCAN` value): its `.cvm_config` section, which
/// build.rs writes, must agree on every field it has.
pub fn check_built_for(path: &Path, elf: &[u8], config: &str) -> Result<()> {
    let p = path.display();
    let Some(built) = crate::elf::section(elf, crate::elf::CONFIG_SECTION)
        .and_then(|b| std::str::from_utf8(b).ok())
    else {
        bail!(
            "--elf {p} does not say what it was built for (no {} section): run dmap twin without --elf to build it",
            crate::elf::CONFIG_SECTION
        );
    };
    check_config(path, built, config)
}

/// [`check_built_for`] on the text of the section, `built`.
fn check_config(path: &Path, built: &str, config: &str) -> Result<()> {
    let p = path.display();
    let run = fields(config);
    for (key, was) in fields(built) {
        let Some(&(_, want)) = run.iter().find(|(k, _)| *k == key) else {
            continue;
        };
        if want != was {
            let from = match key {
                "j1" | "j2" => "the scan's detector geometry",
                "cols" | "rows" => "the scan's size",
                "kernels" | "b" | "weights" | "normalise" => "the scoring options",
                "thr" => "--threshold, --calibration or --set thr=",
                "pthr" => "--power-threshold, --calibration or --set pthr=",
                "sthr" => "--spread-threshold, --calibration or --set sthr=",
                "scores" => "--scores or --set scores=",
                "dcap" => "--max-defect-lines or --set dcap=",
                "fs" => "--full-scale",
                _ => "the run",
            };
            bail!(
                "--elf {p} was built for {key}={was}, this run has {key}={want} (from {from}); run dmap twin without --elf to build it for this run"
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_are_checked_before_the_build() {
        assert_eq!(check_fault("gap@3:5", 2, 5).unwrap(), 5.0);
        assert_eq!(check_fault("burst@0:4:20.5", 2, 5).unwrap(), 0.0);
        assert_eq!(check_fault("halt@2:7.5", 2, 5).unwrap(), 7.5);
        assert!(check_fault("wedge@9", 2, 5).is_ok());
        for kind in ["pin-reset", "bor", "hardfault", "panic"] {
            assert!(check_fault(&format!("{kind}@3"), 2, 5).is_ok(), "{kind}");
            assert!(check_fault(&format!("{kind}@3:1"), 2, 5).is_err(), "{kind}");
        }
        assert!(check_fault("wedge@10", 2, 5).is_err());
        assert!(check_fault("gap@3", 2, 5).is_err());
        assert!(check_fault("wedge@3:1", 2, 5).is_err());
        assert!(check_fault("jam@3", 2, 5).is_err());
        assert!(check_fault("gap", 2, 5).is_err());
        assert!(check_fault("gap@-1:5", 2, 5).is_err());
        assert!(check_fault("gap@1:x", 2, 5).is_err());
    }

    #[test]
    fn faults_that_would_do_nothing_are_refused() {
        let err = |spec| check_fault(spec, 2, 5).unwrap_err().to_string();
        assert!(err("burst@0:0:10").contains("from 1"));
        assert!(err("burst@0:1.5:10").contains("from 1"));
        assert!(check_fault("burst@6:4:10", 2, 5).is_ok());
        assert!(err("burst@6:5:10").contains("past the scan's last beam (9)"));
        assert!(check_fault("sync-miss@5", 2, 5).is_ok());
        assert!(err("sync-miss@6").contains("not a row start"));
        assert!(check_fault("sync-glitch@6", 2, 5).is_ok());
        assert!(err("sync-glitch@5").contains("row start"));
        assert!(err("sync-glitch@0").contains("row start"));
    }

    #[test]
    fn an_elf_built_for_another_run_is_refused_naming_the_field() {
        let config = "j1=9 j2=9 cols=12 rows=6 kernels=paper b=0 weights=uniform normalise=true thr=838861 pthr=3277 scores=1 dcap=0 fs=65535 fw=x";
        assert!(check_built_for_text(config, config).is_ok());
        let other = config.replace("j1=9 j2=9", "j1=15 j2=15");
        let e = check_built_for_text(&other, config)
            .unwrap_err()
            .to_string();
        assert!(e.contains("built for j1=15, this run has j1=9"), "{e}");
        let e = check_built_for_text(&config.replace("scores=1", "scores=0"), config)
            .unwrap_err()
            .to_string();
        assert!(e.contains("scores=0") && e.contains("--scores"), "{e}");
    }

    /// [`check_built_for`] on a section's text.
    fn check_built_for_text(built: &str, config: &str) -> Result<()> {
        check_config(Path::new("x.elf"), built, config)
    }
}
