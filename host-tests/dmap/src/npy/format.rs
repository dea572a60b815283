//! The `.npy` container itself, whatever the array: the checked header
//! (magic, version, length, nesting, order, size against the data), the
//! decoding of its data, mapping a file, and writing one.

use anyhow::{Result, anyhow, bail};
use npyz::{DType, NpyFile, Order, TypeChar, WriterBuilder};
use std::io::Write;
use std::path::Path;

/// Longest header read: NumPy writes a few hundred bytes at most.
const MAX_HEADER_LEN: usize = 1 << 16;

/// A `.npy` file's bytes, read in three steps so that nothing is read
/// beyond what its header announces: the signature and the header's
/// length, the header (checked as [`open_npy`] checks it), then exactly
/// the data the shape and dtype need, and one byte more to see whether
/// anything follows. A regular file's size is checked against the header
/// before its data are read; `/dev/zero` or a pipe of anything but a
/// `.npy` file fails at its first bytes.
pub(super) fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    use std::io::Read;
    let p = path.display();
    let cannot = |e: std::io::Error| anyhow!("{p}: cannot read: {e}");
    let mut file = std::fs::File::open(path).map_err(cannot)?;
    let meta = file.metadata().map_err(cannot)?;
    let regular_len = meta.is_file().then_some(meta.len());
    let mut bytes = Vec::new();
    // Reads until `bytes` holds `upto` bytes, or the file ends.
    let mut fill = |bytes: &mut Vec<u8>, upto: u64| {
        let n = upto.saturating_sub(bytes.len() as u64);
        (&mut file)
            .take(n)
            .read_to_end(bytes)
            .map(|_| ())
            .map_err(cannot)
    };
    // Magic, version and the shorter length field first: a file that is no
    // `.npy` stops here.
    fill(&mut bytes, 10)?;
    let len_at = signature(path, &bytes)?;
    fill(&mut bytes, len_at as u64 + 4)?;
    let header_len = header_len(path, &bytes, len_at)?;
    let data_at = len_at + len_width(&bytes) + header_len;
    if regular_len.is_some_and(|len| len < data_at as u64) {
        bail!("{p}: not a valid .npy file (header truncated)");
    }
    if header_len > MAX_HEADER_LEN {
        bail!(
            "{p}: not a valid .npy file (its header claims {header_len} bytes; a plain array's takes a few hundred)"
        );
    }
    fill(&mut bytes, data_at as u64)?;
    let (npy, want) = parse_header(path, &bytes)?;
    let wrong_size = |have| size_error(path, have, want, &npy);
    if let Some(len) = regular_len {
        let have = len.saturating_sub(data_at as u64);
        if have != want {
            return Err(wrong_size(have));
        }
    }
    // At most the announced data and one byte more (a pipe or device
    // holding more is refused having read only that byte).
    let mut data = Vec::new();
    fill(&mut data, want.saturating_add(1))?;
    if data.len() as u64 != want {
        return Err(wrong_size(data.len() as u64));
    }
    drop(npy);
    bytes.extend_from_slice(&data);
    Ok(bytes)
}

/// Checks the NumPy signature and version; the offset of the header's
/// length field.
fn signature(path: &Path, bytes: &[u8]) -> Result<usize> {
    let p = path.display();
    if !bytes.starts_with(b"\x93NUMPY") {
        bail!("{p}: not a .npy file (no NumPy magic bytes)");
    }
    match (bytes.get(6), bytes.get(7)) {
        (Some(1..=3), _) => Ok(8),
        (Some(&major), Some(&minor)) => bail!(
            "{p}: .npy format version {major}.{minor} is not supported (versions 1.0, 2.0 and 3.0 are)"
        ),
        _ => bail!("{p}: not a valid .npy file (header truncated)"),
    }
}

/// The width of the header's length field: 2 bytes in version 1, 4 after
/// (of a file whose [`signature`] passed).
fn len_width(bytes: &[u8]) -> usize {
    if bytes[6] == 1 { 2 } else { 4 }
}

/// The header length the file announces.
fn header_len(path: &Path, bytes: &[u8], len_at: usize) -> Result<usize> {
    let width = len_width(bytes);
    bytes
        .get(len_at..len_at + width)
        .map(|b| {
            b.iter()
                .rev()
                .fold(0usize, |acc, &x| (acc << 8) | usize::from(x))
        })
        .ok_or_else(|| {
            anyhow!(
                "{}: not a valid .npy file (header truncated)",
                path.display()
            )
        })
}

/// The error of a file whose data are not the size its header says.
fn size_error(path: &Path, have: u64, want: u64, npy: &NpyFile<&[u8]>) -> anyhow::Error {
    // Too few bytes is a cut file; too many, something appended.
    let what = if have < want {
        "truncated or corrupt file"
    } else {
        "extra bytes after the data: a corrupt or appended-to file"
    };
    anyhow!(
        "{}: holds {have} data bytes but shape {:?} of {} needs {want} ({what})",
        path.display(),
        npy.shape(),
        npy.dtype().descr()
    )
}

/// The header of an in-memory `.npy` file, checked for what every reader
/// here needs: C order, no pickled objects, and exactly as many data bytes
/// as the shape and dtype say.
pub(super) fn open_npy<'a>(path: &Path, bytes: &'a [u8]) -> Result<NpyFile<&'a [u8]>> {
    let (npy, want) = parse_header(path, bytes)?;
    let header = npy.header().clone();
    // NpyFile has consumed the header from the slice; what remains is data.
    let data = npy.into_inner();
    if data.len() as u64 != want {
        let npy = NpyFile::with_header(header, data);
        return Err(size_error(path, data.len() as u64, want, &npy));
    }
    Ok(NpyFile::with_header(header, data))
}

/// The checked header of `bytes` (which may end where the data start) and
/// the number of data bytes it announces.
fn parse_header<'a>(path: &Path, bytes: &'a [u8]) -> Result<(NpyFile<&'a [u8]>, u64)> {
    let p = path.display();
    let len_at = signature(path, bytes)?;
    // The header's length field is checked against the file before the
    // parser sizes a buffer by it: a corrupt field must not ask for 4 GiB.
    let header_len = header_len(path, bytes, len_at)?;
    let width = len_width(bytes);
    let Some(header) = bytes.get(len_at + width..len_at + width + header_len) else {
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
    Ok((npy, want))
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

pub(super) fn plain(dtype: &DType) -> Option<(TypeChar, u64)> {
    match dtype {
        DType::Plain(ts) => Some((ts.type_char(), ts.size_field())),
        _ => None,
    }
}

pub(super) fn decode<T: npyz::Deserialize>(path: &Path, npy: NpyFile<&[u8]>) -> Result<Vec<T>> {
    npy.into_vec::<T>().map_err(|e| {
        anyhow!(
            "{}: cannot decode data: {}",
            path.display(),
            one_line(&e.to_string())
        )
    })
}

/// A file's bytes: mapped (read only) when the file can be, else read.
pub(super) enum FileBytes {
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
pub(super) fn map_file(path: &Path) -> Result<FileBytes> {
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

pub(super) fn to_f64<T: Into<f64>>(v: Vec<T>) -> Vec<f64> {
    v.into_iter().map(Into::into).collect()
}

pub(super) fn write_npy<T: npyz::AutoSerialize + Copy>(
    path: &Path,
    shape: &[u64],
    data: &[T],
) -> Result<()> {
    crate::out::write_file(path, |out| {
        encode_npy(&path.display().to_string(), shape, data, out)
    })
}

/// `data` as a `.npy` file of `shape`, to `out`; `name` names it in errors.
pub(super) fn encode_npy<T: npyz::AutoSerialize + Copy>(
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

pub(super) fn check_len(path: &Path, got: usize, want: usize) -> Result<()> {
    if got == want {
        Ok(())
    } else {
        bail!(
            "{}: {got} values do not fill the {want} of the shape",
            path.display()
        )
    }
}
