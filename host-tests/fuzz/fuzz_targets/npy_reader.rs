//! The `.npy` readers (scan, gradient image, mask) on arbitrary file
//! contents: an error or a value that keeps the reader's promises, never a
//! panic or an allocation the file's size does not justify.
#![no_main]

use dmap::npy::{gradient_from_bytes, mask_from_bytes, scan_from_bytes};
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let name = Path::new("fuzz.npy");
    match scan_from_bytes(name, data) {
        Ok(scan) => {
            let n = scan.geometry.cells();
            assert!(scan.rows > 0 && scan.cols > 0 && n > 0);
            assert_eq!(scan.data.len(), scan.rows * scan.cols * n);
            assert!(scan.data.iter().all(|x| x.is_finite() && *x >= 0.0));
            // Conversion to the firmware's input is an error or exact.
            if let Ok(counts) = scan.to_u16() {
                assert!(counts.iter().zip(&scan.data).all(|(&c, &x)| c as f64 == x));
            }
            let _ = scan.map(scan.rows - 1, scan.cols - 1);
        }
        Err(e) => assert!(!e.to_string().contains('\n'), "multi-line error: {e}"),
    }
    match gradient_from_bytes(name, data) {
        Ok(g) => assert_eq!(g.data.len(), g.rows * g.cols * 3),
        Err(e) => assert!(!e.to_string().contains('\n'), "multi-line error: {e}"),
    }
    match mask_from_bytes(name, data) {
        Ok(m) => assert_eq!(m.data.len(), m.rows * m.cols),
        Err(e) => assert!(!e.to_string().contains('\n'), "multi-line error: {e}"),
    }
});
