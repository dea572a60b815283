//! The frame buffers the acquisition side fills (SPI DMA on the H743, file
//! reads on the emulated board) and the scoring side reads, and the
//! acquisition log they share with it ([`Beams`]).
//!
//! Ownership of each buffer is handed over through
//! [`Acquisition`]: a buffer is written only while it is
//! `Filling` and read only after the scoring side took its record and before
//! it released it. That protocol is what makes the shared access sound.

use core::cell::{RefCell, UnsafeCell};

use cvm_core::MAX_CELLS;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;

use crate::acquire::{Acquisition, BeamRecord};
use crate::driver::FrameStore;

/// `N` frame buffers of `C` native `u16` samples each, as a bus that
/// delivers samples leaves them (the H743's 16-bit SPI frames with DMA;
/// the emulated board's scan file holds them in that order too): nothing
/// to decode. `C` is at least the map's cells; an even `C` keeps every
/// buffer word-aligned, which the sum pass's block copy needs.
#[repr(C, align(32))]
pub struct SampleBuffers<const N: usize, const C: usize = MAX_CELLS>(UnsafeCell<[[u16; C]; N]>);

// SAFETY: see the module docs; each buffer has one owner at a time.
unsafe impl<const N: usize, const C: usize> Sync for SampleBuffers<N, C> {}

impl<const N: usize, const C: usize> Default for SampleBuffers<N, C> {
    fn default() -> Self {
        Self::new()
    }
}

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
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn bytes(&self, k: usize, cells: usize) -> &mut [u8] {
        // SAFETY: the caller owns buffer `k`; a `u16` array is valid as
        // twice as many bytes, and any byte values make valid `u16`s.
        let samples = unsafe { self.buffer(k) };
        let n = cells.min(C);
        unsafe { core::slice::from_raw_parts_mut(samples.as_mut_ptr().cast::<u8>(), 2 * n) }
    }
}

/// The acquisition log as the board shares it between its interrupts (or
/// its reading loop) and the scoring side.
pub type SharedLog<M, const B: usize, const L: usize> = Mutex<M, RefCell<Acquisition<B, L>>>;

/// Where the scoring side finds beams: the next record of the log.
pub trait BeamSource: FrameStore {
    fn next(&mut self) -> Option<BeamRecord>;
}

/// The scoring side's view of the board's acquisition: the shared log's
/// records and the [`SampleBuffers`] behind them; a buffer goes back to
/// the log when the scoring side releases it.
pub struct Beams<'b, M: RawMutex, const B: usize, const L: usize, const C: usize> {
    pub log: &'b SharedLog<M, B, L>,
    pub bufs: &'b SampleBuffers<B, C>,
    /// Samples per map, read from each buffer.
    pub cells: usize,
}

impl<M: RawMutex, const B: usize, const L: usize, const C: usize> FrameStore
    for Beams<'_, M, B, L, C>
{
    fn frame(&mut self, buf: usize) -> Option<&[u16]> {
        // SAFETY: the scoring side holds `buf`'s record (FrameStore contract).
        let samples = unsafe { self.bufs.buffer(buf) };
        samples.get(..self.cells)
    }

    fn release(&mut self, buf: usize) {
        // (The log is borrowed only inside its lock, never across a call
        // back into here: the borrow cannot fail, and no panic path is
        // linked for it.)
        self.log.lock(|a| {
            if let Ok(mut a) = a.try_borrow_mut() {
                a.release(buf);
            }
        });
    }
}

impl<M: RawMutex, const B: usize, const L: usize, const C: usize> BeamSource
    for Beams<'_, M, B, L, C>
{
    fn next(&mut self) -> Option<BeamRecord> {
        self.log
            .lock(|a| a.try_borrow_mut().ok().and_then(|mut a| a.take_next()))
    }
}
