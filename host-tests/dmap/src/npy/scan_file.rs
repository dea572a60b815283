//! The streaming reader of scans: a scan file opened with every header
//! check, its samples read a few maps at a time, so that a scan larger
//! than memory goes through `score` and `stream`.

use anyhow::{Result, anyhow, bail};
use cvm_reference::Geometry;
use npyz::{DType, TypeChar};
use std::path::{Path, PathBuf};

use crate::npy::format::{FileBytes, map_file, open_npy, plain};
use crate::npy::scan::{ScanDtype, check_shape, scan_shape};

/// A scan file whose samples are read and decoded a few maps at a time,
/// when asked, so that `score` and `stream` hold a few rows of a scan and a
/// scan larger than memory still goes through. Every header check of
/// [`read_scan`](crate::npy::read_scan) applies when it is opened.
///
/// A regular file is read with positioned reads (not through a memory
/// mapping), so a file that shrinks during the run is an error naming the
/// position whose samples are gone, not a fault of the process. A pipe is
/// read whole.
pub struct ScanFile<'a> {
    path: PathBuf,
    samples: Samples<'a>,
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
enum Samples<'a> {
    /// A regular file, read when maps are asked for.
    File(std::fs::File),
    /// What could not be mapped (a pipe, `/dev/stdin`), read at open.
    Memory(Vec<u8>),
    /// Memory the caller holds (a NumPy array's buffer), never copied.
    Borrowed(&'a [u8]),
}

impl ScanFile<'static> {
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
}

impl<'a> ScanFile<'a> {
    /// A scan whose samples are `bytes` in memory (C order, `dtype`, big
    /// endian or not), of shape `(rows, cols, j1, j2)`, with the header
    /// checks of [`ScanFile::open`] on that shape and the size; `name`
    /// stands for the file in messages. The samples are read in place.
    pub fn from_bytes(
        name: &str,
        bytes: &'a [u8],
        shape: &[usize],
        (dtype, big_endian): (ScanDtype, bool),
    ) -> Result<Self> {
        let path = PathBuf::from(name);
        let shape64: Vec<u64> = shape.iter().map(|&d| d as u64).collect();
        let (rows, cols, geometry) = check_shape(&path, &shape64)?;
        let expected = [cols, geometry.cells(), dtype.item()]
            .iter()
            .try_fold(rows, |n, &d| n.checked_mul(d));
        if expected != Some(bytes.len()) {
            bail!(
                "{name}: {} bytes of {} samples do not fill its shape {shape:?}",
                bytes.len(),
                dtype.name()
            );
        }
        Ok(ScanFile {
            path,
            samples: Samples::Borrowed(bytes),
            offset: 0,
            rows,
            cols,
            geometry,
            dtype,
            big_endian,
        })
    }

    fn item(&self) -> usize {
        self.dtype.item()
    }

    /// Positions of the scan.
    pub fn maps(&self) -> usize {
        self.rows * self.cols
    }

    /// The bytes of `count` samples from map `first` on.
    fn sample_bytes(&self, first: usize, count: usize) -> Result<std::borrow::Cow<'_, [u8]>> {
        let n = self.geometry.cells();
        let item = self.item();
        let p = self.path.display();
        if first * n + count > self.maps() * n {
            bail!(
                "{p}: maps from {first} on are outside the scan's {} positions",
                self.maps()
            );
        }
        let (start, len) = (self.offset + first * n * item, count * item);
        Ok(match &self.samples {
            Samples::Memory(v) => std::borrow::Cow::Borrowed(&v[start..start + len]),
            Samples::Borrowed(v) => std::borrow::Cow::Borrowed(&v[start..start + len]),
            Samples::File(file) => {
                use std::os::unix::fs::FileExt;
                let mut buf = vec![0u8; len];
                file.read_exact_at(&mut buf, start as u64).map_err(|e| {
                    if e.kind() == std::io::ErrorKind::UnexpectedEof {
                        anyhow!(
                            "{p}: the file ends before the samples of positions {:?} to {:?}: it is shorter than when it was opened (truncated while being read?)",
                            self.locate(first * n).0,
                            self.locate((first * n + count).max(1) - 1).0
                        )
                    } else {
                        anyhow!("{p}: cannot read: {e}")
                    }
                })?;
                std::borrow::Cow::Owned(buf)
            }
        })
    }

    /// The samples of maps `first..first + out.len() / cells`, as f64,
    /// checked finite and non-negative.
    pub fn maps_f64(&self, first: usize, out: &mut [f64]) -> Result<()> {
        let n = self.geometry.cells();
        let item = self.item();
        let bytes = self.sample_bytes(first, out.len())?;
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
            ScanDtype::U8 => out
                .iter_mut()
                .zip(&bytes[..])
                .for_each(|(o, &b)| *o = b.into()),
            ScanDtype::U16 => decode!(u16),
            ScanDtype::U32 => decode!(u32),
            ScanDtype::F32 => decode!(f32),
            ScanDtype::F64 => decode!(f64),
        }
        // Integers are finite and non-negative.
        let float = matches!(self.dtype, ScanDtype::F32 | ScanDtype::F64);
        if float && let Some(i) = out.iter().position(|x| !(x.is_finite() && *x >= 0.0)) {
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
    /// integer in `0..=65535`. Integer samples are read as they are
    /// (`scratch`, the f64 staging, serves float scans only).
    pub fn maps_u16(&self, first: usize, out: &mut [u16], scratch: &mut Vec<f64>) -> Result<()> {
        let n = self.geometry.cells();
        let not_a_count = |i: usize, x: &dyn std::fmt::Display| {
            let (pos, cell) = self.locate(first * n + i);
            anyhow!(
                "{}: {} scan value {x} at {pos:?} cell {cell:?} is not a u16 count (integer 0..=65535)",
                self.path.display(),
                self.dtype.name()
            )
        };
        let be = self.big_endian;
        match self.dtype {
            ScanDtype::U8 => {
                let bytes = self.sample_bytes(first, out.len())?;
                out.iter_mut()
                    .zip(&bytes[..])
                    .for_each(|(o, &b)| *o = b.into());
            }
            ScanDtype::U16 => {
                let bytes = self.sample_bytes(first, out.len())?;
                for (o, b) in out.iter_mut().zip(bytes.chunks_exact(2)) {
                    let b = [b[0], b[1]];
                    *o = if be {
                        u16::from_be_bytes(b)
                    } else {
                        u16::from_le_bytes(b)
                    };
                }
            }
            ScanDtype::U32 => {
                let bytes = self.sample_bytes(first, out.len())?;
                for (i, (o, b)) in out.iter_mut().zip(bytes.chunks_exact(4)).enumerate() {
                    let b = [b[0], b[1], b[2], b[3]];
                    let x = if be {
                        u32::from_be_bytes(b)
                    } else {
                        u32::from_le_bytes(b)
                    };
                    *o = u16::try_from(x).map_err(|_| not_a_count(i, &x))?;
                }
            }
            ScanDtype::F32 | ScanDtype::F64 => {
                scratch.resize(out.len(), 0.0);
                self.maps_f64(first, scratch)?;
                for (i, (o, &x)) in out.iter_mut().zip(scratch.iter()).enumerate() {
                    // `as` saturates (and takes NaN to 0): only an integer
                    // in 0..=65535 converts back to itself.
                    let c = x as u16;
                    if f64::from(c) != x {
                        return Err(not_a_count(i, &x));
                    }
                    *o = c;
                }
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
