//! `.npy` reading and writing against files built and parsed by hand from
//! the format description.

use crate::common;

use common::raw_npy;
use cvm_reference::Geometry;
use dmap::npy::{
    Mask, ScanDtype, ScanFile, read_gradient, read_mask, read_scan, write_gradient, write_mask,
    write_scan_u16,
};
use std::path::{Path, PathBuf};

fn path(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("npy_io");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// Header dict and data bytes of a version-1 `.npy` file, parsed by hand.
fn parse_by_hand(bytes: &[u8]) -> (String, &[u8]) {
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
    let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    assert_eq!((10 + len) % 64, 0, "header not padded to 64 bytes");
    let header = std::str::from_utf8(&bytes[10..10 + len])
        .unwrap()
        .to_string();
    (header, &bytes[10 + len..])
}

/// The shape tuple of a header dict, e.g. `(2, 3)` or `(2, 3, )`.
fn shape_of(header: &str) -> Vec<usize> {
    let start = header.find("'shape': (").expect("shape key") + "'shape': (".len();
    let end = start + header[start..].find(')').expect("shape tuple end");
    header[start..end]
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().expect("shape entry"))
        .collect()
}

#[test]
fn reads_every_scan_dtype_and_byte_order() {
    let shape = [1, 2, 1, 3];
    let values = [0u32, 1, 2, 250, 7, 3];
    let cases: Vec<(&str, Vec<u8>, ScanDtype)> = vec![
        (
            "|u1",
            values.iter().map(|&v| v as u8).collect(),
            ScanDtype::U8,
        ),
        (
            "<u2",
            values
                .iter()
                .flat_map(|&v| (v as u16).to_le_bytes())
                .collect(),
            ScanDtype::U16,
        ),
        (
            ">u2",
            values
                .iter()
                .flat_map(|&v| (v as u16).to_be_bytes())
                .collect(),
            ScanDtype::U16,
        ),
        (
            "<u4",
            values.iter().flat_map(|&v| v.to_le_bytes()).collect(),
            ScanDtype::U32,
        ),
        (
            "<f4",
            values
                .iter()
                .flat_map(|&v| (v as f32).to_le_bytes())
                .collect(),
            ScanDtype::F32,
        ),
        (
            "<f8",
            values
                .iter()
                .flat_map(|&v| f64::from(v).to_le_bytes())
                .collect(),
            ScanDtype::F64,
        ),
        (
            ">f8",
            values
                .iter()
                .flat_map(|&v| f64::from(v).to_be_bytes())
                .collect(),
            ScanDtype::F64,
        ),
    ];
    for (descr, data, dtype) in cases {
        let p = path(&format!("dtype{}.npy", descr.replace(['<', '>', '|'], "_")));
        std::fs::write(&p, raw_npy(descr, false, &shape, &data)).unwrap();
        let scan = read_scan(&p).unwrap_or_else(|e| panic!("{descr}: {e}"));
        assert_eq!((scan.rows, scan.cols), (1, 2), "{descr}");
        assert_eq!(scan.geometry, Geometry::new(1, 3).unwrap());
        assert_eq!(scan.dtype, dtype);
        let want: Vec<f64> = values.iter().map(|&v| f64::from(v)).collect();
        assert_eq!(scan.data, want, "{descr}");
        assert_eq!(scan.map(0, 1), &want[3..]);
        assert_eq!(
            scan.to_u16().unwrap(),
            values.iter().map(|&v| v as u16).collect::<Vec<_>>()
        );
    }
}

#[test]
fn to_u16_refuses_non_counts() {
    for (descr, data, needle) in [
        ("<f8", 1.5f64.to_le_bytes().to_vec(), "1.5"),
        ("<u4", 70000u32.to_le_bytes().to_vec(), "70000"),
    ] {
        let p = path("noncount.npy");
        std::fs::write(&p, raw_npy(descr, false, &[1, 1, 1, 1], &data)).unwrap();
        let scan = read_scan(&p).unwrap();
        let err = scan.to_u16().unwrap_err().to_string();
        assert!(
            err.contains(needle) && err.contains("u16") && !err.contains('\n'),
            "{err}"
        );
    }
}

#[test]
fn u16_scan_written_as_numpy_expects() {
    let p = path("written.npy");
    let g = Geometry::new(2, 3).unwrap();
    let data: Vec<u16> = (0..2 * 2 * 6).map(|i| i * 1000 + 7).collect();
    write_scan_u16(&p, 2, 2, g, &data).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let (header, body) = parse_by_hand(&bytes);
    assert!(header.contains("'descr': '<u2'"), "{header}");
    assert!(header.contains("'fortran_order': False"), "{header}");
    assert_eq!(shape_of(&header), [2, 2, 2, 3], "{header}");
    let back: Vec<u16> = body
        .chunks(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect();
    assert_eq!(back, data);
    assert_eq!(read_scan(&p).unwrap().to_u16().unwrap(), data);
}

#[test]
fn gradient_written_as_float64_rows_cols_3() {
    let p = path("grad.npy");
    let data: Vec<f64> = (0..2 * 4 * 3).map(|i| f64::from(i) * 0.125 - 1.0).collect();
    write_gradient(&p, 2, 4, &data).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let (header, body) = parse_by_hand(&bytes);
    assert!(header.contains("'descr': '<f8'"), "{header}");
    assert_eq!(shape_of(&header), [2, 4, 3], "{header}");
    let back: Vec<f64> = body
        .chunks(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert_eq!(back, data);
    let img = read_gradient(&p).unwrap();
    assert_eq!((img.rows, img.cols, &img.data), (2, 4, &data));
    // Wrong length is refused, not truncated.
    assert!(write_gradient(&p, 2, 4, &data[1..]).is_err());
}

#[test]
fn masks_round_trip_and_match_numpy_bool() {
    let p = path("mask.npy");
    let mask = Mask {
        rows: 2,
        cols: 3,
        data: vec![true, false, false, true, true, false],
    };
    write_mask(&p, &mask).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let (header, body) = parse_by_hand(&bytes);
    assert!(header.contains("'descr': '|b1'"), "{header}");
    assert_eq!(shape_of(&header), [2, 3], "{header}");
    assert_eq!(body, &[1, 0, 0, 1, 1, 0]);
    assert_eq!(read_mask(&p).unwrap(), mask);
    // A mask numpy wrote (built by hand here) reads the same.
    let q = path("mask_np.npy");
    std::fs::write(&q, raw_npy("|b1", false, &[2, 3], &[1, 0, 0, 1, 1, 0])).unwrap();
    assert_eq!(read_mask(&q).unwrap(), mask);
    // Not bool, wrong rank: one-line errors naming the file.
    for (name, bytes, needle) in [
        (
            "mask_u8.npy",
            raw_npy("|u1", false, &[2, 3], &[0; 6]),
            "bool expected",
        ),
        (
            "mask_rank3.npy",
            raw_npy("|b1", false, &[1, 2, 3], &[0; 6]),
            "(rows, cols)",
        ),
    ] {
        let r = path(name);
        std::fs::write(&r, bytes).unwrap();
        let err = read_mask(&r).unwrap_err().to_string();
        assert!(
            err.contains(name) && err.contains(needle) && !err.contains('\n'),
            "{err}"
        );
    }
}

#[test]
fn header_length_beyond_the_file_is_refused_before_any_allocation() {
    // A version-2 header whose 4-byte length field claims ~4 GiB: the reader
    // must say so rather than size a buffer by it.
    let mut bytes = b"\x93NUMPY\x02\x00".to_vec();
    bytes.extend_from_slice(&0xFFFF_FF00u32.to_le_bytes());
    bytes.extend_from_slice(b"{'descr': '<u2', 'fortran_order': False, 'shape': (1, 1, 1, 1), }");
    let p = path("huge_header_len.npy");
    std::fs::write(&p, &bytes).unwrap();
    for e in [
        read_scan(&p).unwrap_err().to_string(),
        read_gradient(&p).unwrap_err().to_string(),
        read_mask(&p).unwrap_err().to_string(),
    ] {
        assert!(e.contains("header truncated"), "{e}");
        assert!(!e.contains('\n'));
    }
}

#[test]
fn deeply_nested_header_is_refused_without_parsing_it() {
    // Unbalanced nested brackets make the header parser backtrack
    // exponentially (minutes at a dozen levels); the reader refuses them.
    let dict = format!(
        "{{'descr': '<u2', 'shape': {}{}",
        "{".repeat(60),
        " ".repeat(20)
    );
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(dict.len() as u16 + 1).to_le_bytes());
    bytes.extend_from_slice(dict.as_bytes());
    bytes.push(b'\n');
    let p = path("nested_header.npy");
    std::fs::write(&p, &bytes).unwrap();
    let e = read_scan(&p).unwrap_err().to_string();
    assert!(e.contains("nested too deeply"), "{e}");
}

#[test]
fn scan_truncated_while_open_is_an_error_naming_the_lost_positions() {
    // 3 x 4 positions of 2 x 2 big-endian u16 samples, sample k of map m
    // is 10 m + k.
    let (rows, cols, cells) = (3usize, 4usize, 4usize);
    let data: Vec<u8> = (0..rows * cols * cells)
        .flat_map(|i| ((i / cells * 10 + i % cells) as u16).to_be_bytes())
        .collect();
    let bytes = raw_npy(">u2", false, &[rows, cols, 2, 2], &data);
    let file = path("truncated_while_open.npy");
    std::fs::write(&file, &bytes).unwrap();
    let scan = ScanFile::open(&file).unwrap();
    let mut scratch = Vec::new();
    let mut row = vec![0u16; cols * cells];
    scan.maps_u16(cols, &mut row, &mut scratch).unwrap();
    let want: Vec<u16> = (cols * cells..2 * cols * cells)
        .map(|i| (i / cells * 10 + i % cells) as u16)
        .collect();
    assert_eq!(row, want, "row 1 before the file shrinks");

    // Cut the file in the middle of position (1, 2): row 0 is still there,
    // row 1 is not whole any more.
    let cut = bytes.len() - data.len() + (cols + 2) * cells * 2 + 3;
    std::fs::OpenOptions::new()
        .write(true)
        .open(&file)
        .unwrap()
        .set_len(cut as u64)
        .unwrap();
    scan.maps_u16(0, &mut row, &mut scratch).unwrap();
    assert_eq!(row[5], 10 + 1, "row 0 after the file shrinks");
    let err = scan
        .maps_u16(cols, &mut row, &mut scratch)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("shorter than when it was opened")
            && err.contains("(1, 0) to (1, 3)")
            && err.contains("truncated_while_open.npy"),
        "{err}"
    );
    let err = scan
        .maps_u16(rows * cols, &mut row, &mut scratch)
        .unwrap_err()
        .to_string();
    assert!(err.contains("outside the scan's 12 positions"), "{err}");
}

/// Bytes after the data are named as such, not as a cut file (and a cut
/// file still as cut).
#[test]
fn trailing_bytes_are_not_called_truncated() {
    let g = Geometry::new(2, 2).unwrap();
    let whole = path("trailing_whole.npy");
    write_scan_u16(&whole, 2, 2, g, &[7; 16]).unwrap();
    let bytes = std::fs::read(&whole).unwrap();
    let long = path("trailing_long.npy");
    std::fs::write(&long, [&bytes[..], b"xx"].concat()).unwrap();
    let e = format!("{:#}", read_scan(&long).unwrap_err());
    assert!(
        e.contains("holds 34 data bytes") && e.contains("extra bytes after the data"),
        "{e}"
    );
    assert!(!e.contains("truncated"), "{e}");
    let short = path("trailing_short.npy");
    std::fs::write(&short, &bytes[..bytes.len() - 2]).unwrap();
    let e = format!("{:#}", read_scan(&short).unwrap_err());
    assert!(
        e.contains("holds 30 data bytes") && e.contains("truncated"),
        "{e}"
    );
}
