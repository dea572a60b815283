//! Ray model of a laser deflection scanner (Fig. 1 of the paper): a
//! collimated Gaussian beam is stepped over a raster, traced as many rays
//! through a transparent part (refraction by Snell's law at every surface,
//! Fresnel reflection, air bubbles, rough surface patches, scattering
//! regions that spread part of the light into a halo), collected by a
//! receiving lens that maps ray angle to detector position `f tan(alpha)`,
//! and read out by a noisy detector, the laser's power fluctuating from
//! beam to beam and drifting over the scan. Produces `scan[row, col, j1, j2]` and
//! a ground-truth defect mask.

pub mod beam;
pub mod detector;
pub mod laser;
pub mod optics;
pub mod part;
pub mod preset;
pub mod rng;
pub mod scan;
pub mod scatter;
pub mod trace;
pub mod vec3;

pub use detector::Noise;
pub use laser::Laser;
pub use part::{Bubble, Face, Part, Shape, SurfaceDefect};
pub use scan::{Config, Raster, Scan, simulate, truth_mask};
pub use scatter::Scatterer;
pub use trace::{Budget, Interaction, Receiver, TraceOptions, Tracer};
pub use vec3::Vec3;
