//! Frames as bytes in bus order.
//!
//! The detector clocks out `J1*J2` 16-bit samples, most significant byte
//! first, row-major `(j1, j2)` (docs/method.md §5). Where a frame arrives
//! as bytes in that order (the emulated board's scan file, a byte-wide
//! bus), this module turns them into samples. (The H743 reads 16-bit SPI
//! frames straight into `u16` samples and needs no decoding.)

/// The byte buffer does not hold exactly two bytes per sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameSizeError {
    pub bytes: usize,
    pub samples: usize,
}

/// Bytes that one frame of `cells` samples occupies on the bus.
pub const fn frame_bytes(cells: usize) -> usize {
    2 * cells
}

/// Decodes big-endian samples from `bytes` into `out` (sample `k` is
/// detector cell `(k / J2, k % J2)`).
pub fn decode_frame(bytes: &[u8], out: &mut [u16]) -> Result<(), FrameSizeError> {
    if bytes.len() != frame_bytes(out.len()) {
        return Err(FrameSizeError {
            bytes: bytes.len(),
            samples: out.len(),
        });
    }
    // Two samples per 32-bit word: one load, one `REV16` (bytes swapped
    // within each half) and one store, instead of two byte loads, a shift,
    // an `ORR` and a halfword store per sample.
    let mut pairs = out.chunks_exact_mut(2);
    let mut quads = bytes.chunks_exact(4);
    for (o, q) in (&mut pairs).zip(&mut quads) {
        if let (&mut [ref mut s0, ref mut s1], Ok(q)) = (o, <[u8; 4]>::try_from(q)) {
            let w = u32::from_le_bytes(q);
            let w = ((w & 0x00FF_00FF) << 8) | ((w >> 8) & 0x00FF_00FF);
            *s0 = w as u16;
            *s1 = (w >> 16) as u16;
        }
    }
    for (sample, pair) in pairs
        .into_remainder()
        .iter_mut()
        .zip(quads.remainder().chunks_exact(2))
    {
        if let &[hi, lo] = pair {
            *sample = u16::from_be_bytes([hi, lo]);
        }
    }
    Ok(())
}
