//! The settings of a run, resolved in one place: the command-line options
//! ([`crate::options`]), a calibration file if one is given and the
//! defaults become the very values the firmware works with, the core's
//! [`Config`] and the pipeline's [`Settings`], checked once with one-line
//! errors before any sample is scored. `stream`, `emulate`, `twin`,
//! `calibrate`, `score` and `bench` take their configuration from here, so
//! that every command means the same thing by an option.
//!
//! Where each value comes from, first match wins:
//! * thresholds: the calibration file (clap refuses it beside
//!   `--threshold`, `--power-threshold` or `--spread-threshold`), the option, the default (none
//!   for the CVM channel of `--raw` maps, whose distances have no scale);
//! * the configuration: the scoring options and `--full-scale`, which a
//!   calibration file must match field for field;
//! * the columns: the scan's.

use anyhow::{Result, anyhow, bail};
use cvm_core::{Config, Scorer, Settings};

use crate::calibration_file::Calibration;
use crate::fmt::fmt_num;
use crate::options::{KernelArg, OutputArgs, ScoringArgs, WeightArg};

/// Most columns the host pipeline accepts (the engine's capacity is fixed
/// at compile time, as on the target).
pub const MAX_COLS: usize = 4096;

/// Default defect threshold, in distance units.
pub const DEFAULT_THRESHOLD: f64 = 0.5;
/// Default threshold of the power channel: a contrast of 0.1 between the
/// two neighbours' powers (one has 22 % more light than the other).
pub const DEFAULT_POWER_THRESHOLD: f64 = 0.1;
/// Default threshold of the spread channel: off.
pub const DEFAULT_SPREAD_THRESHOLD: f64 = f64::INFINITY;

/// Everything a `stream`, `emulate` or `twin` run is configured with.
pub struct RunSettings {
    /// The core's configuration, full scale included.
    pub config: Config,
    /// The fixed-point scorer of [`Self::config`].
    pub scorer: Scorer,
    /// The pipeline's settings: the integers the firmware compares with.
    pub settings: Settings,
    /// The CVM threshold in distance units: the emulated board's scan
    /// header carries it and the firmware converts it with its own scorer
    /// to exactly [`Settings::threshold`].
    pub threshold_units: f64,
    /// The power threshold as a contrast, likewise.
    pub power_threshold_units: f64,
    /// The spread threshold as a share of the power, likewise (infinite:
    /// off).
    pub spread_threshold_units: f64,
    /// What the user should know about the configuration and the scan's
    /// shape; printed after the run's output.
    pub warnings: Vec<String>,
}

/// The settings of a run over a scan of `rows x cols` maps of `j1 x j2`
/// cells. The checks come in a fixed order (configuration, calibration,
/// threshold, columns, power threshold), so that a run with several
/// mistakes always names the same one.
pub fn resolve(
    scoring: &ScoringArgs,
    output: &OutputArgs,
    geometry: (usize, usize),
    shape: (usize, usize),
) -> Result<RunSettings> {
    resolve_with(
        scoring,
        output,
        &|path| Calibration::load(path),
        geometry,
        shape,
    )
}

/// [`resolve`] with the calibration `output.calibration` names read by
/// `load` (a file, or a calibration already in memory).
pub fn resolve_with(
    scoring: &ScoringArgs,
    output: &OutputArgs,
    load: &dyn Fn(&std::path::Path) -> Result<Calibration>,
    (j1, j2): (usize, usize),
    (rows, cols): (usize, usize),
) -> Result<RunSettings> {
    let config = core_config(scoring, output.full_scale, j1, j2)?;
    let scorer = scorer(&config)?;
    let calibration = match &output.calibration {
        Some(path) => {
            let c = load(path)?;
            c.threshold_for(path, &config, &scorer)?;
            Some(c)
        }
        None => None,
    };
    let threshold_units = match &calibration {
        Some(c) => c.threshold,
        None => threshold_units(output.threshold, scoring.raw)?,
    };
    check_cols(cols)?;
    let power_threshold_units = match &calibration {
        Some(c) => c.power_threshold,
        None => power_threshold_units(output.power_threshold)?,
    };
    let spread_threshold_units = match &calibration {
        Some(c) => c.spread_threshold,
        None => spread_threshold_units(output.spread_threshold)?,
    };
    let mut settings = pipeline_settings(
        &scorer,
        output,
        (rows, cols),
        threshold_units,
        (power_threshold_units, spread_threshold_units),
    );
    apply_set(&mut settings, &output.set)?;
    // The units the emulated board's scan file carries, from the integers
    // (every scale is a power of two, so the board converts them back exactly).
    let (threshold_units, power_threshold_units, spread_threshold_units) = if output.set.is_empty()
    {
        (
            threshold_units,
            power_threshold_units,
            spread_threshold_units,
        )
    } else {
        units_of(&scorer, &settings)?
    };
    let mut warnings = scoring.warnings(j1, j2)?;
    warnings.extend(threshold_warnings(&scorer, threshold_units));
    warnings.extend(flat_scan_warnings(rows, cols));
    Ok(RunSettings {
        config,
        scorer,
        settings,
        threshold_units,
        power_threshold_units,
        spread_threshold_units,
        warnings,
    })
}

/// What `--set` may give on the host: any value the wire allows, but the
/// scan's own shape.
const HOST_CAPACITY: cvm_core::command::Capacity = cvm_core::command::Capacity {
    max_cols: u16::MAX,
    max_rows: u16::MAX,
    max_dcap: u16::MAX,
    max_pulse_us: u32::MAX,
};

/// Applies `--set KEY=VALUE` in order, each checked as the board checks a
/// `set` request (the same names, units, words and ranges:
/// [`cvm_core::command::SETTINGS`]).
fn apply_set(settings: &mut Settings, pairs: &[String]) -> Result<()> {
    use cvm_core::command::{Key, conflict};
    for pair in pairs {
        let Some((name, value)) = pair.split_once('=') else {
            bail!("--set {pair}: expected KEY=VALUE (the keys: dmap sensor --help)");
        };
        let Some(key) = Key::from_name(name.as_bytes()) else {
            let names: Vec<_> = Key::ALL.iter().map(|k| k.name()).collect();
            bail!(
                "--set {pair}: no setting {name:?} (one of {})",
                names.join(", ")
            );
        };
        if matches!(key, Key::Cols | Key::Rows) {
            bail!("--set {pair}: a run's {name} are its scan's");
        }
        let v = key
            .parse_value(value.as_bytes(), &HOST_CAPACITY)
            .map_err(|e| anyhow::anyhow!("--set {pair}: {e}"))?;
        if let Some(max) = key.off_above()
            && v > max
            && v != u32::MAX
        {
            bail!(
                "--set {pair}: above {max} the channel is off; write that as {name}=4294967295, the value the header then shows"
            );
        }
        if !key.set(settings, v) {
            bail!("--set {pair}: not a value of {name}");
        }
        settings.sources[key.index()] = cvm_core::settings::Source::Default;
    }
    if conflict(settings) {
        bail!("--set mode=row needs a pulse width: --set pulse=US (before or after it)");
    }
    Ok(())
}

/// The three thresholds in the units the emulated board's scan file
/// carries, each checked to convert back to its integer.
fn units_of(scorer: &Scorer, s: &Settings) -> Result<(f64, f64, f64)> {
    let t = scorer.score_to_units(s.threshold);
    let p = cvm_core::power::to_units(s.power_threshold);
    let sp = cvm_core::spread::to_units(s.spread_threshold);
    let back = (
        scorer.threshold_from_units(t),
        cvm_core::power::threshold_from_units(if s.power_threshold == u32::MAX {
            f64::INFINITY
        } else {
            p
        }),
        cvm_core::spread::threshold_from_units(if s.spread_threshold == u32::MAX {
            f64::INFINITY
        } else {
            sp
        }),
    );
    if back != (s.threshold, s.power_threshold, s.spread_threshold) {
        bail!(
            "internal: the thresholds {:?} do not convert back exactly",
            back
        );
    }
    let inf = |v: u32, u: f64| if v == u32::MAX { f64::INFINITY } else { u };
    Ok((t, inf(s.power_threshold, p), inf(s.spread_threshold, sp)))
}

/// The core's configuration for `j1 x j2` maps: the scoring options and
/// the detector's full scale.
pub fn core_config(scoring: &ScoringArgs, full_scale: u16, j1: usize, j2: usize) -> Result<Config> {
    Ok(Config {
        full_scale,
        ..scoring.core_config(j1, j2)?
    })
}

/// The fixed-point scorer of `config` ([`crate::fixed::scorer`]), with a
/// readable error if the core refuses it.
pub fn scorer(config: &Config) -> Result<Scorer> {
    crate::fixed::scorer(config)
        .map_err(|e| anyhow!("fixed-point scorer refused the configuration: {e}"))
}

/// The CVM threshold in distance units: the one given, or the default for
/// normalised maps. Raw counts have no sensible default (their distances
/// scale with the square of the counts), so `--raw` needs `--threshold`.
fn threshold_units(given: Option<f64>, raw: bool) -> Result<f64> {
    let t = match given {
        Some(t) => t,
        None if raw => bail!(
            "--raw compares raw counts, whose distances have no default scale: give --threshold (the default {DEFAULT_THRESHOLD} is for normalised maps)"
        ),
        None => DEFAULT_THRESHOLD,
    };
    if t.is_nan() || t < 0.0 {
        bail!(
            "--threshold must be a non-negative number, got {}",
            fmt_num(t)
        );
    }
    if t.is_infinite() {
        bail!("--threshold must be finite, got {t}");
    }
    Ok(t)
}

/// The power channel's threshold, a contrast: the one given or the default
/// ([`f64::INFINITY`] turns the channel off).
fn power_threshold_units(given: Option<f64>) -> Result<f64> {
    let t = given.unwrap_or(DEFAULT_POWER_THRESHOLD);
    if t.is_nan() || t < 0.0 {
        bail!(
            "--power-threshold must be a non-negative contrast (inf: off), got {}",
            fmt_num(t)
        );
    }
    Ok(t)
}

/// The spread threshold as a share of the power: the one given, or off
/// (infinite) by default.
fn spread_threshold_units(given: Option<f64>) -> Result<f64> {
    let t = given.unwrap_or(DEFAULT_SPREAD_THRESHOLD);
    if t.is_nan() || t < 0.0 {
        bail!(
            "--spread-threshold must be a non-negative share of the power (inf: off), got {}",
            fmt_num(t)
        );
    }
    Ok(t)
}

fn check_cols(cols: usize) -> Result<()> {
    if cols == 0 || cols > MAX_COLS {
        bail!("scan has {cols} columns; the pipeline supports 1..={MAX_COLS}");
    }
    Ok(())
}

/// The pipeline's settings from checked thresholds; the rest is what the
/// host announces in its header (a power-on reset, the first boot).
fn pipeline_settings(
    scorer: &Scorer,
    output: &OutputArgs,
    (rows, cols): (usize, usize),
    threshold_units: f64,
    (power_threshold_units, spread_threshold_units): (f64, f64),
) -> Settings {
    Settings {
        cols: cols as u32,
        threshold: scorer.threshold_from_units(threshold_units),
        power_threshold: cvm_core::power::threshold_from_units(power_threshold_units),
        spread_threshold: cvm_core::spread::threshold_from_units(spread_threshold_units),
        scores: output.scores,
        max_defect_lines_per_row: output.max_defect_lines,
        rows: rows as u32,
        outputs: cvm_core::settings::Outputs::DEFAULT,
        sources: [cvm_core::settings::Source::Default; cvm_core::settings::KEYS],
    }
}

/// What the scorer makes of the threshold when it is not what was asked:
/// above every score it can report, or rounded up by more than 1 % to its
/// integer format.
fn threshold_warnings(scorer: &Scorer, units: f64) -> Vec<String> {
    let thr = scorer.threshold_from_units(units);
    let effective = scorer.score_to_units(thr);
    let step = scorer.score_to_units(1);
    let q = scorer.score_frac_bits();
    if thr == u32::MAX && units > effective {
        vec![format!(
            "--threshold {} is above the largest score the scorer reports ({} in its Q({q}) format): no position can be a defect on the CVM channel (the power channel, --power-threshold, still counts in the end line's defects)",
            fmt_num(units),
            fmt_num(effective)
        )]
    } else if effective > units * 1.01 {
        vec![format!(
            "--threshold {} becomes {} in the scorer's Q({q}) format (one score step is {} distance units)",
            fmt_num(units),
            fmt_num(effective),
            fmt_num(step)
        )]
    } else {
        Vec::new()
    }
}

impl OutputArgs {
    /// The pipeline's settings for a scan of `cols` columns under a scorer
    /// already made, from these options alone: the threshold given or the
    /// default whatever the normalisation (tests build pipelines this way;
    /// a command resolves its whole run with [`resolve`]).
    pub fn settings(&self, scorer: &Scorer, (rows, cols): (usize, usize)) -> Result<Settings> {
        let t = self.threshold.unwrap_or(DEFAULT_THRESHOLD);
        if t.is_nan() || t < 0.0 || t.is_infinite() {
            bail!(
                "--threshold must be a finite non-negative number, got {}",
                fmt_num(t)
            );
        }
        check_cols(cols)?;
        let (power, spread) = match &self.calibration {
            Some(path) => {
                let c = Calibration::load(path)?;
                (c.power_threshold, c.spread_threshold)
            }
            None => (
                power_threshold_units(self.power_threshold)?,
                spread_threshold_units(self.spread_threshold)?,
            ),
        };
        Ok(pipeline_settings(
            scorer,
            self,
            (rows, cols),
            t,
            (power, spread),
        ))
    }
}

impl ScoringArgs {
    fn check(&self, j1: usize, j2: usize) -> Result<()> {
        if !(1..=16).contains(&j1) || !(1..=16).contains(&j2) {
            bail!("detector geometry {j1}x{j2} is not supported (each axis must be 1..=16)");
        }
        match self.kernels {
            KernelArg::Paper => {
                if self.bmax == Some(0) {
                    bail!("--bmax must be at least 1 for paper kernels");
                }
            }
            KernelArg::Square => {
                if self.weights == Some(WeightArg::Uniform) {
                    bail!(
                        "square kernels use unit weights (docs/method.md §3); drop --weights uniform"
                    );
                }
                let limit = j1.max(j2) - 1;
                if let Some(k) = self.bmax
                    && k > limit
                {
                    bail!(
                        "--bmax {k} is too large for square kernels on {j1}x{j2} maps (at most {limit})"
                    );
                }
            }
        }
        Ok(())
    }

    /// The fixed-point core's configuration for `j1 x j2` maps.
    pub fn core_config(&self, j1: usize, j2: usize) -> Result<cvm_core::Config> {
        self.check(j1, j2)?;
        let geometry = cvm_core::Geometry::new(j1 as u8, j2 as u8)
            .map_err(|e| anyhow!("geometry {j1}x{j2}: {e}"))?;
        let kernels = match self.kernels {
            KernelArg::Paper => cvm_core::Kernels::Paper {
                bmax: self.bmax.unwrap_or(0).min(16) as u8,
            },
            KernelArg::Square => match self.bmax {
                Some(k) => cvm_core::Kernels::Square { kmax: k as u8 },
                None => cvm_core::Kernels::square_default(geometry),
            },
        };
        let weights = match (self.kernels, self.weights) {
            (KernelArg::Square, _) | (_, Some(WeightArg::Unit)) => cvm_core::Weights::Unit,
            _ => cvm_core::Weights::Uniform,
        };
        Ok(cvm_core::Config {
            geometry,
            kernels,
            weights,
            normalise: !self.raw,
            full_scale: u16::MAX,
        })
    }

    /// The fixed-point scorer, with a readable error if the core refuses it.
    pub fn scorer(&self, j1: usize, j2: usize) -> Result<cvm_core::Scorer> {
        scorer(&self.core_config(j1, j2)?)
    }

    /// Warnings for configurations under which part or all of the gradient
    /// is zero whatever the scan (see [`blind_axes`]).
    pub fn warnings(&self, j1: usize, j2: usize) -> Result<Vec<String>> {
        let e = cvm_reference::CvmEmbedding::new(&self.reference_config(j1, j2)?);
        Ok(blind_axes(j1, j2, |a, b| {
            e.distance(&e.embed(a), &e.embed(b))
        }))
    }

    /// The f64 reference configuration for `j1 x j2` maps.
    pub fn reference_config(&self, j1: usize, j2: usize) -> Result<cvm_reference::CvmConfig> {
        self.check(j1, j2)?;
        let g = cvm_reference::Geometry::new(j1, j2)?;
        let cfg = match self.kernels {
            KernelArg::Paper => {
                let w = match self.weights {
                    Some(WeightArg::Unit) => cvm_reference::PaperWeights::Unit,
                    _ => cvm_reference::PaperWeights::Uniform,
                };
                cvm_reference::CvmConfig::paper(g, w, self.bmax)?
            }
            KernelArg::Square => cvm_reference::CvmConfig::square(g, self.bmax)?,
        };
        Ok(cfg.with_normalise(!self.raw))
    }
}

/// A scan of one position: the border rule makes its gradient zero.
pub fn flat_scan_warnings(rows: usize, cols: usize) -> Vec<String> {
    if rows == 1 && cols == 1 {
        vec!["the scan has a single position: its gradient is zero (a neighbour outside the scan is the map itself)".into()]
    } else {
        Vec::new()
    }
}

/// Detector axes along which the distance `d` cannot tell two maps apart:
/// a unit spot moved from the first cell to the next (and to the last) of
/// the axis scores 0. A 1x1 detector normalised tells nothing apart at all.
pub fn blind_axes(j1: usize, j2: usize, d: impl Fn(&[f64], &[f64]) -> f64) -> Vec<String> {
    let n = j1 * j2;
    let spot = |k: usize| {
        let mut m = vec![0.0; n];
        m[k] = 1.0;
        m
    };
    // Rounding noise of maps of unit mass, far below any real distance.
    let zero = |x: f64| x.abs() <= 1e-12;
    let mut blind = Vec::new();
    let mut any_axis = false;
    for (axis, len, step) in [(1, j1, j2), (2, j2, 1)] {
        if len < 2 {
            continue;
        }
        any_axis = true;
        if zero(d(&spot(0), &spot(step))) && zero(d(&spot(0), &spot(step * (len - 1)))) {
            blind.push(format!(
                "maps that differ only along detector axis {axis} ({len} cells) score 0 under this configuration: that axis contributes nothing to the gradient"
            ));
        }
    }
    let mut dimmer = spot(0);
    dimmer[0] = 0.5;
    let intensity_blind = zero(d(&spot(0), &dimmer));
    if intensity_blind && (!any_axis || blind.len() == usize::from(j1 >= 2) + usize::from(j2 >= 2))
    {
        return vec![format!(
            "{j1}x{j2} maps: this configuration scores every pair of maps 0, so the whole gradient is zero"
        )];
    }
    blind
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refused(
        scoring: &ScoringArgs,
        output: &OutputArgs,
        j: (usize, usize),
        shape: (usize, usize),
    ) -> String {
        match resolve(scoring, output, j, shape) {
            Ok(_) => panic!("accepted {scoring:?} {output:?} {j:?} {shape:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn defaults_become_the_firmware_integers() {
        let run = resolve(
            &ScoringArgs::default(),
            &OutputArgs::default(),
            (3, 3),
            (2, 5),
        )
        .unwrap();
        // 0.5 distance units in the scorer's Q(q); a contrast of 0.1 in Q15
        // is 3276.8, rounded up.
        let q = run.scorer.score_frac_bits();
        assert_eq!(u64::from(run.settings.threshold), 1u64 << (q - 1));
        assert_eq!(run.settings.power_threshold, 3277);
        assert_eq!((run.threshold_units, run.power_threshold_units), (0.5, 0.1));
        assert_eq!(run.settings.cols, 5);
        assert_eq!(run.settings.max_defect_lines_per_row, 0);
        assert!(!run.settings.scores);
        assert_eq!(run.config.full_scale, u16::MAX);
        assert_eq!(
            run.config,
            ScoringArgs::default().core_config(3, 3).unwrap()
        );
        assert!(run.warnings.is_empty(), "{:?}", run.warnings);
    }

    #[test]
    fn options_given_reach_the_settings() {
        let out = OutputArgs {
            threshold: Some(0.25),
            power_threshold: Some(f64::INFINITY),
            scores: true,
            max_defect_lines: 7,
            full_scale: 4095,
            ..OutputArgs::default()
        };
        let run = resolve(&ScoringArgs::default(), &out, (2, 3), (1, 1)).unwrap();
        let q = run.scorer.score_frac_bits();
        assert_eq!(u64::from(run.settings.threshold), 1u64 << (q - 2));
        assert_eq!(run.settings.power_threshold, cvm_core::power::POWER_OFF);
        assert!(run.settings.scores);
        assert_eq!(run.settings.max_defect_lines_per_row, 7);
        assert_eq!(run.config.full_scale, 4095);
        // The configuration's warnings first (a normalised 2-cell axis under
        // paper kernels tells its two cells apart by nothing), then the scan's.
        assert_eq!(
            run.warnings,
            vec![
                "maps that differ only along detector axis 1 (2 cells) score 0 under this configuration: that axis contributes nothing to the gradient",
                "the scan has a single position: its gradient is zero (a neighbour outside the scan is the map itself)",
            ]
        );
    }

    #[test]
    fn checks_come_in_a_fixed_order() {
        let wide = (1, MAX_COLS + 1);
        let raw = ScoringArgs {
            raw: true,
            ..ScoringArgs::default()
        };
        let e = refused(&raw, &OutputArgs::default(), (3, 3), wide);
        assert!(e.starts_with("--raw compares raw counts"), "{e}");
        assert_eq!(
            refused(
                &ScoringArgs::default(),
                &OutputArgs::default(),
                (3, 3),
                wide
            ),
            "scan has 4097 columns; the pipeline supports 1..=4096"
        );
        let bad_power = OutputArgs {
            power_threshold: Some(-1.0),
            ..OutputArgs::default()
        };
        assert_eq!(
            refused(&ScoringArgs::default(), &bad_power, (17, 3), (1, 1)),
            "detector geometry 17x3 is not supported (each axis must be 1..=16)"
        );
        assert_eq!(
            refused(&ScoringArgs::default(), &bad_power, (3, 3), (1, 1)),
            "--power-threshold must be a non-negative contrast (inf: off), got -1"
        );
    }
}
