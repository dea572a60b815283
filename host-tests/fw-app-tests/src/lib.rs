//! A host rig for the firmware's board-independent logic: a deterministic
//! scan generator, the reference output (the core pipeline fed directly),
//! and a simulated board (DRDY edges, SPI completions, a UART that can
//! stall) driving `Acquisition`, `ScanDriver` and `LineQueue` exactly as the
//! boards do; and bank 2 of the H743's flash (`bank`), for the settings
//! store.

pub mod bank;

use cvm_core::pipeline::{Pipeline, Settings};
use cvm_core::protocol::{LineSink, Priority};
use cvm_core::stream::{Position, row_words};
use cvm_core::{Config, Geometry, Scorer};
use cvm_fw_app::acquire::Acquisition;
use cvm_fw_app::driver::{CountingSink, FrameStore, ScanDriver};
use cvm_fw_app::queue::LineQueue;

pub const MAX_COLS: usize = 64;

/// A scan: `rows x cols` frames of `j1 x j2` samples, with a bright blob
/// (a defect) at `defect`.
pub struct Scan {
    pub j1: u8,
    pub j2: u8,
    pub cols: u32,
    pub rows: u32,
    pub frames: Vec<Vec<u16>>,
}

impl Scan {
    pub fn generate(j1: u8, j2: u8, cols: u32, rows: u32, seed: u64, defect: (u32, u32)) -> Scan {
        let mut state = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut rnd = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as u32
        };
        let cells = usize::from(j1) * usize::from(j2);
        let mut frames = Vec::new();
        for r in 0..rows {
            for c in 0..cols {
                let mut f: Vec<u16> = (0..cells).map(|_| 900 + (rnd() % 200) as u16).collect();
                if (r, c) == defect {
                    for (k, v) in f.iter_mut().enumerate() {
                        if k % 3 == 0 {
                            *v = v.saturating_add(4000);
                        }
                    }
                }
                frames.push(f);
            }
        }
        Scan {
            j1,
            j2,
            cols,
            rows,
            frames,
        }
    }

    pub fn frame(&self, beam: usize) -> &[u16] {
        &self.frames[beam % self.frames.len()]
    }

    pub fn pos(&self, beam: usize) -> Position {
        let b = beam as u32 % (self.cols * self.rows);
        Position {
            row: b / self.cols,
            col: b % self.cols,
        }
    }

    pub fn scorer(&self) -> Scorer {
        Scorer::new(&Config::paper(Geometry::new(self.j1, self.j2).unwrap())).unwrap()
    }

    pub fn settings(&self, scorer: &Scorer, scores: bool) -> Settings {
        Settings {
            cols: self.cols,
            threshold: scorer.threshold_from_units(0.006),
            power_threshold: cvm_core::power::threshold_from_units(0.1),
            spread_threshold: cvm_core::spread::SPREAD_OFF,
            scores,
            max_defect_lines_per_row: 4,
            rows: self.rows,
            outputs: cvm_core::settings::Outputs::DEFAULT,
            sources: [cvm_core::settings::Source::Default; cvm_core::settings::KEYS],
        }
    }

    pub fn row_buffers(&self) -> (Vec<i32>, Vec<i32>) {
        let n = row_words(
            self.cols as usize,
            usize::from(self.j1),
            usize::from(self.j2),
        );
        (vec![0; n], vec![0; n])
    }
}

/// Collects lines.
#[derive(Default)]
pub struct Lines(pub Vec<(Vec<u8>, Priority)>);

impl LineSink for Lines {
    fn line(&mut self, line: &[u8], priority: Priority) {
        self.0.push((line.to_vec(), priority));
    }
}

impl Lines {
    pub fn text(&self) -> Vec<String> {
        self.0
            .iter()
            .map(|(l, _)| String::from_utf8(l.clone()).unwrap())
            .collect()
    }
}

/// The reference: the core pipeline fed directly, one scan, with the given
/// positions reported missing instead of scored.
pub fn reference(scan: &Scan, scores: bool, missing: &[Position], dropped: u32) -> Vec<String> {
    let placements: Vec<_> = (0..scan.frames.len())
        .map(|beam| {
            let pos = scan.pos(beam);
            (pos, (!missing.contains(&pos)).then_some(beam))
        })
        .collect();
    replay(scan, scores, &placements, 0, dropped)
}

/// The reference for explicit placements: the core pipeline fed, in this
/// order, the frame of beam `b` at each `(pos, Some(b))` and nothing at
/// each `(pos, None)` (reported missing), then `misplaced` counted and the
/// scan finished. Positions not listed are gaps (missing, too).
pub fn reference_placed(
    scan: &Scan,
    scores: bool,
    placements: &[(Position, Option<usize>)],
    misplaced: u32,
) -> Vec<String> {
    replay(scan, scores, placements, misplaced, 0)
}

fn replay(
    scan: &Scan,
    scores: bool,
    placements: &[(Position, Option<usize>)],
    misplaced: u32,
    dropped: u32,
) -> Vec<String> {
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    let mut p =
        Pipeline::<MAX_COLS>::new(&scorer, scan.settings(&scorer, scores), &mut a, &mut b).unwrap();
    let mut out = Lines::default();
    p.begin(&mut out);
    for &(pos, beam) in placements {
        match beam {
            Some(b) => p.push(pos, scan.frame(b), &mut out),
            None => p.mark_missing(pos, &mut out),
        };
    }
    p.count_misplaced(misplaced);
    p.finish(dropped, &mut out);
    out.text()
}

/// Frame buffers of samples, as both boards' acquisition fills them.
pub struct SampleFrames {
    pub bufs: [Vec<u16>; 2],
    pub released: Vec<usize>,
}

impl FrameStore for SampleFrames {
    fn frame(&mut self, buf: usize) -> Option<&[u16]> {
        self.bufs.get(buf).map(Vec::as_slice)
    }
    fn release(&mut self, buf: usize) {
        self.released.push(buf);
    }
}

/// The output queue plus what the "UART" has sent.
pub struct Uart<const CAP: usize> {
    pub queue: LineQueue<CAP>,
    pub sent: Vec<String>,
}

impl<const CAP: usize> LineSink for Uart<CAP> {
    fn line(&mut self, line: &[u8], priority: Priority) {
        self.queue.push(line, priority);
    }
}

impl<const CAP: usize> CountingSink for Uart<CAP> {
    fn dropped(&self) -> u32 {
        self.queue.dropped()
    }
}

impl<const CAP: usize> Uart<CAP> {
    /// Sends up to `n` lines.
    pub fn send(&mut self, n: usize) {
        let mut line = [0u8; cvm_core::protocol::MAX_LINE];
        for _ in 0..n {
            match self.queue.pop_into(&mut line) {
                Some(k) => self
                    .sent
                    .push(String::from_utf8(line[..k].to_vec()).unwrap()),
                None => break,
            }
        }
    }
}

/// A simulated board: the acquisition bookkeeping, the scoring driver and
/// the UART, stepped by the test.
pub struct Board<'a, const CAP: usize> {
    pub acq: Acquisition<2, 16>,
    pub frames: SampleFrames,
    pub driver: ScanDriver<'a, MAX_COLS>,
    pub uart: Uart<CAP>,
    /// Scans the driver said it finished (the H743 logs each one then).
    pub finished: u32,
}

impl<'a, const CAP: usize> Board<'a, CAP> {
    pub fn new(
        scan: &Scan,
        scorer: &'a Scorer,
        scores: bool,
        rows: (&'a mut [i32], &'a mut [i32]),
        reserve: usize,
    ) -> Self {
        let n = scorer.cells();
        let pipeline =
            Pipeline::new(scorer, scan.settings(scorer, scores), rows.0, rows.1).unwrap();
        Board {
            acq: Acquisition::new(),
            frames: SampleFrames {
                bufs: [vec![0; n], vec![0; n]],
                released: vec![],
            },
            driver: ScanDriver::new(pipeline, scan.cols, scan.rows),
            uart: Uart {
                queue: LineQueue::new(reserve),
                sent: vec![],
            },
            finished: 0,
        }
    }

    /// A DRDY edge; the SPI read of `frame` then completes (`ok = false`:
    /// with an SPI error). Returns whether the frame was read at all.
    pub fn drdy(&mut self, sync: bool, frame: &[u16], ok: bool) -> bool {
        match self.acq.drdy(sync) {
            Some(buf) => {
                self.frames.bufs[buf].copy_from_slice(frame);
                self.acq.read_done(buf, ok);
                true
            }
            None => false,
        }
    }

    /// The scoring loop body of the boards: scores while the queue has its
    /// keep reserve free, at most `max_beams` records (usize::MAX = all).
    pub fn score(&mut self, max_beams: usize) {
        let mut taken = 0;
        loop {
            if !self.uart.queue.keep_room() {
                return;
            }
            let rec = if self.driver.busy() {
                None
            } else {
                if taken == max_beams {
                    return;
                }
                let r = self.acq.take_next();
                if r.is_some() {
                    taken += 1;
                }
                r
            };
            if rec.is_none() && !self.driver.busy() {
                return;
            }
            if self.driver.step(rec, &mut self.frames, &mut self.uart) {
                self.finished += 1;
            }
            for b in self.frames.released.drain(..) {
                self.acq.release(b);
            }
        }
    }

    /// End of data, then everything sent. As on the boards, the data is
    /// only declared ended once every beam record has been scored (the UART
    /// draining as needed), and each end-of-data step waits for queue room.
    pub fn end(&mut self) {
        loop {
            let before = self.acq.pending();
            self.score(usize::MAX);
            let stuck = self.acq.pending() == before && self.uart.queue.is_empty();
            if (self.acq.pending() == 0 || stuck) && !self.driver.busy() {
                break;
            }
            self.uart.send(usize::MAX);
        }
        loop {
            self.uart.send(usize::MAX);
            let (more, finished) = self.driver.end_of_data(&mut self.frames, &mut self.uart);
            self.finished += u32::from(finished);
            if !more {
                break;
            }
        }
        self.uart.send(usize::MAX);
    }
}
