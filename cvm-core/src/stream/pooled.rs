//! The pooled decisions in the window ([`crate::channels::pooled`]): each
//! position `(R, C)` against the positions around it, in the three rows
//! `R-1..=R+1` and the four columns `C-2..=C+1`.
//!
//! Four footprints end at `(R, C)`, so each is taken once in a scan, at
//! its bottom-right position, which it is decided on:
//!
//! | footprint | positions | ring |
//! |---|---|---|
//! | one | `(R, C)` | its 8 neighbours |
//! | pair across | `(R, C-1)`, `(R, C)` | the 10 around them |
//! | pair down | `(R-1, C)`, `(R, C)` | the 7 around them in these rows |
//! | square | `(R-1..=R, C-1..=C)` | the 8 around them in these rows |
//!
//! A defect between two beams shares its change between a pair, one
//! between four a square. The ring holds the positions with data, in the
//! scan; a footprint with a position without data, or with fewer than
//! [`MIN_RING`] positions in its ring, is not taken. A position's values
//! are the largest loss and raise over its footprints.
//!
//! When `(R, C+1)` is settled the window is whole, except at the scan's
//! right border, its last row (no row below) and its first (no row above):
//! those positions are missing from the rings. Row `R-1` is what the
//! engine's two row buffers no longer hold once row `R+1` comes in: each
//! slot's flags, power and spread are kept in [`Older`] as the new beam
//! overwrites them.

use super::Engine;
use crate::channels::flags;
use crate::channels::pooled::{POOLED_OFF, loss, raise};

/// The fewest ring positions a footprint is taken with.
pub const MIN_RING: u32 = 3;

/// Each column's flags, power and spread of the row before the two in
/// the row buffers.
pub(super) struct Older<const N: usize> {
    pub meta: [u8; N],
    pub p: [u32; N],
    pub q: [u16; N],
}

impl<const N: usize> Older<N> {
    pub const fn new() -> Self {
        Older {
            meta: [flags::NO_DATA; N],
            p: [0; N],
            q: [0; N],
        }
    }
}

/// Where a row of the window is: the older row, a row buffer, or none
/// (outside the scan).
#[derive(Clone, Copy)]
pub(super) enum Row {
    Older,
    Buf(usize),
    None,
}

/// Cell `(row, col)` of the 3 x 4 window, `row` 0..3 for `R-1..=R+1` and
/// `col` 0..4 for `C-2..=C+1`, as a bit.
const fn bit(row: u32, col: u32) -> u16 {
    1 << (row * 4 + col)
}

const fn bits(cells: &[(u32, u32)]) -> u16 {
    let mut m = 0;
    let mut i = 0;
    while i < cells.len() {
        m |= bit(cells[i].0, cells[i].1);
        i += 1;
    }
    m
}

/// (footprint, ring) of each footprint ending at `(R, C)` (module doc).
const FOOTPRINTS: [(u16, u16); 4] = [
    (
        bits(&[(1, 2)]),
        bits(&[
            (0, 1),
            (0, 2),
            (0, 3),
            (1, 1),
            (1, 3),
            (2, 1),
            (2, 2),
            (2, 3),
        ]),
    ),
    (
        bits(&[(1, 1), (1, 2)]),
        bits(&[
            (0, 0),
            (0, 1),
            (0, 2),
            (0, 3),
            (1, 0),
            (1, 3),
            (2, 0),
            (2, 1),
            (2, 2),
            (2, 3),
        ]),
    ),
    (
        bits(&[(0, 2), (1, 2)]),
        bits(&[(0, 1), (0, 3), (1, 1), (1, 3), (2, 1), (2, 2), (2, 3)]),
    ),
    (
        bits(&[(0, 1), (0, 2), (1, 1), (1, 2)]),
        bits(&[
            (0, 0),
            (0, 3),
            (1, 0),
            (1, 3),
            (2, 0),
            (2, 1),
            (2, 2),
            (2, 3),
        ]),
    ),
];

impl<const MAX_COLS: usize> Engine<'_, MAX_COLS> {
    /// Either pooled decision is on.
    pub(super) fn pooling(&self) -> bool {
        self.pooled_thresholds != (POOLED_OFF, POOLED_OFF)
    }

    /// Keeps slot `c` of buffer `b` (row `r-2`) before row `r` overwrites it.
    #[inline(always)]
    pub(super) fn keep_older(&mut self, b: usize, c: usize) {
        let meta = self.meta.get(b).and_then(|r| r.get(c)).copied();
        let (pw, sq) = (self.power(b, c), self.spread(b, c));
        if let (Some(m), Some(p), Some(q)) = (
            self.older.meta.get_mut(c),
            self.older.p.get_mut(c),
            self.older.q.get_mut(c),
        ) {
            *m = meta.unwrap_or(flags::NO_DATA);
            *p = pw;
            *q = sq;
        }
    }

    /// Flags, power and spread of `(row, col)`; `None` without data.
    fn cell(&self, row: Row, col: usize) -> Option<(u32, u16)> {
        let (meta, p, q) = match row {
            Row::Older => (
                *self.older.meta.get(col)?,
                *self.older.p.get(col)?,
                *self.older.q.get(col)?,
            ),
            Row::Buf(b) => (
                *self.meta.get(b)?.get(col)?,
                self.power(b, col),
                self.spread(b, col),
            ),
            Row::None => return None,
        };
        (meta & flags::NO_DATA == 0).then_some((p, q))
    }

    /// The largest loss and raise of the footprints ending at `(R, c)`,
    /// rows `R-1`, `R`, `R+1` found at `rows`. Columns at and beyond
    /// `self.cols` are outside the scan.
    pub(super) fn pooled_at(&self, rows: [Row; 3], c: usize) -> (u16, u32) {
        let mut ok = 0u16;
        let mut p = [0u32; 12];
        let mut q = [0u16; 12];
        for (i, &row) in rows.iter().enumerate() {
            for j in 0..4 {
                let Some(col) = (c + j).checked_sub(2).filter(|&x| x < self.cols) else {
                    continue;
                };
                if let Some((pw, sq)) = self.cell(row, col) {
                    let k = i * 4 + j;
                    ok |= 1 << k;
                    p[k] = pw;
                    q[k] = sq;
                }
            }
        }
        let mut best = (0u32, 0u32);
        for (foot, ring) in FOOTPRINTS {
            if ok & foot != foot {
                continue;
            }
            let ring = ring & ok;
            let (k, m) = (foot.count_ones(), ring.count_ones());
            if m < MIN_RING {
                continue;
            }
            let sum = |mask: u16| {
                let (mut sp, mut sq) = (0u32, 0u32);
                for i in 0..12 {
                    if mask & (1 << i) != 0 {
                        sp += p[i];
                        sq += q[i] as u32;
                    }
                }
                (sp, sq)
            };
            let ((fp, fq), (rp, rq)) = (sum(foot), sum(ring));
            best.0 = best.0.max(loss(fp, k, rp, m));
            best.1 = best.1.max(raise(fq, k, rq, m));
        }
        // Footprints of at most four positions against rings of at most
        // ten keep the loss below 2^16 (channels::pooled).
        (best.0.min(u16::MAX as u32) as u16, best.1)
    }

    /// `(R, c)`, decided already in result buffer `rb`, gets its pooled
    /// values and the decisions they make: the power channel fires on the
    /// loss, the spread channel on the raise, each against its pooled
    /// threshold; the row's summary counts a position that only now is a
    /// defect.
    pub(super) fn pool(&mut self, rb: usize, rows: [Row; 3], c: usize) {
        if c >= self.cols {
            return;
        }
        let (pl, pr) = self.pooled_at(rows, c);
        let (tl, tr) = self.pooled_thresholds;
        let (Some(s), Some(sum)) = (
            self.results.get_mut(rb & 1).and_then(|r| r.get_mut(c)),
            self.sums.get_mut(rb & 1),
        ) else {
            return;
        };
        if s.flags & flags::NO_DATA != 0 {
            return;
        }
        s.pl = pl;
        s.pr = pr;
        let was = s.is_defect();
        if pl as u32 >= tl {
            s.flags |= flags::POWER_DEFECT;
            s.strength = s.strength.max(super::strength(pl as u32, tl));
        }
        if pr >= tr {
            s.flags |= flags::SPREAD_DEFECT;
            s.strength = s.strength.max(super::strength(pr, tr));
        }
        if !was && s.is_defect() {
            sum.defects += 1;
        }
    }
}
