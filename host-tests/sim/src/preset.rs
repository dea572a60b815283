//! The two scanner set-ups of the paper.
//!
//! Values the paper gives: raster size, detector size, pitch, part type,
//! bubble radii and places, surface defect sizes. The rest (lens
//! prescriptions, beam waist, receiver optics, noise, laser power) is chosen here so the
//! part's own deflection sweeps the spot over a good part of the detector
//! without leaving it, as in the paper's maps.

use crate::detector::Noise;
use crate::laser::Laser;
use crate::part::{Bubble, Face, Part, Shape, SurfaceDefect};
use crate::scan::{Config, Raster};
use crate::trace::{Receiver, TraceOptions};
use crate::vec3::Vec3;

/// Simulated experiment (Sec. 4.1): 300x300 positions at 334 um through a
/// double-convex lens (f about 1 m, 150 mm across) with nine air bubbles,
/// read by a 15x15 detector. Like the paper's renderer, rays land as points
/// on the detector (no point spread), which gives the grid-like artefacts
/// where the spot crosses cell borders.
pub fn paper_sim(defect_free: bool) -> Config {
    let thickness = 10.0;
    let mut bubbles = Vec::new();
    if !defect_free {
        // Three groups (lower left, centre, upper right), each with one
        // bubble of every radius, 5 mm apart along x at mid-thickness.
        for (gx, gy) in [(-35.0, -35.0), (0.0, 0.0), (35.0, 35.0)] {
            for (k, r) in [0.083, 0.167, 0.334].into_iter().enumerate() {
                bubbles.push(Bubble {
                    center: Vec3::new(gx + 5.0 * (k as f64 - 1.0), gy, thickness / 2.0),
                    radius: r,
                    index: 1.0,
                });
            }
        }
    }
    Config {
        raster: Raster {
            rows: 300,
            cols: 300,
            pitch: 0.334,
            center: (0.0, 0.0),
            waist: 0.25,
            rays: 64,
        },
        part: Part {
            shape: Shape::DoubleConvex {
                r1: 1000.0,
                r2: 1000.0,
                thickness,
                diameter: 150.0,
            },
            index: 1.5,
            bubbles,
            defects: vec![],
            scatterers: vec![],
        },
        receiver: Receiver {
            focal: 50.0,
            distance: 100.0,
            aperture: 100.0,
            j1: 15,
            j2: 15,
            pixel: 0.6,
            spot: 0.0,
        },
        noise: default_noise(),
        laser: default_laser(),
        trace: TraceOptions::default(),
        footprint: 1.0,
        seed: 1,
    }
}

/// Empirical experiment (Sec. 4.2) re-created: 39x39 positions at 334 um
/// through a plano-convex cylindrical lens, 9x9 detector, a 2.8 x 2.8 mm
/// rough patch upper left and a 4 x 4 mm one lower right on the front face.
/// A real receiver blurs the spot (here a Gaussian of half a pixel rms), so
/// the spot crosses cell borders smoothly.
pub fn prototype(defect_free: bool) -> Config {
    let defects = if defect_free {
        vec![]
    } else {
        vec![
            rough_patch(-3.0, 3.0, 2.8, 2.8, 11),
            rough_patch(3.0, -3.0, 4.0, 4.0, 12),
        ]
    };
    Config {
        raster: Raster {
            rows: 39,
            cols: 39,
            pitch: 0.334,
            center: (0.0, 0.0),
            waist: 0.25,
            rays: 256,
        },
        part: Part {
            shape: Shape::Cylindrical {
                radius: 50.0,
                thickness: 5.0,
                width: 25.0,
                length: 25.0,
            },
            index: 1.5,
            bubbles: vec![],
            defects,
            scatterers: vec![],
        },
        receiver: Receiver {
            focal: 50.0,
            distance: 100.0,
            aperture: 60.0,
            j1: 9,
            j2: 9,
            pixel: 1.0,
            spot: 0.5,
        },
        noise: default_noise(),
        laser: default_laser(),
        trace: TraceOptions::default(),
        footprint: 1.0,
        seed: 1,
    }
}

/// A square rough patch of the front face centred at (cx, cy) mm.
pub fn rough_patch(cx: f64, cy: f64, w: f64, h: f64, seed: u64) -> SurfaceDefect {
    SurfaceDefect {
        face: Face::Front,
        x0: cx - w / 2.0,
        x1: cx + w / 2.0,
        y0: cy - h / 2.0,
        y1: cy + h / 2.0,
        tilt_sigma: 0.1,
        facet: 0.2,
        seed,
    }
}

/// 12-bit ADC; the whole beam on one cell gives about 3100 counts with
/// 1 % shot noise, and read noise under one count.
pub fn default_noise() -> Noise {
    Noise {
        photons: 100_000.0,
        gain: 32.0,
        read_noise: 20.0,
        bits: 12,
        bias: 0.0,
        shot: true,
    }
}

/// The source: 1 % rms power fluctuation from beam to beam and a slow drift
/// of up to +-2 % over a scan (see docs/experiments.md, "Noise model"):
/// the upper end of what an unstabilised laser-diode module delivers with
/// a part reflecting some 4 % back into it, chosen so that comparisons of
/// normalised and raw maps do not flatter raw maps.
pub fn default_laser() -> Laser {
    Laser {
        rms: 0.01,
        drift: 0.02,
    }
}
