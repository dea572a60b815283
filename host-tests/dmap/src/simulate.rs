//! `dmap simulate`: run the scanner's ray model (crate `cvm-sim`) and write
//! the scan and its ground-truth mask as `.npy` files.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{ArgAction, Args, ValueEnum};
use cvm_sim::{Bubble, Config, Face, Interaction, Scatterer, Shape, SurfaceDefect, Vec3, preset};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::cli_values::{finite_f64, finite_f64s, j1xj2};

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PresetArg {
    /// Sec. 4.1: 300x300 positions, 15x15 detector, double-convex lens, nine air bubbles
    PaperSim,
    /// Sec. 4.2: 39x39 positions, 9x9 detector, cylindrical lens, two rough surface patches
    Prototype,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PartArg {
    Plate,
    DoubleConvex,
    Cylindrical,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum InteractionArg {
    /// Follow reflected and refracted rays, weighted by Fresnel reflectance
    Split,
    /// Follow one of them, chosen with the Fresnel probabilities
    Stochastic,
}

#[derive(Args, Clone, Debug)]
pub struct SimulateArgs {
    /// Scanner set-up to start from; every flag below overrides it
    #[arg(long, value_enum, default_value = "paper-sim")]
    pub preset: PresetArg,
    /// Output scan (.npy, uint16, shape rows x cols x J1 x J2)
    #[arg(short, long = "output", alias = "out", value_name = "SCAN.npy")]
    pub out: PathBuf,
    /// Output truth mask (.npy, bool, rows x cols); default: SCAN with `.truth.npy`
    #[arg(long, value_name = "MASK.npy")]
    pub truth: Option<PathBuf>,
    /// Remove all bubbles, surface defects and scattering discs (the reference part): with another
    /// --seed, the same part with other noise (shot, read, laser), no defects
    #[arg(long)]
    pub defect_free: bool,
    /// Random seed (same seed, same scan, whatever the thread count)
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Worker threads, 1..=256 (default: all cores)
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=MAX_THREADS as i64))]
    pub threads: Option<u16>,
    /// Raster rows (a smaller raster stays centred on --center-mm)
    #[arg(long)]
    pub rows: Option<usize>,
    /// Raster columns
    #[arg(long)]
    pub cols: Option<usize>,
    /// Distance between beam positions (µm)
    #[arg(long)]
    pub pitch_um: Option<f64>,
    /// Raster centre on the part, "X,Y" in mm
    #[arg(
        long,
        value_name = "X,Y",
        allow_hyphen_values = true,
        value_delimiter = ',',
        action = ArgAction::Set,
        value_parser = finite_f64
    )]
    pub center_mm: Option<Vec<f64>>,
    /// Beam 1/e² intensity radius (µm)
    #[arg(long)]
    pub waist_um: Option<f64>,
    /// Rays per beam (approximate; more rays, smoother maps, slower)
    #[arg(long)]
    pub rays: Option<usize>,
    /// Part shape (changing it resets its dimensions to that shape's defaults)
    #[arg(long, value_enum)]
    pub part: Option<PartArg>,
    /// Refractive index of the part
    #[arg(long)]
    pub index: Option<f64>,
    /// Surface radius of curvature (mm): both faces of a double-convex lens, the cylinder of a cylindrical lens
    #[arg(long)]
    pub radius_mm: Option<f64>,
    /// Centre thickness of the part (mm)
    #[arg(long)]
    pub thickness_mm: Option<f64>,
    /// Lateral size (mm): lens diameter, plate side, cylindrical lens width and length
    #[arg(long)]
    pub size_mm: Option<f64>,
    /// Air bubble "X,Y,Z,R" in mm (repeatable; replaces the preset's bubbles)
    #[arg(
        long = "bubble",
        value_name = "X,Y,Z,R",
        allow_hyphen_values = true,
        value_parser = finite_f64s
    )]
    pub bubbles: Vec<Vec<f64>>,
    /// Refractive index of the bubbles
    #[arg(long, default_value_t = 1.0)]
    pub bubble_index: f64,
    /// Rough strip or patch of the front face "X0,Y0,X1,Y1[,TILT_RAD]" in mm (repeatable; replaces the preset's)
    #[arg(
        long = "scratch",
        value_name = "X0,Y0,X1,Y1[,TILT]",
        allow_hyphen_values = true,
        value_parser = finite_f64s
    )]
    pub scratches: Vec<Vec<f64>>,
    /// Scattering disc of the front face "X,Y,SIZE,SHARE[,WIDTH_RAD]": centre in mm, diameter
    /// in raster positions (pitches), share of the light crossing it sent into a halo (0 < SHARE
    /// <= 1), halo rms angle per axis (rad, default 0.06); repeatable, marked in the truth mask
    #[arg(
        long = "scatter",
        value_name = "X,Y,SIZE,SHARE[,WIDTH]",
        allow_hyphen_values = true,
        value_parser = finite_f64s
    )]
    pub scatters: Vec<Vec<f64>>,
    /// Micro-facet size of the rough surface patches (µm)
    #[arg(long)]
    pub facet_um: Option<f64>,
    /// Facet tilt of the rough surface patches, rms per axis (rad)
    #[arg(long)]
    pub tilt_rad: Option<f64>,
    /// Detector cells "J1xJ2", each axis 1..=16
    #[arg(long, value_name = "J1xJ2", value_parser = j1xj2)]
    pub detector: Option<(usize, usize)>,
    /// Detector pixel pitch (µm)
    #[arg(long)]
    pub pixel_um: Option<f64>,
    /// Receiver point spread in the detector plane, Gaussian rms (µm; 0 = point per ray)
    #[arg(long)]
    pub spot_um: Option<f64>,
    /// Receiving lens focal length (mm)
    #[arg(long)]
    pub focal_mm: Option<f64>,
    /// Receiving lens clear aperture radius (mm)
    #[arg(long)]
    pub aperture_mm: Option<f64>,
    /// Distance from the part's back vertex to the receiving lens (mm)
    #[arg(long)]
    pub receiver_distance_mm: Option<f64>,
    /// Photo-electrons of the whole beam
    #[arg(long)]
    pub photons: Option<f64>,
    /// Electrons per ADC count
    #[arg(long)]
    pub gain: Option<f64>,
    /// Read noise (electrons rms)
    #[arg(long)]
    pub read_noise: Option<f64>,
    /// ADC bit depth (1..=16)
    #[arg(long)]
    pub bits: Option<u32>,
    /// Dark offset (counts)
    #[arg(long)]
    pub bias: Option<f64>,
    /// No Poisson shot noise
    #[arg(long)]
    pub no_shot_noise: bool,
    /// Laser power fluctuation from beam to beam, % rms (preset: 1; 0 = steady)
    #[arg(long, value_name = "PCT")]
    pub power_rms_pct: Option<f64>,
    /// Slow laser power drift over the scan, % peak (preset: 2; 0 = none)
    #[arg(long, value_name = "PCT")]
    pub power_drift_pct: Option<f64>,
    /// Reflection/refraction at interfaces
    #[arg(long, value_enum)]
    pub interaction: Option<InteractionArg>,
    /// Truth mask radius around the beam axis, in beam waists
    #[arg(long)]
    pub footprint: Option<f64>,
}

/// `values` of `flag`, split by clap, if there are `min..=max` of them.
fn count(values: &[f64], flag: &str, min: usize, max: usize) -> Result<()> {
    if !(min..=max).contains(&values.len()) {
        let given: Vec<String> = values.iter().map(|&v| crate::fmt::fmt_num(v)).collect();
        bail!(
            "{flag} {}: expected {min}{} comma-separated numbers, got {}",
            given.join(","),
            if max > min {
                format!("..={max}")
            } else {
                String::new()
            },
            values.len()
        );
    }
    Ok(())
}

/// Halo rms angle of a `--scatter` disc that gives none (rad): a forward
/// lobe of inclusions about ten wavelengths across (docs/spread-study.md).
pub const DEFAULT_HALO_RAD: f64 = 0.06;

/// One `--scatter X,Y,SIZE,SHARE[,WIDTH]` on a raster of `pitch` mm.
fn scatterer(v: &[f64], pitch: f64) -> Result<Scatterer> {
    count(v, "--scatter", 4, 5)?;
    let given = || {
        v.iter()
            .map(|&x| crate::fmt::fmt_num(x))
            .collect::<Vec<_>>()
            .join(",")
    };
    let (size, share) = (v[2], v[3]);
    let width = v.get(4).copied().unwrap_or(DEFAULT_HALO_RAD);
    if size <= 0.0 {
        bail!(
            "--scatter {}: the disc's size must be positive (raster positions across), got {}",
            given(),
            crate::fmt::fmt_num(size)
        );
    }
    if !(share > 0.0 && share <= 1.0) {
        bail!(
            "--scatter {}: the scattered share must be in (0, 1], got {}",
            given(),
            crate::fmt::fmt_num(share)
        );
    }
    if !(width > 0.0 && width < 0.5) {
        bail!(
            "--scatter {}: the halo width must be in (0, 0.5) rad, got {}",
            given(),
            crate::fmt::fmt_num(width)
        );
    }
    // The radius follows the pitch, which the configuration's check refuses
    // when not positive.
    Ok(Scatterer::across(v[0], v[1], size, pitch, share, width))
}

/// Most worker threads `--threads` starts.
pub const MAX_THREADS: usize = 256;

/// The simulator configuration: the preset with every given flag applied.
pub fn config(a: &SimulateArgs) -> Result<Config> {
    let mut c = match a.preset {
        PresetArg::PaperSim => preset::paper_sim(a.defect_free),
        PresetArg::Prototype => preset::prototype(a.defect_free),
    };
    c.seed = a.seed;
    let r = &mut c.raster;
    r.rows = a.rows.unwrap_or(r.rows);
    r.cols = a.cols.unwrap_or(r.cols);
    r.pitch = a.pitch_um.map_or(r.pitch, |v| v / 1000.0);
    r.waist = a.waist_um.map_or(r.waist, |v| v / 1000.0);
    r.rays = a.rays.unwrap_or(r.rays);
    if let Some(v) = &a.center_mm {
        count(v, "--center-mm", 2, 2)?;
        r.center = (v[0], v[1]);
    }
    let p = &mut c.part;
    if let Some(kind) = a.part {
        p.shape = match kind {
            PartArg::Plate => Shape::Plate {
                thickness: 5.0,
                side: 200.0,
            },
            PartArg::DoubleConvex => Shape::DoubleConvex {
                r1: 1000.0,
                r2: 1000.0,
                thickness: 10.0,
                diameter: 150.0,
            },
            PartArg::Cylindrical => Shape::Cylindrical {
                radius: 50.0,
                thickness: 5.0,
                width: 25.0,
                length: 25.0,
            },
        };
    }
    match &mut p.shape {
        Shape::Plate { thickness, side } => {
            if a.radius_mm.is_some() {
                bail!("--radius-mm does not apply to a flat plate");
            }
            *thickness = a.thickness_mm.unwrap_or(*thickness);
            *side = a.size_mm.unwrap_or(*side);
        }
        Shape::DoubleConvex {
            r1,
            r2,
            thickness,
            diameter,
        } => {
            *r1 = a.radius_mm.unwrap_or(*r1);
            *r2 = a.radius_mm.unwrap_or(*r2);
            *thickness = a.thickness_mm.unwrap_or(*thickness);
            *diameter = a.size_mm.unwrap_or(*diameter);
        }
        Shape::Cylindrical {
            radius,
            thickness,
            width,
            length,
        } => {
            *radius = a.radius_mm.unwrap_or(*radius);
            *thickness = a.thickness_mm.unwrap_or(*thickness);
            *width = a.size_mm.unwrap_or(*width);
            *length = a.size_mm.unwrap_or(*length);
        }
    }
    p.index = a.index.unwrap_or(p.index);
    if !a.bubbles.is_empty() {
        p.bubbles = a
            .bubbles
            .iter()
            .map(|v| {
                count(v, "--bubble", 4, 4)?;
                Ok(Bubble {
                    center: Vec3::new(v[0], v[1], v[2]),
                    radius: v[3],
                    index: a.bubble_index,
                })
            })
            .collect::<Result<_>>()?;
    } else {
        p.bubbles.iter_mut().for_each(|b| b.index = a.bubble_index);
    }
    if !a.scratches.is_empty() {
        p.defects = a
            .scratches
            .iter()
            .enumerate()
            .map(|(i, v)| {
                count(v, "--scratch", 4, 5)?;
                Ok(SurfaceDefect {
                    face: Face::Front,
                    x0: v[0].min(v[2]),
                    x1: v[0].max(v[2]),
                    y0: v[1].min(v[3]),
                    y1: v[1].max(v[3]),
                    tilt_sigma: v.get(4).copied().unwrap_or(0.1),
                    facet: 0.2,
                    seed: 100 + i as u64,
                })
            })
            .collect::<Result<_>>()?;
    }
    for s in &mut p.defects {
        s.facet = a.facet_um.map_or(s.facet, |v| v / 1000.0);
        s.tilt_sigma = a.tilt_rad.unwrap_or(s.tilt_sigma);
    }
    if !a.scatters.is_empty() {
        p.scatterers = a
            .scatters
            .iter()
            .map(|v| scatterer(v, c.raster.pitch))
            .collect::<Result<_>>()?;
    }
    if a.defect_free {
        p.bubbles.clear();
        p.defects.clear();
        p.scatterers.clear();
    }
    let rx = &mut c.receiver;
    if let Some(d) = a.detector {
        (rx.j1, rx.j2) = d;
    }
    rx.pixel = a.pixel_um.map_or(rx.pixel, |v| v / 1000.0);
    rx.spot = a.spot_um.map_or(rx.spot, |v| v / 1000.0);
    rx.focal = a.focal_mm.unwrap_or(rx.focal);
    rx.aperture = a.aperture_mm.unwrap_or(rx.aperture);
    rx.distance = a.receiver_distance_mm.unwrap_or(rx.distance);
    let n = &mut c.noise;
    n.photons = a.photons.unwrap_or(n.photons);
    n.gain = a.gain.unwrap_or(n.gain);
    n.read_noise = a.read_noise.unwrap_or(n.read_noise);
    n.bits = a.bits.unwrap_or(n.bits);
    n.bias = a.bias.unwrap_or(n.bias);
    n.shot = !a.no_shot_noise;
    for (v, flag, max) in [
        (a.power_rms_pct, "--power-rms-pct", 20.0),
        (a.power_drift_pct, "--power-drift-pct", 50.0),
    ] {
        if let Some(v) = v
            && !(v.is_finite() && (0.0..max).contains(&v))
        {
            bail!(
                "{flag} must be at least 0 and under {max} (percent), got {}",
                crate::fmt::fmt_num(v)
            );
        }
    }
    let l = &mut c.laser;
    l.rms = a.power_rms_pct.map_or(l.rms, |v| v / 100.0);
    l.drift = a.power_drift_pct.map_or(l.drift, |v| v / 100.0);
    if let Some(i) = a.interaction {
        c.trace.interaction = match i {
            InteractionArg::Split => Interaction::Split,
            InteractionArg::Stochastic => Interaction::Stochastic,
        };
    }
    c.footprint = a.footprint.unwrap_or(c.footprint);
    // The simulator writes numbers out in full: 1e300 would be 300 digits.
    c.validate()
        .map_err(|e| anyhow::anyhow!(crate::fmt::short_numbers(&e)))?;
    Ok(c)
}

/// Default truth path: `scan.npy` -> `scan.truth.npy`.
pub fn default_truth_path(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    out.with_file_name(format!("{stem}.truth.npy"))
}

/// The simulator run over `cfg` on `threads` worker threads (default:
/// the global pool), `tick` called after each row.
pub fn simulate_with(
    cfg: &Config,
    threads: Option<u16>,
    tick: &(dyn Fn() + Sync),
) -> Result<cvm_sim::Scan> {
    match threads {
        Some(t) => rayon::ThreadPoolBuilder::new()
            .num_threads(usize::from(t))
            .build()
            .context("starting worker threads")?
            .install(|| cvm_sim::simulate(cfg, tick)),
        None => cvm_sim::simulate(cfg, tick),
    }
    .map_err(|e| anyhow::anyhow!(e))
}

pub fn run(a: &SimulateArgs) -> Result<()> {
    let cfg = config(a)?;
    let geometry = cvm_reference::Geometry::new(cfg.receiver.j1, cfg.receiver.j2)
        .map_err(|e| anyhow::anyhow!("--detector: {e}"))?;
    let truth_path = a
        .truth
        .clone()
        .unwrap_or_else(|| default_truth_path(&a.out));
    if a.out.as_os_str() == "-" || truth_path.as_os_str() == "-" {
        bail!("simulate writes two .npy files (scan and truth mask): give both file names, not -");
    }
    if crate::out::same_destination(&truth_path, &a.out) {
        bail!(
            "--truth and --output name the same file {}",
            a.out.display()
        );
    }
    let bar = ProgressBar::with_draw_target(
        Some(cfg.raster.rows as u64),
        if std::io::stderr().is_terminal() {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        },
    );
    bar.set_style(
        ProgressStyle::with_template("simulating {bar:40} {pos}/{len} rows  {elapsed} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let start = Instant::now();
    let tick = || bar.inc(1);
    let scan = simulate_with(&cfg, a.threads, &tick)?;
    bar.finish_and_clear();
    let secs = start.elapsed().as_secs_f64();
    crate::npy::write_scan_u16(&a.out, scan.rows, scan.cols, geometry, &scan.data)?;
    let mask = crate::npy::Mask {
        rows: scan.rows,
        cols: scan.cols,
        data: scan.truth.clone(),
    };
    crate::npy::write_mask(&truth_path, &mask)?;
    let _ = writeln!(
        std::io::stderr(),
        "dmap simulate: {}x{} positions x {}x{} cells in {secs:.1} s -> {} and {} ({} defect positions)",
        scan.rows,
        scan.cols,
        scan.j1,
        scan.j2,
        a.out.display(),
        truth_path.display(),
        scan.truth.iter().filter(|&&t| t).count()
    );
    let _ = writeln!(std::io::stderr(), "{}", budget_summary(&scan, &cfg));
    Ok(())
}

/// Where the beams' power went and how many samples clipped, one line
/// (what `dmap simulate` prints after the scan, and the Python package
/// returns).
pub fn budget_summary(scan: &cvm_sim::Scan, cfg: &Config) -> String {
    let b = scan.budget;
    let beams = (scan.rows * scan.cols) as f64;
    let pct = |v: f64| 100.0 * v / beams;
    format!(
        "beam power: detected {:.2} %, outside receiver aperture {:.2} %, beside detector {:.2} %, backward {:.2} %, part rim {:.2} %, below cut-off {:.2e} %; {} samples clipped at full scale {}",
        pct(b.detected),
        pct(b.aperture),
        pct(b.off_detector),
        pct(b.backward),
        pct(b.edge),
        pct(b.truncated),
        scan.saturated,
        cfg.noise.full_scale()
    )
}
