//! The frame buffers the acquisition side fills (SPI DMA on the H743, file
//! reads on the emulated board) and the scoring side reads.
//!
//! Ownership of each buffer is handed over through
//! `cvm_fw_app::acquire::Acquisition`: a buffer is written only while it is
//! `Filling` and read only after the scoring side took its record and before
//! it released it. That protocol is what makes the shared access sound.

use core::cell::UnsafeCell;

use cvm_core::MAX_CELLS;
#[cfg(feature = "emulated")]
use cvm_fw_app::decode::{decode_frame, frame_bytes};
use cvm_fw_app::driver::FrameStore;

/// Bytes of one frame buffer: the largest detector's frame.
#[cfg(feature = "emulated")]
pub const FRAME_BYTES: usize = frame_bytes(MAX_CELLS);

/// `N` frame buffers in bus byte order (the emulated board's file reads).
#[cfg(feature = "emulated")]
#[repr(C, align(32))]
pub struct FrameBuffers<const N: usize>(UnsafeCell<[[u8; FRAME_BYTES]; N]>);

// SAFETY: see the module docs; each buffer has one owner at a time.
#[cfg(feature = "emulated")]
unsafe impl<const N: usize> Sync for FrameBuffers<N> {}

#[cfg(feature = "emulated")]
impl<const N: usize> FrameBuffers<N> {
    pub const fn new() -> Self {
        FrameBuffers(UnsafeCell::new([[0; FRAME_BYTES]; N]))
    }

    /// # Safety
    /// The caller must own buffer `k` (it is `Filling`, or the scoring side
    /// holds its record) and hold no other reference to it.
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn buffer(&self, k: usize) -> &mut [u8; FRAME_BYTES] {
        // SAFETY: the caller upholds exclusive ownership of buffer `k`.
        unsafe { &mut (*self.0.get())[k % N] }
    }
}

/// The scoring side's view: decodes a buffer into samples on demand.
#[cfg(feature = "emulated")]
pub struct Decoder<'b, const N: usize, R: FnMut(usize)> {
    pub bufs: &'b FrameBuffers<N>,
    pub cells: usize,
    pub samples: [u16; MAX_CELLS],
    /// Hands a buffer back to the acquisition side.
    pub release: R,
}

#[cfg(feature = "emulated")]
impl<const N: usize, R: FnMut(usize)> FrameStore for Decoder<'_, N, R> {
    fn frame(&mut self, buf: usize) -> Option<&[u16]> {
        // SAFETY: the scoring side holds `buf`'s record (FrameStore contract).
        let bytes = unsafe { self.bufs.buffer(buf) };
        let out = self.samples.get_mut(..self.cells)?;
        let n = frame_bytes(out.len());
        decode_frame(bytes.get(..n)?, out).ok()?;
        Some(out)
    }

    fn release(&mut self, buf: usize) {
        (self.release)(buf);
    }
}

/// `N` frame buffers of native `u16` samples, for a bus that delivers
/// samples (16-bit SPI frames with DMA): nothing to decode.
#[cfg(feature = "h743")]
#[repr(C, align(32))]
pub struct SampleBuffers<const N: usize>(UnsafeCell<[[u16; MAX_CELLS]; N]>);

// SAFETY: see the module docs; each buffer has one owner at a time.
#[cfg(feature = "h743")]
unsafe impl<const N: usize> Sync for SampleBuffers<N> {}

#[cfg(feature = "h743")]
impl<const N: usize> SampleBuffers<N> {
    pub const fn new() -> Self {
        SampleBuffers(UnsafeCell::new([[0; MAX_CELLS]; N]))
    }

    /// # Safety
    /// The caller must own buffer `k` (it is `Filling`, or the scoring side
    /// holds its record) and hold no other reference to it.
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn buffer(&self, k: usize) -> &mut [u16; MAX_CELLS] {
        // SAFETY: the caller upholds exclusive ownership of buffer `k`.
        unsafe { &mut (*self.0.get())[k % N] }
    }
}

/// The scoring side's view of [`SampleBuffers`].
#[cfg(feature = "h743")]
pub struct Samples<'b, const N: usize, R: FnMut(usize)> {
    pub bufs: &'b SampleBuffers<N>,
    pub cells: usize,
    /// Hands a buffer back to the acquisition side.
    pub release: R,
}

#[cfg(feature = "h743")]
impl<const N: usize, R: FnMut(usize)> FrameStore for Samples<'_, N, R> {
    fn frame(&mut self, buf: usize) -> Option<&[u16]> {
        // SAFETY: the scoring side holds `buf`'s record (FrameStore contract).
        let samples = unsafe { self.bufs.buffer(buf) };
        samples.get(..self.cells)
    }

    fn release(&mut self, buf: usize) {
        (self.release)(buf);
    }
}
