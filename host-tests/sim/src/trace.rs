//! Ray tracing through the part and onto the detector.

use rand::{Rng, RngExt};

use crate::optics::{fresnel_reflectance, reflect, refract};
use crate::part::{Body, Face, sphere_interval};
use crate::vec3::Vec3;

/// Distance (mm) a ray must travel before it can meet a surface again:
/// keeps a ray from re-hitting the surface it has just left through rounding.
const EPS: f64 = 1e-7;

/// How a ray meeting an interface is split between reflection and refraction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interaction {
    /// Follow both, weighted by the Fresnel reflectance (deterministic).
    Split,
    /// Follow one, chosen at random with the Fresnel probabilities (weight kept).
    Stochastic,
}

/// Receiving lens and detector array (Fig. 1 of the paper).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Receiver {
    /// Focal length of the receiving lens (mm).
    pub focal: f64,
    /// Distance of the receiving lens behind the back vertex of the part (mm).
    pub distance: f64,
    /// Radius of the receiving lens's clear aperture (mm).
    pub aperture: f64,
    /// Detector rows (j1, along -y) and columns (j2, along +x).
    pub j1: usize,
    pub j2: usize,
    /// Detector pixel pitch (mm).
    pub pixel: f64,
    /// Standard deviation (mm) of the receiver's Gaussian point spread in
    /// the focal plane (diffraction, aberrations, beam divergence); 0 = a
    /// geometric point per ray.
    pub spot: f64,
}

impl Receiver {
    /// Detector position `(u, v)` in the focal plane of a ray of direction
    /// `d` (d.z > 0): `f tan(alpha)` along the ray's azimuth.
    pub fn focal_plane(&self, d: Vec3) -> (f64, f64) {
        (self.focal * d.x / d.z, self.focal * d.y / d.z)
    }

    /// Detector cell `(j1, j2)` of a focal-plane position, if on the array.
    /// The optical axis meets the array at its centre.
    pub fn cell(&self, u: f64, v: f64) -> Option<(usize, usize)> {
        let c2 = (u / self.pixel + self.j2 as f64 / 2.0).floor();
        let c1 = (-v / self.pixel + self.j1 as f64 / 2.0).floor();
        (c1 >= 0.0 && c2 >= 0.0 && c1 < self.j1 as f64 && c2 < self.j2 as f64)
            .then_some((c1 as usize, c2 as usize))
    }

    /// Spread weight `w` landing at `(u, v)` over the cells with the
    /// Gaussian point spread (exact cell integrals, separable per axis);
    /// returns the weight that fell on the array. `scratch` is reused storage.
    pub fn spread(&self, u: f64, v: f64, w: f64, map: &mut [f64], scratch: &mut Vec<f64>) -> f64 {
        self.spread_sigma(u, v, w, self.spot, map, scratch)
    }

    /// [`spread`](Self::spread) with a Gaussian of rms `sigma` (mm, > 0)
    /// instead of the receiver's spot.
    pub fn spread_sigma(
        &self,
        u: f64,
        v: f64,
        w: f64,
        sigma: f64,
        map: &mut [f64],
        scratch: &mut Vec<f64>,
    ) -> f64 {
        let axis = |x: f64, n: usize, out: &mut Vec<f64>| {
            // Cell c spans [(c - n/2) p, (c + 1 - n/2) p] in the axis coordinate.
            let s = sigma * std::f64::consts::SQRT_2;
            let mut prev = erf((-(n as f64) / 2.0 * self.pixel - x) / s);
            for c in 0..n {
                let next = erf(((c as f64 + 1.0 - n as f64 / 2.0) * self.pixel - x) / s);
                out.push(0.5 * (next - prev));
                prev = next;
            }
        };
        scratch.clear();
        axis(-v, self.j1, scratch);
        axis(u, self.j2, scratch);
        let (rows, cols) = scratch.split_at(self.j1);
        for (a, &fa) in rows.iter().enumerate() {
            for (b, &fb) in cols.iter().enumerate() {
                map[a * self.j2 + b] += w * fa * fb;
            }
        }
        w * rows.iter().sum::<f64>() * cols.iter().sum::<f64>()
    }
}

/// Error function (Abramowitz & Stegun 7.1.26, absolute error below 1.5e-7,
/// far below detector noise).
pub fn erf(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let y = 1.0 - poly * (-x * x).exp();
    if x < 0.0 { -y } else { y }
}

/// Where the power of traced rays went (fractions of the beam power).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Budget {
    pub detected: f64,
    /// Outside the receiving lens aperture.
    pub aperture: f64,
    /// Through the aperture but beside the detector array.
    pub off_detector: f64,
    /// Travelling back towards the source.
    pub backward: f64,
    /// Absorbed by the ground rim of the part.
    pub edge: f64,
    /// Dropped by the weight or interaction-count cut-offs.
    pub truncated: f64,
}

impl Budget {
    pub fn add(&mut self, o: &Budget) {
        self.detected += o.detected;
        self.aperture += o.aperture;
        self.off_detector += o.off_detector;
        self.backward += o.backward;
        self.edge += o.edge;
        self.truncated += o.truncated;
    }

    pub fn total(&self) -> f64 {
        self.detected
            + self.aperture
            + self.off_detector
            + self.backward
            + self.edge
            + self.truncated
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Medium {
    Air,
    Glass,
    Bubble(usize),
}

#[derive(Clone, Copy, Debug)]
struct Ray {
    p: Vec3,
    d: Vec3,
    w: f64,
    medium: Medium,
    events: u32,
    /// Fraction of `w` scattered into a halo on the way in (0 for most rays).
    halo: f64,
    /// The halo's rms angle per axis (radians).
    halo_width: f64,
}

/// Options of the tracer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraceOptions {
    pub interaction: Interaction,
    /// Rays below this weight (fraction of the beam power) are dropped.
    pub min_weight: f64,
    /// Rays with more interface events than this are dropped.
    pub max_events: u32,
}

impl Default for TraceOptions {
    fn default() -> Self {
        Self {
            interaction: Interaction::Split,
            min_weight: 1e-9,
            max_events: 40,
        }
    }
}

/// Traces rays of one beam; owns the scratch stack so it is allocated once per thread.
pub struct Tracer<'a> {
    pub body: &'a Body,
    pub receiver: &'a Receiver,
    pub options: TraceOptions,
    stack: Vec<Ray>,
    spread: Vec<f64>,
    /// When set, rays leaving the part forward are collected here
    /// `(point, direction, weight)` instead of being sent to the receiver.
    pub exits: Option<Vec<(Vec3, Vec3, f64)>>,
}

impl<'a> Tracer<'a> {
    pub fn new(body: &'a Body, receiver: &'a Receiver, options: TraceOptions) -> Self {
        Self {
            body,
            receiver,
            options,
            stack: Vec::with_capacity(64),
            spread: Vec::new(),
            exits: None,
        }
    }

    /// Trace one ray starting in air at `p` with unit direction `d` and
    /// weight `w`, adding what reaches the detector into `map` (row-major
    /// `j1 x j2`) and accounting for every bit of power in `budget`.
    pub fn trace<R: Rng>(
        &mut self,
        p: Vec3,
        d: Vec3,
        w: f64,
        rng: &mut R,
        map: &mut [f64],
        budget: &mut Budget,
    ) {
        self.stack.clear();
        self.stack.push(Ray {
            p,
            d,
            w,
            medium: Medium::Air,
            events: 0,
            halo: 0.0,
            halo_width: 0.0,
        });
        while let Some(r) = self.stack.pop() {
            if r.w < self.options.min_weight || r.events > self.options.max_events {
                budget.truncated += r.w;
                continue;
            }
            match r.medium {
                Medium::Air => self.in_air(r, rng, map, budget),
                Medium::Glass => self.in_glass(r, rng, budget),
                Medium::Bubble(i) => self.in_bubble(r, i, rng, budget),
            }
        }
    }

    fn in_air<R: Rng>(&mut self, r: Ray, rng: &mut R, map: &mut [f64], budget: &mut Budget) {
        match self.body.interval(r.p, r.d) {
            Some((enter, _)) if enter.t > EPS => {
                if enter.face == Face::Edge {
                    budget.edge += r.w;
                    return;
                }
                let q = r.p + r.d * enter.t;
                let n = self.body.normal(&enter, q);
                let n_in = self.body.index;
                let r = self.scatter_on_entry(r, enter.face, q);
                self.interface(r, q, n, 1.0, n_in, Medium::Glass, Medium::Air, rng);
            }
            _ => self.receive(r, map, budget),
        }
    }

    /// A beam ray entering the front face through a scattering disc carries
    /// the disc's share as halo from here on; only the first entry counts,
    /// since light reflected back inside has already crossed the disc.
    fn scatter_on_entry(&self, r: Ray, face: Face, q: Vec3) -> Ray {
        if r.events != 0 || face != Face::Front {
            return r;
        }
        match self.body.scatterers.iter().find(|s| s.contains(q.x, q.y)) {
            Some(s) => Ray {
                halo: s.share,
                halo_width: s.width,
                ..r
            },
            None => r,
        }
    }

    fn in_glass<R: Rng>(&mut self, r: Ray, rng: &mut R, budget: &mut Budget) {
        let Some((_, leave)) = self.body.interval(r.p, r.d) else {
            // Only reachable through rounding at grazing incidence.
            budget.truncated += r.w;
            return;
        };
        let mut hit: Option<(f64, usize)> = None;
        for (i, b) in self.body.bubbles.iter().enumerate() {
            if let Some((t0, _)) = sphere_interval(b.center, b.radius, r.p, r.d)
                && t0 > EPS
                && t0 < hit.map_or(leave.t, |h| h.0)
            {
                hit = Some((t0, i));
            }
        }
        let n_glass = self.body.index;
        if let Some((t, i)) = hit {
            let b = self.body.bubbles[i];
            let q = r.p + r.d * t;
            let n = (q - b.center).normalized();
            self.interface(
                r,
                q,
                n,
                n_glass,
                b.index,
                Medium::Bubble(i),
                Medium::Glass,
                rng,
            );
        } else if leave.t > EPS {
            if leave.face == Face::Edge {
                budget.edge += r.w;
                return;
            }
            let q = r.p + r.d * leave.t;
            let n = self.body.normal(&leave, q);
            self.interface(r, q, n, n_glass, 1.0, Medium::Air, Medium::Glass, rng);
        } else {
            budget.truncated += r.w;
        }
    }

    fn in_bubble<R: Rng>(&mut self, r: Ray, i: usize, rng: &mut R, budget: &mut Budget) {
        let b = self.body.bubbles[i];
        match sphere_interval(b.center, b.radius, r.p, r.d) {
            Some((_, t1)) if t1 > EPS => {
                let q = r.p + r.d * t1;
                let n = (q - b.center).normalized();
                self.interface(
                    r,
                    q,
                    n,
                    b.index,
                    self.body.index,
                    Medium::Glass,
                    Medium::Bubble(i),
                    rng,
                );
            }
            _ => budget.truncated += r.w,
        }
    }

    /// Split (or choose) between refraction into `n2` and reflection back
    /// into `n1` at point `q` of a surface with normal `n` (either orientation).
    #[allow(clippy::too_many_arguments)]
    fn interface<R: Rng>(
        &mut self,
        r: Ray,
        q: Vec3,
        n: Vec3,
        n1: f64,
        n2: f64,
        through: Medium,
        back: Medium,
        rng: &mut R,
    ) {
        let facing = if n.dot(r.d) < 0.0 { n } else { -n };
        let cos_i = -facing.dot(r.d);
        let refl = fresnel_reflectance(cos_i, n1, n2);
        let events = r.events + 1;
        let reflected = Ray {
            p: q,
            d: reflect(r.d, facing).normalized(),
            w: r.w,
            medium: back,
            events,
            ..r
        };
        let Some(t) = refract(r.d, facing, n1 / n2) else {
            self.stack.push(reflected);
            return;
        };
        let transmitted = Ray {
            p: q,
            d: t.normalized(),
            w: r.w,
            medium: through,
            events,
            ..r
        };
        match self.options.interaction {
            Interaction::Split => {
                if refl > 0.0 {
                    self.stack.push(Ray {
                        w: r.w * refl,
                        ..reflected
                    });
                }
                self.stack.push(Ray {
                    w: r.w * (1.0 - refl),
                    ..transmitted
                });
            }
            Interaction::Stochastic => {
                if rng.random::<f64>() < refl {
                    self.stack.push(reflected);
                } else {
                    self.stack.push(transmitted);
                }
            }
        }
    }

    fn receive(&mut self, r: Ray, map: &mut [f64], budget: &mut Budget) {
        if r.d.z <= 0.0 {
            budget.backward += r.w;
            return;
        }
        if let Some(exits) = self.exits.as_mut() {
            exits.push((r.p, r.d, r.w));
            return;
        }
        let rx = self.receiver;
        let t = (self.body.z_max + rx.distance - r.p.z) / r.d.z;
        let q = r.p + r.d * t;
        if q.x * q.x + q.y * q.y > rx.aperture * rx.aperture {
            budget.aperture += r.w;
            return;
        }
        let (u, v) = rx.focal_plane(r.d);
        let r = if r.halo > 0.0 {
            // The halo is centred where the unscattered light lands: the
            // lobe's angles add to the ray's own, and f tan(alpha) is close
            // to linear over them (0.2 % at 0.06 rad).
            let h = r.w * r.halo;
            let sigma = (rx.focal * r.halo_width).hypot(rx.spot);
            let on = rx.spread_sigma(u, v, h, sigma, map, &mut self.spread);
            budget.detected += on;
            budget.off_detector += h - on;
            Ray { w: r.w - h, ..r }
        } else {
            r
        };
        if rx.spot > 0.0 {
            let on = rx.spread(u, v, r.w, map, &mut self.spread);
            budget.detected += on;
            budget.off_detector += r.w - on;
            return;
        }
        match rx.cell(u, v) {
            Some((a, b)) => {
                map[a * rx.j2 + b] += r.w;
                budget.detected += r.w;
            }
            None => budget.off_detector += r.w,
        }
    }
}
