//! The bounded queue of result lines between the scoring side and the UART.
//!
//! Lines are stored back to back in a byte ring (two length bytes, then the
//! line), so short lines cost little and the order of lines is kept exactly.
//!
//! # Priority policy
//!
//! Per-position score lines are [`Priority::Droppable`]; header, row,
//! defect and end lines are [`Priority::Keep`].
//!
//! - A droppable line is accepted only if, after it, at least `reserve`
//!   bytes stay free. Otherwise it is dropped and counted. So score lines can
//!   never fill the part of the queue that keep lines rely on.
//! - A keep line is accepted whenever it fits at all. The scoring side calls
//!   [`LineQueue::keep_room`] before handing the engine a beam and waits for
//!   the UART while it is false: `reserve` is sized for the keep lines one
//!   beam (or the end of a scan) can produce, so a keep line never meets a
//!   full queue. Waiting there stalls only scoring; the acquisition side
//!   keeps counting beams, and any frame it cannot buffer meanwhile is an
//!   overrun reported as a missing position.
//! - At the end of a scan the engine flushes its last two rows; their score
//!   lines are queued as keep lines (`ScanDriver` promotes them), because
//!   the end line's drop count is fixed before they are encoded and must
//!   be exact. `reserve` therefore also covers two rows of score lines.
//! - Should a keep line still not fit (a `reserve` too small for the
//!   configuration), it is dropped and counted separately, never silently.
//!
//! Dropped lines of both kinds add up in [`LineQueue::dropped`], which the
//! end-of-scan line reports.

use core::cell::RefCell;

use cvm_core::protocol::{LineSink, Priority};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;

use crate::driver::CountingSink;

const LEN_BYTES: usize = 2;

/// Queue counters since start-up.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct QueueCounts {
    pub accepted: u32,
    pub dropped_scores: u32,
    /// Keep lines that did not fit (must stay 0; see the module docs).
    pub dropped_keep: u32,
    /// Largest number of bytes ever queued.
    pub high_water: usize,
}

/// A ring of `CAP` bytes of lines; `reserve` bytes are kept for keep lines.
pub struct LineQueue<const CAP: usize> {
    buf: [u8; CAP],
    head: usize,
    used: usize,
    reserve: usize,
    counts: QueueCounts,
}

impl<const CAP: usize> LineQueue<CAP> {
    /// `reserve` is clamped to `CAP`.
    pub const fn new(reserve: usize) -> Self {
        LineQueue {
            buf: [0; CAP],
            head: 0,
            used: 0,
            reserve: if reserve < CAP { reserve } else { CAP },
            counts: QueueCounts {
                accepted: 0,
                dropped_scores: 0,
                dropped_keep: 0,
                high_water: 0,
            },
        }
    }

    /// Sets `reserve` (clamped to `CAP`). A `static` queue built with
    /// `new(0)` is all zero bytes and goes to `.bss`; with a non-zero
    /// reserve its whole buffer would be an initial value in flash
    /// (`.data`), so the firmware sets the reserve at start-up instead.
    pub fn set_reserve(&mut self, reserve: usize) {
        self.reserve = if reserve < CAP { reserve } else { CAP };
    }

    pub fn counts(&self) -> &QueueCounts {
        &self.counts
    }

    /// Lines dropped so far, of either priority.
    pub fn dropped(&self) -> u32 {
        self.counts
            .dropped_scores
            .wrapping_add(self.counts.dropped_keep)
    }

    pub fn is_empty(&self) -> bool {
        self.used == 0
    }

    pub fn free(&self) -> usize {
        CAP - self.used
    }

    /// Bytes a line of `len` bytes takes in the queue.
    pub const fn cost(len: usize) -> usize {
        LEN_BYTES + len
    }

    /// True when the full reserve is free, i.e. keep lines of up to
    /// `reserve` bytes (with their length bytes) are sure to fit.
    pub fn keep_room(&self) -> bool {
        self.free() >= self.reserve
    }

    /// Offers a line; returns whether it was queued.
    pub fn push(&mut self, line: &[u8], priority: Priority) -> bool {
        let need = Self::cost(line.len());
        let fits = match priority {
            Priority::Droppable => self.free() >= need.saturating_add(self.reserve),
            Priority::Keep => self.free() >= need,
        };
        if !fits || line.len() > usize::from(u16::MAX) {
            match priority {
                Priority::Droppable => {
                    self.counts.dropped_scores = self.counts.dropped_scores.wrapping_add(1)
                }
                Priority::Keep => {
                    self.counts.dropped_keep = self.counts.dropped_keep.wrapping_add(1)
                }
            }
            return false;
        }
        let len = (line.len() as u16).to_le_bytes();
        self.write_bytes(&len);
        self.write_bytes(line);
        self.counts.accepted = self.counts.accepted.wrapping_add(1);
        self.counts.high_water = self.counts.high_water.max(self.used);
        true
    }

    /// Appends `bytes` (the caller has checked that they fit) as at most
    /// two block copies: up to the end of the ring, then from its start.
    fn write_bytes(&mut self, bytes: &[u8]) {
        let at = (self.head + self.used) % CAP;
        let (tail, wrapped) = bytes.split_at(bytes.len().min(CAP - at));
        copy(self.buf.get_mut(at..).unwrap_or(&mut []), tail);
        copy(&mut self.buf, wrapped);
        self.used += bytes.len();
    }

    fn byte_at(&self, k: usize) -> u8 {
        self.buf[(self.head + k) % CAP]
    }

    /// Moves the oldest line into `out` (e.g. a DMA buffer) and returns its
    /// length; `None` when empty. A line longer than `out` is cut to fit
    /// (sizing `out` to [`cvm_core::protocol::MAX_LINE`] rules that out).
    pub fn pop_into(&mut self, out: &mut [u8]) -> Option<usize> {
        if self.used < LEN_BYTES {
            return None;
        }
        let len = usize::from(u16::from_le_bytes([self.byte_at(0), self.byte_at(1)]));
        let n = len.min(out.len());
        let at = (self.head + LEN_BYTES) % CAP;
        let (out, _) = out.split_at_mut(n);
        let (tail, wrapped) = out.split_at_mut(n.min(CAP - at));
        copy(tail, self.buf.get(at..).unwrap_or(&[]));
        copy(wrapped, &self.buf);
        let total = (LEN_BYTES + len).min(self.used);
        self.head = (self.head + total) % CAP;
        self.used -= total;
        Some(n)
    }
}

/// Copies the first `min(dst.len(), src.len())` bytes of `src` into `dst`
/// with one `memcpy`: the line bytes move a block at a time, not one
/// modulo-indexed byte at a time.
fn copy(dst: &mut [u8], src: &[u8]) {
    let n = dst.len().min(src.len());
    if let (Some(d), Some(s)) = (dst.get_mut(..n), src.get(..n)) {
        d.copy_from_slice(s);
    }
}

impl<const CAP: usize> LineSink for LineQueue<CAP> {
    fn line(&mut self, line: &[u8], priority: Priority) {
        self.push(line, priority);
    }
}

/// A queue as the board shares it between the task that fills it and the
/// one that sends it.
pub type SharedQueue<M, const N: usize> = Mutex<M, RefCell<LineQueue<N>>>;

/// The line sink over a [`SharedQueue`]: each line goes into the queue.
pub struct QueueSink<'q, M: RawMutex, const N: usize>(pub &'q SharedQueue<M, N>);

impl<M: RawMutex, const N: usize> LineSink for QueueSink<'_, M, N> {
    fn line(&mut self, line: &[u8], priority: Priority) {
        // (Borrowed only inside the lock: cannot fail, no panic path.)
        self.0.lock(|q| {
            if let Ok(mut q) = q.try_borrow_mut() {
                q.push(line, priority);
            }
        });
    }
}

impl<M: RawMutex, const N: usize> CountingSink for QueueSink<'_, M, N> {
    fn dropped(&self) -> u32 {
        self.0.lock(|q| q.try_borrow().map_or(0, |q| q.dropped()))
    }
}
