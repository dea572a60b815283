//! The scan: beam positions on a raster, one deflection map each, plus the
//! ground-truth mask of positions whose beam a defect touches.

use rayon::prelude::*;

use crate::beam;
use crate::detector::Noise;
use crate::laser::Laser;
use crate::optics::refract;
use crate::part::{Face, Part};
use crate::rng::position_rng;
use crate::trace::{Budget, Receiver, TraceOptions, Tracer};
use crate::vec3::Vec3;

/// The raster and the beam.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Raster {
    pub rows: usize,
    pub cols: usize,
    /// Distance between neighbouring beam positions (mm).
    pub pitch: f64,
    /// Position of the raster centre on the part (mm).
    pub center: (f64, f64),
    /// 1/e^2 intensity radius of the beam (mm).
    pub waist: f64,
    /// Approximate number of rays per beam.
    pub rays: usize,
}

impl Raster {
    /// Beam axis position of (row, col): columns run along +x, rows along -y
    /// (row 0 is the top of an image of the scan).
    pub fn position(&self, row: usize, col: usize) -> (f64, f64) {
        let x = self.center.0 + (col as f64 - (self.cols as f64 - 1.0) / 2.0) * self.pitch;
        let y = self.center.1 + ((self.rows as f64 - 1.0) / 2.0 - row as f64) * self.pitch;
        (x, y)
    }
}

/// Everything that defines a simulated scan.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    pub raster: Raster,
    pub part: Part,
    pub receiver: Receiver,
    pub noise: Noise,
    /// Power fluctuation and drift of the source.
    pub laser: Laser,
    pub trace: TraceOptions,
    /// Radius around the beam axis, in units of the waist, within which a
    /// defect counts as touching the beam in the truth mask.
    pub footprint: f64,
    pub seed: u64,
}

impl Config {
    pub fn validate(&self) -> Result<(), String> {
        let r = &self.raster;
        if r.rows == 0 || r.cols == 0 {
            return Err(format!(
                "raster must have at least one position, got {}x{}",
                r.rows, r.cols
            ));
        }
        if r.rows
            .checked_mul(r.cols)
            .and_then(|n| n.checked_mul(self.receiver.j1 * self.receiver.j2))
            .is_none_or(|n| n > 1 << 31)
        {
            return Err("scan too large (over 2^31 samples)".into());
        }
        for (v, what) in [
            (r.pitch, "pitch"),
            (r.waist, "beam waist"),
            (self.receiver.focal, "receiver focal length"),
            (self.receiver.pixel, "detector pixel pitch"),
            (self.receiver.aperture, "receiver aperture"),
            (self.receiver.distance, "receiver distance"),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{what} must be positive, got {v}"));
            }
        }
        if !(r.center.0.is_finite() && r.center.1.is_finite()) {
            return Err("raster centre must be finite".into());
        }
        if r.rays == 0 || r.rays > 1_000_000 {
            return Err(format!("rays per beam must be 1..=1000000, got {}", r.rays));
        }
        let rx = &self.receiver;
        if !(1..=64).contains(&rx.j1) || !(1..=64).contains(&rx.j2) {
            return Err(format!(
                "detector must be 1..=64 cells per axis, got {}x{}",
                rx.j1, rx.j2
            ));
        }
        if !(rx.spot.is_finite() && rx.spot >= 0.0) {
            return Err(format!("detector spot size must be >= 0, got {}", rx.spot));
        }
        if !(self.footprint.is_finite() && self.footprint >= 0.0) {
            return Err(format!(
                "truth footprint must be >= 0, got {}",
                self.footprint
            ));
        }
        self.part.validate()?;
        self.laser.validate()?;
        self.noise.validate()
    }
}

/// A simulated scan.
#[derive(Clone, Debug, PartialEq)]
pub struct Scan {
    pub rows: usize,
    pub cols: usize,
    pub j1: usize,
    pub j2: usize,
    /// `scan[row, col, j1, j2]`, C order, ADC counts.
    pub data: Vec<u16>,
    /// `truth[row, col]`.
    pub truth: Vec<bool>,
    /// Where the beam power went, summed over positions (in beams).
    pub budget: Budget,
    /// Samples at the ADC full scale (clipped).
    pub saturated: usize,
}

/// Noise-free deflection map (fractions of the beam power) of one position,
/// with its power budget; `rng` drives beam jitter and stochastic choices.
pub fn beam_map<R: rand::Rng>(
    cfg: &Config,
    tracer: &mut Tracer,
    x: f64,
    y: f64,
    rng: &mut R,
    rays: &mut Vec<(f64, f64, f64)>,
    map: &mut [f64],
) -> Budget {
    let mut budget = Budget::default();
    map.iter_mut().for_each(|m| *m = 0.0);
    beam::sample(cfg.raster.waist, cfg.raster.rays, rng, rays);
    let z0 = tracer.body.z_min - 1.0;
    let d = Vec3::new(0.0, 0.0, 1.0);
    for &(dx, dy, w) in rays.iter() {
        tracer.trace(Vec3::new(x + dx, y + dy, z0), d, w, rng, map, &mut budget);
    }
    budget
}

/// Simulate the whole scan in parallel. `progress` is called once per
/// finished row (from worker threads). Every position has its own random
/// stream, so the result does not depend on the number of threads.
pub fn simulate(cfg: &Config, progress: &(dyn Fn() + Sync)) -> Result<Scan, String> {
    cfg.validate()?;
    let body = cfg.part.body();
    let rx = cfg.receiver;
    let cells = rx.j1 * rx.j2;
    let fs = cfg.noise.full_scale();
    let rows: Vec<(Vec<u16>, Budget, usize)> = (0..cfg.raster.rows)
        .into_par_iter()
        .map(|row| {
            let mut tracer = Tracer::new(&body, &rx, cfg.trace);
            let mut rays = Vec::new();
            let mut map = vec![0.0; cells];
            let mut out = vec![0u16; cfg.raster.cols * cells];
            let mut budget = Budget::default();
            for col in 0..cfg.raster.cols {
                let mut rng = position_rng(cfg.seed, row, col);
                let (x, y) = cfg.raster.position(row, col);
                budget.add(&beam_map(
                    cfg,
                    &mut tracer,
                    x,
                    y,
                    &mut rng,
                    &mut rays,
                    &mut map,
                ));
                let power = cfg
                    .laser
                    .factor(cfg.seed, cfg.raster.rows, cfg.raster.cols, row, col);
                if power != 1.0 {
                    map.iter_mut().for_each(|m| *m *= power);
                }
                cfg.noise
                    .digitize(&map, &mut rng, &mut out[col * cells..(col + 1) * cells]);
            }
            let saturated = out.iter().filter(|&&v| v == fs).count();
            progress();
            (out, budget, saturated)
        })
        .collect();
    let mut data = Vec::with_capacity(cfg.raster.rows * cfg.raster.cols * cells);
    let mut budget = Budget::default();
    let mut saturated = 0;
    for (r, b, s) in rows {
        data.extend_from_slice(&r);
        budget.add(&b);
        saturated += s;
    }
    Ok(Scan {
        rows: cfg.raster.rows,
        cols: cfg.raster.cols,
        j1: rx.j1,
        j2: rx.j2,
        data,
        truth: truth_mask(cfg),
        budget,
        saturated,
    })
}

/// Ground truth: a position is defective when a defect lies within
/// `footprint * waist` of the beam axis, measured where the undisturbed
/// chief ray crosses the defect (its depth for a bubble, its face for a
/// surface defect, the front face for a scattering disc).
pub fn truth_mask(cfg: &Config) -> Vec<bool> {
    let body = cfg.part.body();
    let clean = Part {
        defects: vec![],
        bubbles: vec![],
        scatterers: vec![],
        ..cfg.part.clone()
    }
    .body();
    let reach = cfg.footprint * cfg.raster.waist;
    let mut mask = vec![false; cfg.raster.rows * cfg.raster.cols];
    for row in 0..cfg.raster.rows {
        for col in 0..cfg.raster.cols {
            let (x, y) = cfg.raster.position(row, col);
            let p0 = Vec3::new(x, y, body.z_min - 1.0);
            let d0 = Vec3::new(0.0, 0.0, 1.0);
            let Some((enter, _)) = clean.interval(p0, d0) else {
                continue;
            };
            if enter.face == Face::Edge {
                continue;
            }
            let p1 = p0 + d0 * enter.t;
            let Some(d1) = refract(d0, clean.normal(&enter, p1), 1.0 / clean.index) else {
                continue;
            };
            let Some((_, leave)) = clean.interval(p1, d1) else {
                continue;
            };
            let p2 = p1 + d1 * leave.t;
            let hit_bubble = body.bubbles.iter().any(|b| {
                let q = p1 + d1 * ((b.center.z - p1.z) / d1.z);
                (q.x - b.center.x).hypot(q.y - b.center.y) < b.radius + reach
            });
            let hit_surface = body.defects.iter().any(|s| {
                let q = if s.face == Face::Front { p1 } else { p2 };
                s.distance(q.x, q.y) < reach
            });
            // A scattering disc sits on the front face, like a front surface defect.
            let hit_scatter = body
                .scatterers
                .iter()
                .any(|s| (p1.x - s.x).hypot(p1.y - s.y) < s.radius + reach);
            mask[row * cfg.raster.cols + col] = hit_bubble || hit_surface || hit_scatter;
        }
    }
    mask
}
