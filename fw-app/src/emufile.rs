//! The scan file the emulated board reads over semihosting (written by
//! `dmap emulate`). Little-endian header, then the frames as the H743's
//! 16-bit SPI frames leave them in memory: native (little-endian) `u16`
//! samples, so that the board reads them into its frame buffers and scores
//! them without decoding, as the H743 does. (Version 2 of the format held
//! the bytes in bus order, most significant first; its magic is refused.)
//!
//! | offset | size | field |
//! |-------:|-----:|-------|
//! | 0 | 8 | magic `CVMSCAN3` |
//! | 8 | 2 | header length in bytes ([`HEADER_LEN`]) |
//! | 10 | 1+1 | `J1`, `J2` |
//! | 12 | 1+1 | kernels (0 paper, 1 square), size (`bmax`, 0 = all / `kmax`) |
//! | 14 | 1+1 | weights (0 uniform, 1 unit, 2 separable), normalise (0/1) |
//! | 16 | 2 | full scale |
//! | 18 | 1+1 | per-position score lines (0/1), reserved 0 |
//! | 20 | 4+4 | columns, rows per scan |
//! | 28 | 8 | threshold in `dmap` units (f64) |
//! | 36 | 2 | most defect lines per row |
//! | 38 | 1+1 | firmware version length (0 = the firmware's own), reserved 0 |
//! | 40 | 24 | firmware version text, zero padded |
//! | 64 | 128+128 | separable weights `w1[16]`, `w2[16]` (f64; zero otherwise) |
//! | 320 | 8 | power threshold, a contrast (f64; infinite = the channel off) |
//! | 328 | 8 | spread threshold, a share of the power (f64; infinite = the channel off) |
//! | 336 | | frames: `J1*J2` samples each, little-endian `u16`, raster order, until end of file |
//!
//! The board synthesises LINE_SYNC on every `cols`-th beam, as a scanner
//! would drive it.

use cvm_core::config::{Config, Geometry, Kernels, MAX_J, Weights};
use cvm_core::protocol::MAX_FW;

pub const MAGIC: [u8; 8] = *b"CVMSCAN3";
pub const HEADER_LEN: usize = 336;

/// Everything the header says.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScanHeader {
    pub config: Config,
    pub cols: u32,
    pub rows: u32,
    pub threshold_units: f64,
    /// Power channel threshold, a contrast (`cvm_core::power`).
    pub power_threshold_units: f64,
    /// Spread channel threshold, a share of the power (`cvm_core::spread`).
    pub spread_threshold_units: f64,
    pub scores: bool,
    pub max_defect_lines_per_row: u16,
    pub version_len: u8,
    pub version: [u8; MAX_FW],
}

/// Why a header was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HeaderError {
    Short,
    Magic,
    Length,
    Geometry,
    Kernels,
    Weights,
    Flag,
    Columns,
    Rows,
    Version,
}

impl core::fmt::Display for HeaderError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.message())
    }
}

impl HeaderError {
    pub fn message(self) -> &'static str {
        match self {
            HeaderError::Short => "scan file shorter than its header",
            HeaderError::Magic => "not a CVMSCAN3 scan file (older dmap versions wrote CVMSCAN1/2)",
            HeaderError::Length => "unsupported header length",
            HeaderError::Geometry => "detector geometry outside 1..=16 per axis",
            HeaderError::Kernels => "unknown kernel set",
            HeaderError::Weights => "unknown weights",
            HeaderError::Flag => "flag byte other than 0 or 1",
            HeaderError::Columns => "zero columns",
            HeaderError::Rows => "zero rows",
            HeaderError::Version => "firmware version longer than 24 bytes or not UTF-8",
        }
    }
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn f64_at(b: &[u8], at: usize) -> f64 {
    let mut w = [0u8; 8];
    w.copy_from_slice(&b[at..at + 8]);
    f64::from_le_bytes(w)
}

fn flag(v: u8) -> Result<bool, HeaderError> {
    match v {
        0 => Ok(false),
        1 => Ok(true),
        _ => Err(HeaderError::Flag),
    }
}

impl ScanHeader {
    /// The firmware version to announce, if the file names one.
    pub fn version(&self) -> Option<&str> {
        let v = self.version.get(..usize::from(self.version_len))?;
        if v.is_empty() {
            None
        } else {
            core::str::from_utf8(v).ok()
        }
    }

    pub fn parse(b: &[u8]) -> Result<ScanHeader, HeaderError> {
        if b.len() < HEADER_LEN {
            return Err(HeaderError::Short);
        }
        if b[..8] != MAGIC {
            return Err(HeaderError::Magic);
        }
        if usize::from(u16_at(b, 8)) != HEADER_LEN {
            return Err(HeaderError::Length);
        }
        let geometry = Geometry::new(b[10], b[11]).map_err(|_| HeaderError::Geometry)?;
        let kernels = match b[12] {
            0 => Kernels::Paper { bmax: b[13] },
            1 => Kernels::Square { kmax: b[13] },
            _ => return Err(HeaderError::Kernels),
        };
        let mut w1 = [0.0; MAX_J];
        let mut w2 = [0.0; MAX_J];
        for k in 0..MAX_J {
            w1[k] = f64_at(b, 64 + 8 * k);
            w2[k] = f64_at(b, 192 + 8 * k);
        }
        let weights = match b[14] {
            0 => Weights::Uniform,
            1 => Weights::Unit,
            2 => Weights::Separable { w1, w2 },
            _ => return Err(HeaderError::Weights),
        };
        let normalise = flag(b[15])?;
        let full_scale = u16_at(b, 16);
        let scores = flag(b[18])?;
        let cols = u32_at(b, 20);
        let rows = u32_at(b, 24);
        if cols == 0 {
            return Err(HeaderError::Columns);
        }
        if rows == 0 {
            return Err(HeaderError::Rows);
        }
        let version_len = b[38];
        if usize::from(version_len) > MAX_FW {
            return Err(HeaderError::Version);
        }
        let mut version = [0u8; MAX_FW];
        version.copy_from_slice(&b[40..40 + MAX_FW]);
        let h = ScanHeader {
            config: Config {
                geometry,
                kernels,
                weights,
                normalise,
                full_scale,
            },
            cols,
            rows,
            threshold_units: f64_at(b, 28),
            power_threshold_units: f64_at(b, 320),
            spread_threshold_units: f64_at(b, 328),
            scores,
            max_defect_lines_per_row: u16_at(b, 36),
            version_len,
            version,
        };
        if version_len > 0 && h.version().is_none() {
            return Err(HeaderError::Version);
        }
        Ok(h)
    }

    /// The header bytes (what `dmap emulate` writes).
    pub fn encode(&self) -> [u8; HEADER_LEN] {
        let mut b = [0u8; HEADER_LEN];
        b[..8].copy_from_slice(&MAGIC);
        b[8..10].copy_from_slice(&(HEADER_LEN as u16).to_le_bytes());
        let c = &self.config;
        b[10] = c.geometry.j1;
        b[11] = c.geometry.j2;
        (b[12], b[13]) = match c.kernels {
            Kernels::Paper { bmax } => (0, bmax),
            Kernels::Square { kmax } => (1, kmax),
        };
        b[14] = match c.weights {
            Weights::Uniform => 0,
            Weights::Unit => 1,
            Weights::Separable { w1, w2 } => {
                for k in 0..MAX_J {
                    b[64 + 8 * k..72 + 8 * k].copy_from_slice(&w1[k].to_le_bytes());
                    b[192 + 8 * k..200 + 8 * k].copy_from_slice(&w2[k].to_le_bytes());
                }
                2
            }
        };
        b[15] = u8::from(c.normalise);
        b[16..18].copy_from_slice(&c.full_scale.to_le_bytes());
        b[18] = u8::from(self.scores);
        b[20..24].copy_from_slice(&self.cols.to_le_bytes());
        b[24..28].copy_from_slice(&self.rows.to_le_bytes());
        b[28..36].copy_from_slice(&self.threshold_units.to_le_bytes());
        b[36..38].copy_from_slice(&self.max_defect_lines_per_row.to_le_bytes());
        b[320..328].copy_from_slice(&self.power_threshold_units.to_le_bytes());
        b[328..336].copy_from_slice(&self.spread_threshold_units.to_le_bytes());
        b[38] = self.version_len;
        b[40..40 + MAX_FW].copy_from_slice(&self.version);
        b
    }
}
