//! Scans `scan[row, col, j1, j2]` read whole into memory, and written.

use anyhow::{Result, anyhow, bail};
use cvm_reference::Geometry;
use npyz::{NpyFile, TypeChar};
use std::path::Path;

use crate::npy::format::{check_len, decode, open_npy, plain, read_bytes, to_f64, write_npy};

/// Element type a scan was stored with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScanDtype {
    /// `uint8`
    U8,
    /// `uint16` (raw ADC counts, the native format)
    U16,
    /// `uint32`
    U32,
    /// `float32`
    F32,
    /// `float64`
    F64,
}

impl ScanDtype {
    /// Bytes per sample.
    pub fn item(self) -> usize {
        match self {
            Self::U8 => 1,
            Self::U16 => 2,
            Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    /// NumPy's name of the dtype.
    pub fn name(self) -> &'static str {
        match self {
            Self::U8 => "uint8",
            Self::U16 => "uint16",
            Self::U32 => "uint32",
            Self::F32 => "float32",
            Self::F64 => "float64",
        }
    }
}

/// A scan: `rows x cols` beam positions, each a `J1 x J2` deflection map,
/// held as `f64` in C order (`data[((row * cols + col) * J1 + j1) * J2 + j2]`).
#[derive(Clone, Debug, PartialEq)]
pub struct Scan {
    /// Positions along the slow axis (`m2`).
    pub rows: usize,
    /// Positions along the fast axis (`m1`).
    pub cols: usize,
    /// Detector geometry.
    pub geometry: Geometry,
    /// The samples, finite and non-negative.
    pub data: Vec<f64>,
    /// The dtype the file stored.
    pub dtype: ScanDtype,
}

impl Scan {
    /// The deflection map at `(row, col)`.
    ///
    /// # Panics
    /// If the position is outside the scan.
    pub fn map(&self, row: usize, col: usize) -> &[f64] {
        let n = self.geometry.cells();
        let at = (row * self.cols + col) * n;
        &self.data[at..at + n]
    }

    /// The samples as `u16` counts, the firmware's input. Fails if any value
    /// is not an integer in `0..=65535` (a float scan of counts converts; a
    /// `uint32` scan converts if it stays in range).
    pub fn to_u16(&self) -> Result<Vec<u16>> {
        self.data
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                if x.fract() == 0.0 && (0.0..=65535.0).contains(&x) {
                    Ok(x as u16)
                } else {
                    let (pos, cell) = self.locate(i);
                    Err(anyhow!(
                        "{} scan value {x} at {pos:?} cell {cell:?} is not a u16 count (integer 0..=65535)",
                        self.dtype.name()
                    ))
                }
            })
            .collect()
    }

    /// `(row, col)` and `(j1, j2)` of flat index `i`.
    fn locate(&self, i: usize) -> ((usize, usize), (usize, usize)) {
        let n = self.geometry.cells();
        let p = i / n;
        ((p / self.cols, p % self.cols), self.geometry.cell(i % n))
    }

    /// Read a scan file (see [`read_scan`]).
    pub fn read(path: &Path) -> Result<Self> {
        read_scan(path)
    }
}

/// Read a scan `scan[row, col, j1, j2]` (C order; dtype uint8, uint16,
/// uint32, float32 or float64, either byte order).
///
/// Rejected, each with a one-line error naming the file: anything that is
/// not a `.npy` file, Fortran order, a rank other than 4, another dtype, a
/// detector axis of 0 or over 16 cells, an empty scan (no rows or columns),
/// a file shorter or longer than its header says, and NaN, infinite or
/// negative samples.
pub fn read_scan(path: &Path) -> Result<Scan> {
    scan_from_bytes(path, &read_bytes(path)?)
}

/// [`read_scan`] of a file already in memory; `path` only names it in errors.
pub fn scan_from_bytes(path: &Path, bytes: &[u8]) -> Result<Scan> {
    let npy = open_npy(path, bytes)?;
    let p = path.display();
    let (rows, cols, geometry) = scan_shape(path, &npy)?;
    let dtype = npy.dtype();
    let (data, kind) = match plain(&dtype) {
        Some((TypeChar::Uint, 1)) => (to_f64(decode::<u8>(path, npy)?), ScanDtype::U8),
        Some((TypeChar::Uint, 2)) => (to_f64(decode::<u16>(path, npy)?), ScanDtype::U16),
        Some((TypeChar::Uint, 4)) => (to_f64(decode::<u32>(path, npy)?), ScanDtype::U32),
        Some((TypeChar::Float, 4)) => (to_f64(decode::<f32>(path, npy)?), ScanDtype::F32),
        Some((TypeChar::Float, 8)) => (decode::<f64>(path, npy)?, ScanDtype::F64),
        _ => bail!(
            "{p}: unsupported dtype {} (scans must be uint8, uint16, uint32, float32 or float64)",
            dtype.descr()
        ),
    };
    let scan = Scan {
        rows,
        cols,
        geometry,
        data,
        dtype: kind,
    };
    if let Some(i) = scan.data.iter().position(|x| !(x.is_finite() && *x >= 0.0)) {
        let (pos, cell) = scan.locate(i);
        bail!(
            "{p}: sample {} at position {pos:?} cell {cell:?} is not a finite non-negative intensity",
            scan.data[i]
        );
    }
    Ok(scan)
}

/// Rows, columns and detector geometry of a scan's header.
pub(super) fn scan_shape(path: &Path, npy: &NpyFile<&[u8]>) -> Result<(usize, usize, Geometry)> {
    check_shape(path, npy.shape())
}

/// Rows, columns and detector geometry of a scan's shape, checked.
pub(super) fn check_shape(path: &Path, shape: &[u64]) -> Result<(usize, usize, Geometry)> {
    let p = path.display();
    let shape: Vec<u64> = shape.to_vec();
    if shape.len() != 4 {
        bail!(
            "{p}: a scan must have rank 4 (rows, cols, J1, J2), got shape {shape:?} (rank {})",
            shape.len()
        );
    }
    let dim = |i: usize| {
        usize::try_from(shape[i]).map_err(|_| anyhow!("{p}: shape {shape:?} is too large"))
    };
    let (rows, cols, j1, j2) = (dim(0)?, dim(1)?, dim(2)?, dim(3)?);
    let geometry = Geometry::new(j1, j2).map_err(|e| anyhow!("{p}: {e}"))?;
    if rows == 0 || cols == 0 {
        bail!("{p}: empty scan (shape {shape:?} has no beam positions)");
    }
    Ok((rows, cols, geometry))
}

/// Write a scan of `u16` counts, shape `(rows, cols, J1, J2)`.
pub fn write_scan_u16(
    path: &Path,
    rows: usize,
    cols: usize,
    geometry: Geometry,
    data: &[u16],
) -> Result<()> {
    check_len(path, data.len(), rows * cols * geometry.cells())?;
    let shape = [rows, cols, geometry.j1(), geometry.j2()].map(|d| d as u64);
    write_npy(path, &shape, data)
}

/// Write a scan as float64, shape `(rows, cols, J1, J2)`.
pub fn write_scan_f64(
    path: &Path,
    rows: usize,
    cols: usize,
    geometry: Geometry,
    data: &[f64],
) -> Result<()> {
    check_len(path, data.len(), rows * cols * geometry.cells())?;
    let shape = [rows, cols, geometry.j1(), geometry.j2()].map(|d| d as u64);
    write_npy(path, &shape, data)
}
