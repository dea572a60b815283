//! Exact f64 reference implementations of the deflection-map distances and
//! of the spread measures of a single map.
//!
//! Everything here is plain `f64`, written from the equations of the method's
//! paper (Eq. 1, 5, 6, 8, 9, 10) and the conventions fixed in the project's
//! design notes. It is the yardstick that the fixed-point core and the host
//! tools are checked against, so clarity and exactness come before speed;
//! the fast paths ([`cvm_sat`], [`CvmEmbedding`], [`Emd`]) are each checked
//! against the brute-force definitions in this crate's tests.
//!
//! Maps are row-major `&[f64]` of length `J1 * J2`, cell `(j1, j2)` (0-based)
//! at index `j1 * J2 + j2`. Raw maps are detector counts as `f64` and are
//! expected to be finite and non-negative.

mod brute;
mod embedding;
mod emd;
mod geometry;
mod gradient;
mod kernels;
mod linalg;
mod mean_dir;
mod min_cost_flow;
mod normalise;
mod sat;
mod spread;
mod tail;
mod transport;

pub use brute::{cvm_brute, lcd_brute};
pub use embedding::{CvmEmbedding, cvm_embedding};
pub use emd::{Emd, EmdMap, Ground, dark_lit_distance, emd, emd_1d_closed_form, emd_independent};
pub use geometry::{Geometry, GeometryError};
pub use gradient::{BruteCvm, MapDistance, gradient_image, gradient_image_fn};
pub use kernels::{ConfigError, CvmConfig, Kernel, KernelFamily, PaperWeights, box_range};
pub use linalg::cholesky_psd;
pub use mean_dir::{MeanDir, mean_dir, mean_direction};
pub use min_cost_flow::min_cost_transport;
pub use normalise::{Normalised, normalise};
pub use sat::{SummedAreaTable, cvm_sat};
pub use spread::{local_deviation, neighbour_gradient, outside_core, spread_moment};
pub use tail::{ExpTail, exp_tail, nearest_rank};
pub use transport::{transport_simplex, transport_simplex_checked};
