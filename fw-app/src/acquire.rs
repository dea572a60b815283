//! DRDY and frame-buffer accounting between the acquisition side (DRDY
//! interrupt, SPI DMA) and the scoring side.
//!
//! Every DRDY edge becomes exactly one beam record, in edge order, whatever
//! happens to its frame: read into a free buffer, or lost because no buffer
//! was free or the SPI was still busy (an *overrun*), or lost to an SPI/DMA
//! error. The scoring side takes records in the same order, so a lost frame
//! keeps its position (reported missing) and never shifts later ones.
//!
//! The record log is bounded. When it is full, further lost beams are
//! folded into the last record as a run (a run's beams after the first
//! carry no LINE_SYNC; a LINE_SYNC folded that way is counted). Frames are
//! only read while there is room for their own record plus one spare slot,
//! so a run always has a lost record to extend and the count never breaks.
//!
//! The type is plain data; the firmware wraps it in a critical-section
//! mutex shared by the DRDY interrupt, the SPI task and the scoring task.

/// Why a beam has no frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LostCause {
    /// DRDY while no frame buffer was free or the SPI was still reading.
    Overrun,
    /// The SPI/DMA transfer failed.
    SpiError,
}

/// A beam as the scoring side sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BeamRecord {
    /// Frame in buffer `buf`, ready to score (release it afterwards).
    Frame { sync: bool, buf: usize },
    /// `run` consecutive beams without a frame; only the first may carry
    /// LINE_SYNC.
    Lost {
        sync: bool,
        cause: LostCause,
        run: u32,
    },
}

/// Acquisition counters since start-up.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AcquireCounts {
    pub drdy: u32,
    pub frames_read: u32,
    pub overruns: u32,
    pub spi_errors: u32,
    /// LINE_SYNC flags of lost beams folded into a run (log full).
    pub sync_folded: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Buf {
    Free,
    /// The SPI is filling it.
    Filling,
    /// Filled, waiting in the log or being scored.
    Busy,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Slot {
    Filling { sync: bool, buf: usize },
    Done(BeamRecord),
}

/// `BUFS` frame buffers and a log of at most `LOG` beam records (`LOG >= 2`).
#[derive(Clone, Debug)]
pub struct Acquisition<const BUFS: usize, const LOG: usize> {
    bufs: [Buf; BUFS],
    /// Buffers `Filling` (0 or 1): the SPI is busy while it is not 0.
    filling: usize,
    /// Where the search for a free buffer starts: after the last one
    /// handed out. The scoring side releases buffers in the order they
    /// were filled, so the first one looked at is free unless all are in
    /// use, and the DRDY interrupt does not scan dozens of buffers.
    next: usize,
    log: [Slot; LOG],
    head: usize,
    len: usize,
    counts: AcquireCounts,
}

impl<const BUFS: usize, const LOG: usize> Default for Acquisition<BUFS, LOG> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const BUFS: usize, const LOG: usize> Acquisition<BUFS, LOG> {
    pub const fn new() -> Self {
        Acquisition {
            bufs: [Buf::Free; BUFS],
            filling: 0,
            next: 0,
            log: [Slot::Done(BeamRecord::Lost {
                sync: false,
                cause: LostCause::Overrun,
                run: 0,
            }); LOG],
            head: 0,
            len: 0,
            counts: AcquireCounts {
                drdy: 0,
                frames_read: 0,
                overruns: 0,
                spi_errors: 0,
                sync_folded: 0,
            },
        }
    }

    pub fn counts(&self) -> &AcquireCounts {
        &self.counts
    }

    /// Records waiting for the scoring side (including one being filled).
    pub fn pending(&self) -> usize {
        self.len
    }

    fn spi_busy(&self) -> bool {
        self.filling > 0
    }

    /// A free buffer, looked for from `next` on, round the end.
    fn free_buffer(&self) -> Option<usize> {
        let start = self.next.min(BUFS);
        let (before, after) = self.bufs.split_at(start);
        let free = |b: &Buf| *b == Buf::Free;
        match after.iter().position(free) {
            Some(i) => Some(start + i),
            None => before.iter().position(free),
        }
    }

    fn slot(&self, k: usize) -> usize {
        (self.head + k) % LOG
    }

    /// A DRDY edge with LINE_SYNC sampled as `sync`. Returns the buffer the
    /// SPI must now read the frame into, or `None` when the frame is lost.
    pub fn drdy(&mut self, sync: bool) -> Option<usize> {
        self.counts.drdy = self.counts.drdy.wrapping_add(1);
        if !self.spi_busy()
            && self.len + 2 <= LOG
            && let Some(buf) = self.free_buffer()
            && let Some(b) = self.bufs.get_mut(buf)
        {
            *b = Buf::Filling;
            self.filling += 1;
            self.next = buf + 1;
            let at = self.slot(self.len);
            self.log[at] = Slot::Filling { sync, buf };
            self.len += 1;
            return Some(buf);
        }
        self.counts.overruns = self.counts.overruns.wrapping_add(1);
        self.push_lost(sync, LostCause::Overrun);
        None
    }

    fn push_lost(&mut self, sync: bool, cause: LostCause) {
        if self.len < LOG {
            let at = self.slot(self.len);
            self.log[at] = Slot::Done(BeamRecord::Lost {
                sync,
                cause,
                run: 1,
            });
            self.len += 1;
            return;
        }
        // Full: the last record is a lost one (frames keep a spare slot).
        let last = self.slot(self.len - 1);
        if let Slot::Done(BeamRecord::Lost { run, .. }) = &mut self.log[last] {
            *run = run.saturating_add(1);
        }
        if sync {
            self.counts.sync_folded = self.counts.sync_folded.wrapping_add(1);
        }
    }

    /// The SPI read into `buf` finished (`ok = false`: SPI/DMA error, the
    /// buffer is freed and the beam reported lost).
    pub fn read_done(&mut self, buf: usize, ok: bool) {
        // No record names a buffer that does not exist; saying so up front
        // also lets the compiler drop the bounds checks below.
        if buf >= BUFS {
            return;
        }
        // Newest first: the record being filled is the last but for the
        // beams lost while it was read.
        for k in (0..self.len).rev() {
            let at = self.slot(k);
            if let Slot::Filling { sync, buf: b } = self.log[at] {
                if b != buf {
                    continue;
                }
                self.filling = self.filling.saturating_sub(1);
                if ok {
                    self.counts.frames_read = self.counts.frames_read.wrapping_add(1);
                    self.log[at] = Slot::Done(BeamRecord::Frame { sync, buf });
                    self.bufs[buf] = Buf::Busy;
                } else {
                    self.counts.spi_errors = self.counts.spi_errors.wrapping_add(1);
                    self.log[at] = Slot::Done(BeamRecord::Lost {
                        sync,
                        cause: LostCause::SpiError,
                        run: 1,
                    });
                    self.bufs[buf] = Buf::Free;
                }
                return;
            }
        }
    }

    /// The oldest beam record, once its frame (if any) is complete.
    pub fn take_next(&mut self) -> Option<BeamRecord> {
        if self.len == 0 {
            return None;
        }
        match self.log.get(self.head).copied() {
            Some(Slot::Done(rec)) => {
                self.head = (self.head + 1) % LOG;
                self.len -= 1;
                Some(rec)
            }
            _ => None,
        }
    }

    /// The scoring side is done with `buf`.
    pub fn release(&mut self, buf: usize) {
        if let Some(b) = self.bufs.get_mut(buf)
            && *b == Buf::Busy
        {
            *b = Buf::Free;
        }
    }
}
