//! Defect objects: the defective positions grouped into 8-connected
//! components while the rows stream past, one record per defect.
//!
//! Rows arrive final and in order. Each row's defective positions form
//! runs (maximal horizontal segments); a run joins every object with a run
//! of the previous row within one column of it (8-neighbourhood), and when
//! a run touches two objects they merge. An object closes when a row
//! passes without touching it (or at the end of the scan) and is handed
//! out once, complete. Only the previous row's runs and the open objects
//! are kept: [`MAX_OBJECTS`] objects and as many runs per row. A run that
//! finds no free slot (its object, or its row's run table, is full) is
//! left out of every object and its positions are counted
//! ([`crate::stream::Totals::unobjected`]); an object can then be reported
//! in parts, never silently merged with a wrong one.
//!
//! # Statistics and their ranges
//!
//! Per object: first and last row and column, area (positions, saturating
//! `u32`), the peak (largest strength, the first in raster order on ties)
//! with its position and both channels' values there, the channels that
//! fired anywhere, and the strength-weighted centroid. The weight of a
//! position is its strength over `2^8` (threshold ratio in `Q8`), capped
//! at `2^24`; its offsets from the object's first row and column are below
//! `2^32`, so each product is below `2^56` and a sum of at most `2^32`
//! of them (area) stays below `2^88`: `u128` accumulators cannot
//! overflow. The centroid is reported in `Q8` positions (1/256).

use crate::channels::flags;
use crate::stream::{PositionScore, RowView, Totals};

/// Objects open at once, and runs kept per row.
pub const MAX_OBJECTS: usize = 32;

/// Largest weight of one position in the centroid (threshold ratio in Q8).
const MAX_WEIGHT: u64 = 1 << 24;

/// One defect, as its object line reports it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Object {
    /// Order of opening within the scan, from 0; a merged object keeps the
    /// smaller id.
    pub id: u32,
    pub row0: u32,
    pub row1: u32,
    pub col0: u32,
    pub col1: u32,
    /// Defective positions.
    pub area: u32,
    /// Largest [`PositionScore::strength`] of the object.
    pub peak: u32,
    pub peak_row: u32,
    pub peak_col: u32,
    /// Distance-gradient magnitude at the peak (`Q(q)`).
    pub peak_mag: u32,
    /// Power magnitude at the peak (`Q15`).
    pub peak_power: u16,
    /// Spread magnitude at the peak (`Q16`, [`crate::channels::spread`]; 0 while
    /// the spread channel is off).
    pub peak_spread: u32,
    /// Channels that fired anywhere in the object: [`flags::CVM_DEFECT`],
    /// [`flags::POWER_DEFECT`], [`flags::SPREAD_DEFECT`].
    pub channels: u8,
    /// Strength-weighted centroid, `Q8` (row, column).
    pub centroid_row_q8: u64,
    pub centroid_col_q8: u64,
}

/// `n / d` (`None` for `d = 0`), in 64 bits whenever both fit: a 128-bit
/// division is a long software routine on the target (several thousand
/// instructions per object closed, on the path to a board's verdict),
/// and every object of fewer than `2^16` positions at the largest
/// weights fits.
fn div(n: u128, d: u128) -> Option<u128> {
    match (u64::try_from(n), u64::try_from(d)) {
        (Ok(n), Ok(d)) => n.checked_div(d).map(u128::from),
        _ => n.checked_div(d),
    }
}

#[derive(Clone, Copy, Default)]
struct Open {
    obj: Object,
    /// Last row a run of this object was seen in.
    last_row: u32,
    w: u128,
    wr: u128,
    wc: u128,
    used: bool,
}

impl Open {
    /// Adds position `(row, col)`.
    fn add(&mut self, row: u32, col: u32, p: &PositionScore) {
        let o = &mut self.obj;
        o.row1 = o.row1.max(row);
        o.col0 = o.col0.min(col);
        o.col1 = o.col1.max(col);
        o.area = o.area.saturating_add(1);
        o.channels |= p.flags & flags::DEFECT;
        // Positions come in raster order: a tie keeps the first.
        if o.area == 1 || p.strength > o.peak {
            o.peak = p.strength;
            o.peak_row = row;
            o.peak_col = col;
            o.peak_mag = p.mag;
            o.peak_power = p.pmag;
            o.peak_spread = p.smag;
        }
        // Each product is below 2^56 (see the module's ranges): one 64-bit
        // multiply, then a 128-bit sum.
        let w = ((p.strength >> 8) as u64).clamp(1, MAX_WEIGHT);
        self.w += w as u128;
        self.wr += (w * (row - o.row0) as u64) as u128;
        self.wc += (w * col as u64) as u128;
        self.last_row = row;
    }

    /// Takes `other` in (both open, `other` released by the caller).
    fn absorb(&mut self, other: &Open) {
        let base = self.obj.row0.min(other.obj.row0);
        // Re-base both row sums on the earlier first row.
        let mine = (self.obj.row0 - base) as u128;
        let theirs = (other.obj.row0 - base) as u128;
        self.wr = self.wr + self.w * mine + other.wr + other.w * theirs;
        self.w += other.w;
        self.wc += other.wc;
        self.last_row = self.last_row.max(other.last_row);
        let (a, b) = (&mut self.obj, &other.obj);
        let first = a.peak > b.peak
            || (a.peak == b.peak && (a.peak_row, a.peak_col) <= (b.peak_row, b.peak_col));
        if !first {
            a.peak = b.peak;
            a.peak_row = b.peak_row;
            a.peak_col = b.peak_col;
            a.peak_mag = b.peak_mag;
            a.peak_power = b.peak_power;
            a.peak_spread = b.peak_spread;
        }
        a.id = a.id.min(b.id);
        a.row0 = base;
        a.row1 = a.row1.max(b.row1);
        a.col0 = a.col0.min(b.col0);
        a.col1 = a.col1.max(b.col1);
        a.area = a.area.saturating_add(b.area);
        a.channels |= b.channels;
    }

    fn close(&self) -> Object {
        let mut o = self.obj;
        if let (Some(r), Some(c)) = (div(self.wr << 8, self.w), div(self.wc << 8, self.w)) {
            o.centroid_row_q8 = r as u64 + ((o.row0 as u64) << 8);
            o.centroid_col_q8 = c as u64;
        }
        o
    }
}

impl Object {
    /// Every field 0.
    pub const EMPTY: Object = Object {
        id: 0,
        row0: 0,
        row1: 0,
        col0: 0,
        col1: 0,
        area: 0,
        peak: 0,
        peak_row: 0,
        peak_col: 0,
        peak_mag: 0,
        peak_power: 0,
        peak_spread: 0,
        channels: 0,
        centroid_row_q8: 0,
        centroid_col_q8: 0,
    };
}

#[derive(Clone, Copy, Default)]
struct Run {
    c0: u32,
    c1: u32,
    /// Slot of its object.
    slot: u8,
}

/// The streaming labeller: about 4.5 KB.
pub struct Objects {
    open: [Open; MAX_OBJECTS],
    runs: [[Run; MAX_OBJECTS]; 2],
    n_runs: [usize; 2],
    /// Index (0 or 1) of the previous row's runs in `runs`.
    prev: usize,
    last_row: Option<u32>,
    next_id: u32,
    reported: u32,
    unobjected: u32,
}

impl Default for Objects {
    fn default() -> Self {
        Self::new()
    }
}

impl Objects {
    pub const fn new() -> Self {
        const OPEN: Open = Open {
            obj: Object::EMPTY,
            last_row: 0,
            w: 0,
            wr: 0,
            wc: 0,
            used: false,
        };
        const RUN: Run = Run {
            c0: 0,
            c1: 0,
            slot: 0,
        };
        Objects {
            open: [OPEN; MAX_OBJECTS],
            runs: [[RUN; MAX_OBJECTS]; 2],
            n_runs: [0; 2],
            prev: 0,
            last_row: None,
            next_id: 0,
            reported: 0,
            unobjected: 0,
        }
    }

    /// Whether an object still open satisfies `pred` as it stands (its
    /// area and peak so far: both only grow until it closes, merged or
    /// not).
    pub fn any_open(&self, pred: impl Fn(&Object) -> bool) -> bool {
        self.open.iter().any(|o| o.used && pred(&o.obj))
    }

    /// Objects reported since the last [`Objects::finish_with`].
    pub fn reported(&self) -> u32 {
        self.reported
    }

    /// Defective positions left out of every object since the last
    /// [`Objects::finish_with`].
    pub fn unobjected(&self) -> u32 {
        self.unobjected
    }

    /// Takes a finished row in; objects that the row closes go to `out`
    /// in increasing id.
    pub fn push_row(&mut self, view: &RowView, out: &mut dyn FnMut(&Object)) {
        let row = view.summary.row;
        if self.last_row.is_some_and(|r| r.checked_add(1) != Some(row)) {
            // Not the next row (cannot happen inside a scan): nothing connects.
            self.close_all(out);
        }
        let cur = 1 - (self.prev & 1);
        if let Some(n) = self.n_runs.get_mut(cur) {
            *n = 0;
        }
        let scores = view.scores;
        let mut c = 0usize;
        // Iterators, not indexing: this scan runs over every position of
        // every row, on the path to a board's verdict.
        while let Some(start) = scores
            .get(c..)
            .and_then(|s| s.iter().position(PositionScore::is_defect))
        {
            let start = c + start;
            let len = scores
                .get(start..)
                .map_or(0, |s| s.iter().take_while(|p| p.is_defect()).count());
            c = start + len.max(1);
            self.run(row, start, c, scores, cur);
        }
        self.prev = cur;
        self.last_row = Some(row);
        self.close_where(out, |o| o.last_row != row);
    }

    /// Ends the scan: every open object goes to `out`, the scan's counts
    /// into `totals`, and the counts restart.
    pub fn finish_with(&mut self, out: &mut dyn FnMut(&Object), totals: &mut Totals) {
        self.close_all(out);
        totals.objects = self.reported;
        totals.unobjected = self.unobjected;
        // Every slot is free and no run kept: the tables' contents are
        // never read again, so only the counts restart (clearing 4.5 KB
        // would delay a board's verdict).
        self.prev = 0;
        self.next_id = 0;
        self.reported = 0;
        self.unobjected = 0;
    }

    fn close_all(&mut self, out: &mut dyn FnMut(&Object)) {
        self.close_where(out, |_| true);
        self.n_runs = [0; 2];
        self.last_row = None;
    }

    /// The run `[c0, c1)` of `row`: joins, merges or opens objects.
    fn run(&mut self, row: u32, c0: usize, c1: usize, scores: &[PositionScore], cur: usize) {
        let (c0u, c1u) = (c0 as u32, (c1 - 1) as u32);
        let prev = self.prev & 1;
        let mut slot: Option<u8> = None;
        for i in 0..self.n_runs.get(prev).copied().unwrap_or(0) {
            let Some(r) = self.runs.get(prev).and_then(|rs| rs.get(i)).copied() else {
                break;
            };
            // 8-neighbourhood: within one column of the run. The previous
            // row's runs are in column order: none after this one touches.
            if r.c0 > c1u.saturating_add(1) {
                break;
            }
            if r.c1.saturating_add(1) < c0u {
                continue;
            }
            match slot {
                None => slot = Some(r.slot),
                Some(s) if s != r.slot => {
                    self.merge(s, r.slot);
                }
                Some(_) => {}
            }
        }
        // A run the table cannot keep opens no object (it would stay empty).
        let n = self.n_runs.get(cur).copied().unwrap_or(0);
        let room = n < MAX_OBJECTS;
        let slot = match slot {
            Some(s) => Some(s),
            None if room => self.open_slot(row, c0u),
            None => None,
        };
        let (Some(s), true) = (slot, room) else {
            self.unobjected = self.unobjected.saturating_add((c1 - c0) as u32);
            return;
        };
        if let Some(o) = self.open.get_mut(s as usize) {
            for (p, col) in scores.get(c0..c1).unwrap_or(&[]).iter().zip(c0u..) {
                o.add(row, col, p);
            }
        }
        if let Some(r) = self.runs.get_mut(cur).and_then(|rs| rs.get_mut(n)) {
            *r = Run {
                c0: c0u,
                c1: c1u,
                slot: s,
            };
        }
        if let Some(k) = self.n_runs.get_mut(cur) {
            *k = n + 1;
        }
    }

    fn open_slot(&mut self, row: u32, col: u32) -> Option<u8> {
        let i = self.open.iter().position(|o| !o.used)?;
        let o = self.open.get_mut(i)?;
        *o = Open {
            obj: Object {
                id: self.next_id,
                row0: row,
                row1: row,
                col0: col,
                col1: col,
                ..Object::default()
            },
            // `last_row` is set by the first `add`, which follows at once.
            used: true,
            ..Open::default()
        };
        self.next_id = self.next_id.saturating_add(1);
        Some(i as u8)
    }

    /// Merges the object in slot `from` into the one in `into`; every run
    /// of `from` now points at `into`.
    fn merge(&mut self, into: u8, from: u8) {
        let Some(other) = self.open.get(from as usize).copied() else {
            return;
        };
        if let Some(o) = self.open.get_mut(into as usize) {
            o.absorb(&other);
        }
        if let Some(o) = self.open.get_mut(from as usize) {
            o.used = false;
        }
        for (rs, &n) in self.runs.iter_mut().zip(self.n_runs.iter()) {
            for r in rs.iter_mut().take(n) {
                if r.slot == from {
                    r.slot = into;
                }
            }
        }
    }

    /// Closes every open object `pred` selects, in increasing id.
    fn close_where(&mut self, out: &mut dyn FnMut(&Object), pred: impl Fn(&Open) -> bool) {
        loop {
            let mut best: Option<usize> = None;
            for (i, o) in self.open.iter().enumerate() {
                if o.used
                    && pred(o)
                    && best.is_none_or(|b| self.open.get(b).is_some_and(|x| o.obj.id < x.obj.id))
                {
                    best = Some(i);
                }
            }
            let Some(i) = best else { break };
            if let Some(o) = self.open.get_mut(i) {
                o.used = false;
                let obj = o.close();
                self.reported = self.reported.saturating_add(1);
                out(&obj);
            }
        }
    }
}
