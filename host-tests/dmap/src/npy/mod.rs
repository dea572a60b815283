//! NumPy `.npy` files in the layouts of docs/method.md §2: scans
//! `scan[row, col, j1, j2]`, gradient images `(rows, cols, 3)` float64 and
//! boolean masks `(rows, cols)`.
//!
//! Every error is one line naming the file and the problem, because users
//! meet them in a terminal or a CI log.

mod format;
mod image;
mod scan;
mod scan_file;

pub use image::{
    GradientImage, GradientWriter, Mask, gradient_from_bytes, image_shape, mask_from_bytes,
    read_gradient, read_mask, write_gradient, write_gradient_to, write_mask,
};
pub use scan::{Scan, ScanDtype, read_scan, scan_from_bytes, write_scan_f64, write_scan_u16};
pub use scan_file::{ScanFile, band_rows};
