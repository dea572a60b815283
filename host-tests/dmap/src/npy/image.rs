//! Gradient images `(rows, cols, 3)` float64 and boolean masks
//! `(rows, cols)`: read, written, and a gradient written a band at a time.

use anyhow::{Context, Result, anyhow, bail};
use npyz::{TypeChar, WriterBuilder};
use std::io::Write;
use std::path::Path;

use crate::npy::format::{
    check_len, decode, encode_npy, map_file, open_npy, plain, read_bytes, to_f64, write_npy,
};

/// A gradient image written a few rows at a time (float64, shape
/// `(rows, cols, 3)`), so that it need not be held whole.
pub struct GradientWriter<'a> {
    w: npyz::NpyWriter<f64, &'a mut dyn Write>,
    name: String,
    left: usize,
}

impl<'a> GradientWriter<'a> {
    /// Starts the file on `out`; `name` names it in errors.
    pub fn new(out: &'a mut dyn Write, name: String, rows: usize, cols: usize) -> Result<Self> {
        let w = npyz::WriteOptions::new()
            .default_dtype()
            .shape(&[rows as u64, cols as u64, 3])
            .writer(out)
            .begin_nd()
            .map_err(|e| anyhow!("{name}: cannot write: {e}"))?;
        Ok(GradientWriter {
            w,
            name,
            left: rows * cols * 3,
        })
    }

    /// The next values, `[g0, g1, magnitude]` per position in raster order.
    pub fn push(&mut self, values: &[f64]) -> Result<()> {
        if values.len() > self.left {
            bail!("{}: more values than the shape holds", self.name);
        }
        self.left -= values.len();
        self.w
            .extend(values.iter().copied())
            .map_err(|e| anyhow!("{}: cannot write: {e}", self.name))
    }

    /// Ends the file; fails if the shape is not filled.
    pub fn finish(self) -> Result<()> {
        if self.left != 0 {
            bail!("{}: {} values short of the shape", self.name, self.left);
        }
        self.w
            .finish()
            .map_err(|e| anyhow!("{}: cannot write: {e}", self.name))
    }
}

/// Write a gradient image: float64, shape `(rows, cols, 3)` with
/// `[g0, g1, magnitude]` per position (docs/method.md §2).
pub fn write_gradient(path: &Path, rows: usize, cols: usize, data: &[f64]) -> Result<()> {
    write_gradient_to(
        &crate::out::Target::File(path.to_path_buf()),
        rows,
        cols,
        data,
    )
}

/// [`write_gradient`] to a file or standard output.
pub fn write_gradient_to(
    target: &crate::out::Target,
    rows: usize,
    cols: usize,
    data: &[f64],
) -> Result<()> {
    let name = target.name();
    if data.len() != rows * cols * 3 {
        bail!(
            "{name}: {} values do not fill the {} of the shape",
            data.len(),
            rows * cols * 3
        );
    }
    crate::out::write_target(target, |out| {
        encode_npy(&name, &[rows as u64, cols as u64, 3], data, out)
    })
}

/// A gradient image as written by [`write_gradient`].
#[derive(Clone, Debug, PartialEq)]
pub struct GradientImage {
    /// Rows of positions.
    pub rows: usize,
    /// Columns of positions.
    pub cols: usize,
    /// `rows * cols * 3` values `[g0, g1, magnitude]`, row-major.
    pub data: Vec<f64>,
}

/// Read a gradient image: float64 (or float32), shape `(rows, cols, 3)`.
pub fn read_gradient(path: &Path) -> Result<GradientImage> {
    gradient_from_bytes(path, &read_bytes(path)?)
}

/// [`read_gradient`] of a file already in memory; `path` only names it in errors.
pub fn gradient_from_bytes(path: &Path, bytes: &[u8]) -> Result<GradientImage> {
    let npy = open_npy(path, bytes)?;
    let p = path.display();
    let shape = npy.shape().to_vec();
    if shape.len() != 3 || shape[2] != 3 {
        bail!("{p}: a gradient image must have shape (rows, cols, 3), got {shape:?}");
    }
    let dtype = npy.dtype();
    let data = match plain(&dtype) {
        Some((TypeChar::Float, 8)) => decode::<f64>(path, npy)?,
        Some((TypeChar::Float, 4)) => to_f64(decode::<f32>(path, npy)?),
        _ => bail!(
            "{p}: unsupported dtype {} for a gradient image (float64 expected)",
            dtype.descr()
        ),
    };
    Ok(GradientImage {
        rows: shape[0] as usize,
        cols: shape[1] as usize,
        data,
    })
}

/// Rows and columns of a gradient image or a mask, from its header alone
/// (the file is mapped, not read): what `render` sizes its image by before
/// loading anything.
pub fn image_shape(path: &Path) -> Result<(usize, usize)> {
    let p = path.display();
    let map = map_file(path)?;
    let npy = open_npy(path, &map)?;
    let shape = npy.shape();
    let dim = |d: u64| usize::try_from(d).map_err(|_| anyhow!("{p}: shape {shape:?} is too large"));
    match shape {
        [rows, cols, 3] | [rows, cols] => Ok((dim(*rows)?, dim(*cols)?)),
        _ => bail!("{p}: a gradient image must have shape (rows, cols, 3), got {shape:?}"),
    }
}

/// A boolean mask over the scan positions (true on defects).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Mask {
    /// Rows of positions.
    pub rows: usize,
    /// Columns of positions.
    pub cols: usize,
    /// `rows * cols` flags, row-major.
    pub data: Vec<bool>,
}

/// Read a mask: dtype bool, shape `(rows, cols)`.
pub fn read_mask(path: &Path) -> Result<Mask> {
    mask_from_bytes(path, &read_bytes(path)?)
}

/// [`read_mask`] of a file already in memory; `path` only names it in errors.
pub fn mask_from_bytes(path: &Path, bytes: &[u8]) -> Result<Mask> {
    let npy = open_npy(path, bytes)?;
    let p = path.display();
    let shape = npy.shape().to_vec();
    if shape.len() != 2 {
        bail!("{p}: a mask must have shape (rows, cols), got {shape:?}");
    }
    let dtype = npy.dtype();
    if plain(&dtype) != Some((TypeChar::Bool, 1)) {
        bail!(
            "{p}: unsupported dtype {} for a mask (bool expected)",
            dtype.descr()
        );
    }
    let data = decode::<bool>(path, npy)?;
    Ok(Mask {
        rows: shape[0] as usize,
        cols: shape[1] as usize,
        data,
    })
}

/// Write a mask: dtype bool, shape `(rows, cols)`.
pub fn write_mask(path: &Path, mask: &Mask) -> Result<()> {
    check_len(path, mask.data.len(), mask.rows * mask.cols)?;
    write_npy(path, &[mask.rows as u64, mask.cols as u64], &mask.data)
        .with_context(|| format!("writing mask {}", path.display()))
}
