//! The frame buffers the acquisition side fills (SPI DMA on the H743, file
//! reads on the emulated board) and the scoring side reads.
//!
//! Ownership of each buffer is handed over through
//! `cvm_fw_app::acquire::Acquisition`: a buffer is written only while it is
//! `Filling` and read only after the scoring side took its record and before
//! it released it. That protocol is what makes the shared access sound.

use core::cell::UnsafeCell;

use cvm_core::MAX_CELLS;
use cvm_fw_app::driver::FrameStore;

/// `N` frame buffers of `C` native `u16` samples each, as a bus that
/// delivers samples leaves them (the H743's 16-bit SPI frames with DMA;
/// the emulated board's scan file holds them in that order too): nothing
/// to decode. `C` is at least the map's cells; an even `C` keeps every
/// buffer word-aligned, which the sum pass's block copy needs.
#[repr(C, align(32))]
pub struct SampleBuffers<const N: usize, const C: usize = MAX_CELLS>(UnsafeCell<[[u16; C]; N]>);

// SAFETY: see the module docs; each buffer has one owner at a time.
unsafe impl<const N: usize, const C: usize> Sync for SampleBuffers<N, C> {}

impl<const N: usize, const C: usize> SampleBuffers<N, C> {
    pub const fn new() -> Self {
        SampleBuffers(UnsafeCell::new([[0; C]; N]))
    }

    /// # Safety
    /// The caller must own buffer `k` (it is `Filling`, or the scoring side
    /// holds its record) and hold no other reference to it.
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn buffer(&self, k: usize) -> &mut [u16; C] {
        // SAFETY: the caller upholds exclusive ownership of buffer `k`.
        unsafe { &mut (*self.0.get())[k % N] }
    }

    /// Buffer `k`'s first `cells` samples as bytes, in memory order, for a
    /// source that writes bytes (the emulated board's file reads).
    ///
    /// # Safety
    /// As for [`SampleBuffers::buffer`].
    #[cfg(feature = "emulated")]
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn bytes(&self, k: usize, cells: usize) -> &mut [u8] {
        // SAFETY: the caller owns buffer `k`; a `u16` array is valid as
        // twice as many bytes, and any byte values make valid `u16`s.
        let samples = unsafe { self.buffer(k) };
        let n = cells.min(C);
        unsafe { core::slice::from_raw_parts_mut(samples.as_mut_ptr().cast::<u8>(), 2 * n) }
    }
}

/// The scoring side's view of [`SampleBuffers`].
pub struct Samples<'b, const N: usize, const C: usize, R: FnMut(usize)> {
    pub bufs: &'b SampleBuffers<N, C>,
    pub cells: usize,
    /// Hands a buffer back to the acquisition side.
    pub release: R,
}

impl<const N: usize, const C: usize, R: FnMut(usize)> FrameStore for Samples<'_, N, C, R> {
    fn frame(&mut self, buf: usize) -> Option<&[u16]> {
        // SAFETY: the scoring side holds `buf`'s record (FrameStore contract).
        let samples = unsafe { self.bufs.buffer(buf) };
        samples.get(..self.cells)
    }

    fn release(&mut self, buf: usize) {
        (self.release)(buf);
    }
}
