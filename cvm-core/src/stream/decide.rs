//! The engine's decisions: each position's magnitudes and channel
//! decisions as soon as it is final, its row's summary built alongside,
//! and a final row put out.

use super::{Engine, PositionScore, RowView, strength};
use crate::channels::flags;
use crate::channels::magnitude::magnitude;
use crate::channels::power::{self, contrast};
use crate::channels::spread::{self, SPREAD_OFF};

impl<const MAX_COLS: usize> Engine<'_, MAX_COLS> {
    /// The last row pending: its undecided positions get their vertical
    /// component by the border rule and are decided (the end of a scan
    /// whose row count is not known, or that ended early).
    pub(super) fn decide_last(&mut self) {
        let Some(p) = self.pending else { return };
        let rb = (self.cur ^ 1) & 1;
        let pb = (p % 2) as usize;
        for c in self.decided[rb]..self.cols {
            let meta = |b: usize| self.meta[b].get(c).copied().unwrap_or(flags::NO_DATA);
            let (own, above) = (meta(pb), meta(1 - pb));
            if own & flags::NO_DATA != 0 {
                continue;
            }
            let (g1, p1, s1) = if above & flags::NO_DATA == 0 {
                let (a, b) = (self.slot(1 - pb, c), self.slot(pb, c));
                (
                    self.scorer.distance(a, b),
                    contrast(self.power(1 - pb, c), self.power(pb, c)),
                    self.spread(1 - pb, c).abs_diff(self.spread(pb, c)),
                )
            } else {
                (0, 0, 0)
            };
            if let Some(s) = self.results[rb].get_mut(c) {
                s.g1 = g1;
                s.p1 = p1;
                s.s1 = s1;
            }
        }
        self.decide_upto(rb, self.cols);
    }

    /// Decides the positions of result buffer `rb` up to column `end`
    /// (excluded), in column order, each once.
    pub(super) fn decide_upto(&mut self, rb: usize, end: usize) {
        let rb = rb & 1;
        let end = end.min(self.cols);
        while self.decided[rb] < end {
            let c = self.decided[rb];
            self.decide(rb, c);
            self.decided[rb] = c + 1;
        }
    }

    /// The magnitudes and decisions of a final position, added to its
    /// row's summary.
    fn decide(&mut self, rb: usize, c: usize) {
        let (Some(s), Some(sum)) = (
            self.results.get_mut(rb).and_then(|r| r.get_mut(c)),
            self.sums.get_mut(rb),
        ) else {
            return;
        };
        if s.flags & flags::NO_DATA != 0 {
            *s = PositionScore {
                flags: s.flags,
                ..PositionScore::default()
            };
            sum.no_data += 1;
            return;
        }
        s.mag = magnitude(s.g0, s.g1);
        s.pmag = power::magnitude(s.p0, s.p1);
        s.flags &= !flags::DEFECT;
        s.strength = 0;
        // The magnitude is at least either score, so it is at the top
        // of its range whenever one of them is.
        if s.mag == u32::MAX {
            s.flags |= flags::CLIPPED;
            self.totals.clipped += 1;
        }
        if s.flags & flags::DARK != 0 {
            sum.dark += 1;
        }
        if s.flags & flags::SATURATED != 0 {
            sum.saturated += 1;
        }
        if s.mag >= self.threshold {
            s.flags |= flags::CVM_DEFECT;
            s.strength = strength(s.mag, self.threshold);
        }
        if s.pmag as u32 >= self.power_threshold {
            s.flags |= flags::POWER_DEFECT;
            s.strength = s
                .strength
                .max(strength(s.pmag as u32, self.power_threshold));
        }
        // Off, nothing was measured: `s0`, `s1` and `smag` stay 0.
        if self.spread_threshold != SPREAD_OFF {
            s.smag = spread::magnitude(s.s0, s.s1);
            if s.smag >= self.spread_threshold {
                s.flags |= flags::SPREAD_DEFECT;
                s.strength = s.strength.max(strength(s.smag, self.spread_threshold));
            }
        }
        if s.is_defect() {
            sum.defects += 1;
        }
        if sum.argmax.is_none() || s.mag > sum.max {
            sum.max = s.mag;
            sum.argmax = Some(c as u32);
        }
        if sum.pargmax.is_none() || s.pmag as u32 > sum.pmax {
            sum.pmax = s.pmag as u32;
            sum.pargmax = Some(c as u32);
        }
    }

    pub(super) fn view(&self, rb: usize) -> RowView<'_> {
        let rb = rb & 1;
        RowView {
            summary: self.sums[rb],
            scores: self.results[rb].get(..self.cols).unwrap_or(&[]),
            threshold: self.threshold,
            power_threshold: self.power_threshold,
        }
    }

    /// Puts out the final row in result buffer `rb`. Out of line and
    /// through `dyn`: one copy for every caller, and the line encoder
    /// behind `out` is not inlined into each of them (about 15 KB of flash
    /// per copy).
    #[inline(never)]
    pub(super) fn emit(&mut self, rb: usize, out: &mut dyn FnMut(&RowView)) {
        let sum = self.sums[rb & 1];
        self.totals.defects += sum.defects;
        self.totals.rows += 1;
        out(&self.view(rb));
    }
}
