//! NumPy `.npy` files in the layouts of docs/method.md §2: scans
//! `scan[row, col, j1, j2]`, gradient images `(rows, cols, 3)` float64 and
//! boolean masks `(rows, cols)`.
//!
//! Every error is one line naming the file and the problem, because users
//! meet them in a terminal or a CI log.

use anyhow::{Context, Result, anyhow, bail};
use cvm_reference::Geometry;
use npyz::{DType, NpyFile, Order, TypeChar, WriterBuilder};
use std::io::Write;
use std::path::{Path, PathBuf};

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
    fn name(self) -> &'static str {
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

fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| anyhow!("{}: cannot read: {e}", path.display()))
}

/// The header of an in-memory `.npy` file, checked for what every reader
/// here needs: C order, no pickled objects, and exactly as many data bytes
/// as the shape and dtype say.
fn open_npy<'a>(path: &Path, bytes: &'a [u8]) -> Result<NpyFile<&'a [u8]>> {
    let p = path.display();
    if !bytes.starts_with(b"\x93NUMPY") {
        bail!("{p}: not a .npy file (no NumPy magic bytes)");
    }
    // The header's length field is checked against the file before the
    // parser sizes a buffer by it: a corrupt field must not ask for 4 GiB.
    let (len_at, len_bytes) = match (bytes.get(6), bytes.get(7)) {
        (Some(1), _) => (8, 2),
        (Some(2 | 3), _) => (8, 4),
        (Some(&major), Some(&minor)) => bail!(
            "{p}: .npy format version {major}.{minor} is not supported (versions 1.0, 2.0 and 3.0 are)"
        ),
        _ => bail!("{p}: not a valid .npy file (header truncated)"),
    };
    let header_len = bytes.get(len_at..len_at + len_bytes).map(|b| {
        b.iter()
            .rev()
            .fold(0usize, |acc, &x| (acc << 8) | usize::from(x))
    });
    let Some(header) =
        header_len.and_then(|n| bytes.get(len_at + len_bytes..len_at + len_bytes + n))
    else {
        bail!("{p}: not a valid .npy file (header truncated)");
    };
    // The header parser backtracks exponentially on deeply nested brackets.
    if nesting(header) > MAX_HEADER_NESTING {
        bail!("{p}: not a valid .npy file (header nested too deeply for a plain array)");
    }
    let npy = NpyFile::new(bytes).map_err(|e| {
        anyhow!(
            "{p}: not a valid .npy file (header unreadable or truncated): {}",
            one_line(&e.to_string())
        )
    })?;
    if npy.order() == Order::Fortran {
        bail!(
            "{p}: Fortran-order arrays are not supported; save it in C order (np.ascontiguousarray)"
        );
    }
    if npy.uses_pickled_array() {
        bail!("{p}: object arrays are not supported");
    }
    let item = npy
        .dtype()
        .num_bytes()
        .ok_or_else(|| anyhow!("{p}: unsupported dtype {}", npy.dtype().descr()))?;
    let want = npy
        .shape()
        .iter()
        .try_fold(item as u64, |acc, &d| acc.checked_mul(d))
        .ok_or_else(|| anyhow!("{p}: shape {:?} is too large", npy.shape()))?;
    let header = npy.header().clone();
    // NpyFile has consumed the header from the slice; what remains is data.
    let data = npy.into_inner();
    if data.len() as u64 != want {
        bail!(
            "{p}: holds {} data bytes but shape {:?} of {} needs {want} (truncated or corrupt file)",
            data.len(),
            header.shape(),
            header.dtype().descr()
        );
    }
    Ok(NpyFile::with_header(header, data))
}

/// Deepest bracket nesting in a header dict allowed through to the parser:
/// a plain array's header nests two deep (the dict, the shape tuple).
const MAX_HEADER_NESTING: usize = 3;

/// Deepest nesting of `{[(` brackets outside quoted strings.
fn nesting(header: &[u8]) -> usize {
    let (mut depth, mut deepest, mut quote) = (0usize, 0, None);
    for &b in header {
        match (quote, b) {
            (Some(q), _) if b == q => quote = None,
            (Some(_), _) => {}
            (None, b'\'' | b'"') => quote = Some(b),
            (None, b'{' | b'[' | b'(') => {
                depth += 1;
                deepest = deepest.max(depth);
            }
            (None, b'}' | b']' | b')') => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    deepest
}

fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

fn plain(dtype: &DType) -> Option<(TypeChar, u64)> {
    match dtype {
        DType::Plain(ts) => Some((ts.type_char(), ts.size_field())),
        _ => None,
    }
}

fn decode<T: npyz::Deserialize>(path: &Path, npy: NpyFile<&[u8]>) -> Result<Vec<T>> {
    npy.into_vec::<T>().map_err(|e| {
        anyhow!(
            "{}: cannot decode data: {}",
            path.display(),
            one_line(&e.to_string())
        )
    })
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

/// A file's bytes: mapped (read only) when the file can be, else read.
enum FileBytes {
    /// The mapping and the file it maps.
    Mapped(memmap2::Mmap, std::fs::File),
    Read(Vec<u8>),
}

impl std::ops::Deref for FileBytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            FileBytes::Mapped(m, _) => m,
            FileBytes::Read(v) => v,
        }
    }
}

/// Maps a regular file; reads anything else (a pipe, an empty file).
fn map_file(path: &Path) -> Result<FileBytes> {
    let p = path.display();
    let file = std::fs::File::open(path).map_err(|e| anyhow!("{p}: cannot read: {e}"))?;
    let meta = file
        .metadata()
        .map_err(|e| anyhow!("{p}: cannot read: {e}"))?;
    if meta.is_file() && meta.len() > 0 {
        // SAFETY: the mapping is read only, and it is read only while a
        // header is checked or a whole file is decoded, right after it is
        // made (a scan's samples are read with positioned reads, see
        // `ScanFile`): only a file truncated in that instant would fault.
        if let Ok(map) = unsafe { memmap2::Mmap::map(&file) } {
            let _ = map.advise(memmap2::Advice::Sequential);
            return Ok(FileBytes::Mapped(map, file));
        }
    }
    read_bytes(path).map(FileBytes::Read)
}

/// Rows, columns and detector geometry of a scan's header.
fn scan_shape(path: &Path, npy: &NpyFile<&[u8]>) -> Result<(usize, usize, Geometry)> {
    let p = path.display();
    let shape: Vec<u64> = npy.shape().to_vec();
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

/// A scan file whose samples are read and decoded a few maps at a time,
/// when asked, so that `score` and `stream` hold a few rows of a scan and a
/// scan larger than memory still goes through. Every header check of
/// [`read_scan`] applies when it is opened.
///
/// A regular file is read with positioned reads (not through a memory
/// mapping), so a file that shrinks during the run is an error naming the
/// position whose samples are gone, not a fault of the process. A pipe is
/// read whole.
pub struct ScanFile {
    path: PathBuf,
    samples: Samples,
    /// Where the samples start in the file.
    offset: usize,
    /// Positions along the slow axis.
    pub rows: usize,
    /// Positions along the fast axis.
    pub cols: usize,
    /// Detector geometry.
    pub geometry: Geometry,
    /// The dtype the file stores.
    pub dtype: ScanDtype,
    big_endian: bool,
}

/// Where a scan's samples come from.
enum Samples {
    /// A regular file, read when maps are asked for.
    File(std::fs::File),
    /// What could not be mapped (a pipe, `/dev/stdin`), read at open.
    Memory(Vec<u8>),
}

impl ScanFile {
    /// Opens `path` and checks its header and its length. What cannot be
    /// mapped (a pipe, `/dev/stdin`) is read into memory instead.
    pub fn open(path: &Path) -> Result<Self> {
        let p = path.display();
        let map = map_file(path)?;
        let bytes: &[u8] = &map;
        let npy = open_npy(path, bytes)?;
        let (rows, cols, geometry) = scan_shape(path, &npy)?;
        let dtype = npy.dtype();
        let kind = match plain(&dtype) {
            Some((TypeChar::Uint, 1)) => ScanDtype::U8,
            Some((TypeChar::Uint, 2)) => ScanDtype::U16,
            Some((TypeChar::Uint, 4)) => ScanDtype::U32,
            Some((TypeChar::Float, 4)) => ScanDtype::F32,
            Some((TypeChar::Float, 8)) => ScanDtype::F64,
            _ => bail!(
                "{p}: unsupported dtype {} (scans must be uint8, uint16, uint32, float32 or float64)",
                dtype.descr()
            ),
        };
        let big_endian = matches!(
            &dtype,
            DType::Plain(ts) if ts.endianness() == npyz::Endianness::Big
        );
        let offset = bytes.len() - npy.into_inner().len();
        let samples = match map {
            FileBytes::Mapped(_, file) => Samples::File(file),
            FileBytes::Read(bytes) => Samples::Memory(bytes),
        };
        Ok(ScanFile {
            path: path.to_path_buf(),
            samples,
            offset,
            rows,
            cols,
            geometry,
            dtype: kind,
            big_endian,
        })
    }

    fn item(&self) -> usize {
        match self.dtype {
            ScanDtype::U8 => 1,
            ScanDtype::U16 => 2,
            ScanDtype::U32 | ScanDtype::F32 => 4,
            ScanDtype::F64 => 8,
        }
    }

    /// Positions of the scan.
    pub fn maps(&self) -> usize {
        self.rows * self.cols
    }

    /// The samples of maps `first..first + out.len() / cells`, as f64,
    /// checked finite and non-negative.
    pub fn maps_f64(&self, first: usize, out: &mut [f64]) -> Result<()> {
        let n = self.geometry.cells();
        let item = self.item();
        let p = self.path.display();
        if first * n + out.len() > self.maps() * n {
            bail!(
                "{p}: maps from {first} on are outside the scan's {} positions",
                self.maps()
            );
        }
        let (start, len) = (self.offset + first * n * item, out.len() * item);
        let read;
        let bytes: &[u8] = match &self.samples {
            Samples::Memory(v) => &v[start..start + len],
            Samples::File(file) => {
                use std::os::unix::fs::FileExt;
                let mut buf = vec![0u8; len];
                file.read_exact_at(&mut buf, start as u64).map_err(|e| {
                    if e.kind() == std::io::ErrorKind::UnexpectedEof {
                        anyhow!(
                            "{p}: the file ends before the samples of positions {:?} to {:?}: it is shorter than when it was opened (truncated while being read?)",
                            self.locate(first * n).0,
                            self.locate((first * n + out.len()).max(1) - 1).0
                        )
                    } else {
                        anyhow!("{p}: cannot read: {e}")
                    }
                })?;
                read = buf;
                &read
            }
        };
        let be = self.big_endian;
        macro_rules! decode {
            ($t:ty) => {
                for (o, b) in out.iter_mut().zip(bytes.chunks_exact(item)) {
                    let b = b.try_into().expect("chunk of the item size");
                    *o = if be {
                        <$t>::from_be_bytes(b)
                    } else {
                        <$t>::from_le_bytes(b)
                    } as f64;
                }
            };
        }
        match self.dtype {
            ScanDtype::U8 => out.iter_mut().zip(bytes).for_each(|(o, &b)| *o = b.into()),
            ScanDtype::U16 => decode!(u16),
            ScanDtype::U32 => decode!(u32),
            ScanDtype::F32 => decode!(f32),
            ScanDtype::F64 => decode!(f64),
        }
        if let Some(i) = out.iter().position(|x| !(x.is_finite() && *x >= 0.0)) {
            let (pos, cell) = self.locate(first * n + i);
            bail!(
                "{}: sample {} at position {pos:?} cell {cell:?} is not a finite non-negative intensity",
                self.path.display(),
                out[i]
            );
        }
        Ok(())
    }

    /// The samples of maps `first..first + out.len() / cells` as `u16`
    /// counts, the firmware's input; fails on any value that is not an
    /// integer in `0..=65535`.
    pub fn maps_u16(&self, first: usize, out: &mut [u16], scratch: &mut Vec<f64>) -> Result<()> {
        let n = self.geometry.cells();
        scratch.resize(out.len(), 0.0);
        self.maps_f64(first, scratch)?;
        for (i, (o, &x)) in out.iter_mut().zip(scratch.iter()).enumerate() {
            if x.fract() == 0.0 && (0.0..=65535.0).contains(&x) {
                *o = x as u16;
            } else {
                let (pos, cell) = self.locate(first * n + i);
                bail!(
                    "{}: {} scan value {x} at {pos:?} cell {cell:?} is not a u16 count (integer 0..=65535)",
                    self.path.display(),
                    self.dtype.name()
                );
            }
        }
        Ok(())
    }

    /// Checks every sample (as [`Self::maps_f64`], or as counts with
    /// `counts`) before anything is written, a few rows at a time, and
    /// reports the first bad sample in file order.
    pub fn validate(&self, counts: bool) -> Result<()> {
        use rayon::prelude::*;
        let n = self.geometry.cells();
        let band = band_rows(self.cols, n);
        for r0 in (0..self.rows).step_by(band) {
            let r1 = (r0 + band).min(self.rows);
            let first_error = (r0..r1).into_par_iter().find_map_first(|r| {
                let mut f = vec![0.0; self.cols * n];
                let mut c = vec![0u16; self.cols * n];
                let res = if counts {
                    self.maps_u16(r * self.cols, &mut c, &mut f)
                } else {
                    self.maps_f64(r * self.cols, &mut f)
                };
                res.err()
            });
            if let Some(e) = first_error {
                return Err(e);
            }
        }
        Ok(())
    }

    fn locate(&self, i: usize) -> ((usize, usize), (usize, usize)) {
        let n = self.geometry.cells();
        let p = i / n;
        ((p / self.cols, p % self.cols), self.geometry.cell(i % n))
    }
}

/// Rows per band when a scan is processed a few rows at a time: about
/// 2^20 samples per band, at least one row.
pub fn band_rows(cols: usize, cells: usize) -> usize {
    ((1usize << 20) / (cols * cells).max(1)).max(1)
}

fn to_f64<T: Into<f64>>(v: Vec<T>) -> Vec<f64> {
    v.into_iter().map(Into::into).collect()
}

fn write_npy<T: npyz::AutoSerialize + Copy>(path: &Path, shape: &[u64], data: &[T]) -> Result<()> {
    crate::out::write_file(path, |out| {
        encode_npy(&path.display().to_string(), shape, data, out)
    })
}

/// `data` as a `.npy` file of `shape`, to `out`; `name` names it in errors.
fn encode_npy<T: npyz::AutoSerialize + Copy>(
    name: &str,
    shape: &[u64],
    data: &[T],
    out: &mut dyn Write,
) -> Result<()> {
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(shape)
        .writer(out)
        .begin_nd()
        .map_err(|e| anyhow!("{name}: cannot write: {e}"))?;
    w.extend(data.iter().copied())
        .map_err(|e| anyhow!("{name}: cannot write: {e}"))?;
    w.finish().map_err(|e| anyhow!("{name}: cannot write: {e}"))
}

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

fn check_len(path: &Path, got: usize, want: usize) -> Result<()> {
    if got == want {
        Ok(())
    } else {
        bail!(
            "{}: {got} values do not fill the {want} of the shape",
            path.display()
        )
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
