//! The window: a beam settled in its slot, the vertical component of the
//! position above it and the horizontal component of the one to its left
//! (the module doc of [`super`]).

use super::{Engine, PositionScore};
use crate::channels::flags;
use crate::channels::power::contrast;
use crate::channels::spread::SPREAD_OFF;
use crate::scorer::{FrameError, Prepared};

impl<const MAX_COLS: usize> Engine<'_, MAX_COLS> {
    /// Settles position `(current, next_col)`: with a frame it is prepared
    /// and becomes the lower neighbour of the row above; then the left
    /// neighbour's horizontal component is final.
    pub(super) fn resolve(&mut self, frame: Option<&[u16]>) {
        let Some(r) = self.current else { return };
        let c = self.next_col;
        let b = (r % 2) as usize;
        let has = |m: &[u8; MAX_COLS]| m.get(c).is_some_and(|f| f & flags::NO_DATA == 0);
        // (r-1, c) needs its vertical component when it has data; slot c of
        // buffer b still holds (r-2, c), its upper neighbour.
        let mid_ok = self.pending.is_some() && has(&self.meta[1 - b]);
        let up_ok = has(&self.meta[b]);
        // The new map is prepared straight into slot c. When both
        // neighbours of (r-1, c) have data, their distance comes out of the
        // embedding as it overwrites (r-2, c).
        let start = c * self.words;
        let fuse = mid_ok && up_ok;
        let near_start = (c % 3) * self.words;
        let near = self
            .near
            .get_mut(near_start..near_start + self.words)
            .unwrap_or(&mut []);
        let spread = self.spread_threshold != SPREAD_OFF;
        let prepared = match (frame, self.bufs[b].get_mut(start..start + self.words)) {
            (Some(f), Some(slot)) => {
                self.scorer
                    .prepare_beam(f, slot, near, &mut self.scratch, fuse, spread)
            }
            _ => Err(FrameError::Length),
        };
        let (own, fused, pw, sq) = match prepared {
            Ok(Prepared {
                flags: fl,
                power,
                score,
                spread,
            }) => {
                self.totals.frames += 1;
                if fl & flags::DARK != 0 {
                    self.totals.dark += 1;
                }
                if fl & flags::SATURATED != 0 {
                    self.totals.saturated += 1;
                }
                (fl, score, power, spread)
            }
            Err(_) => {
                self.totals.missing += 1;
                (flags::NO_DATA, 0, 0, 0)
            }
        };

        let prev_rb = (self.cur ^ 1) & 1;
        if mid_ok && self.decided[prev_rb] <= c {
            self.vertical(b, c, up_ok, (own, fused, pw, sq));
        }

        if let Some(m) = self.meta[b].get_mut(c) {
            *m = own;
        }
        if let Some(p) = self.powers[b].get_mut(c) {
            *p = pw;
        }
        if let Some(q) = self.spreads[b].get_mut(c) {
            *q = sq;
        }
        if let Some(s) = self.cur_row().get_mut(c) {
            *s = PositionScore {
                flags: own,
                ..PositionScore::default()
            };
        }
        // (r-1, c) is final.
        if self.pending.is_some() {
            self.decide_upto(prev_rb, c + 1);
        }
        let last = self.is_last(r);
        if last && own & flags::NO_DATA == 0 {
            // The last row's vertical component, by the border rule (the
            // missing lower neighbour is the map itself): `d(up, own)`.
            let (g1, p1, s1) = if has(&self.meta[1 - b]) {
                (
                    self.scorer.distance(self.slot(1 - b, c), self.slot(b, c)),
                    contrast(self.power(1 - b, c), pw),
                    self.spread(1 - b, c).abs_diff(sq),
                )
            } else {
                (0, 0, 0)
            };
            if let Some(s) = self.cur_row().get_mut(c) {
                s.g1 = g1;
                s.p1 = p1;
                s.s1 = s1;
            }
        }

        // Horizontal component of (r, c-1), now that its right neighbour is settled.
        if c >= 1 {
            self.horizontal(b, c - 1, Some(c));
            if last {
                self.decide_upto(self.cur, c);
            }
        }
        self.next_col = c + 1;
    }

    /// Vertical component of `(r-1, c)` (row `r` in buffer `b`), which has
    /// data, once the map of `(r, c)` is prepared: `new` is its flags, the
    /// distance fused into its preparation, its power and its spread. A
    /// missing neighbour is replaced by `(r-1, c)` itself; without a new
    /// map slot `c` still holds `(r-2, c)`. (A row decided already is the
    /// scan's last by the row count, with its border rule: see
    /// `set_rows`.)
    #[inline(always)]
    fn vertical(&mut self, b: usize, c: usize, up_ok: bool, new: (u8, u32, u32, u16)) {
        let (own, fused, pw, sq) = new;
        let down_ok = own & flags::NO_DATA == 0;
        let (up_p, mid_p) = (self.power(b, c), self.power(1 - b, c));
        let (up_q, mid_q) = (self.spread(b, c), self.spread(1 - b, c));
        let (g1, p1, s1) = match (up_ok, down_ok) {
            (true, true) => (fused, contrast(up_p, pw), up_q.abs_diff(sq)),
            (true, false) => (
                self.scorer.distance(self.slot(b, c), self.slot(1 - b, c)),
                contrast(up_p, mid_p),
                up_q.abs_diff(mid_q),
            ),
            (false, true) => (
                self.scorer.distance(self.slot(1 - b, c), self.slot(b, c)),
                contrast(mid_p, pw),
                mid_q.abs_diff(sq),
            ),
            (false, false) => (0, 0, 0),
        };
        if let Some(s) = self.results[(self.cur ^ 1) & 1].get_mut(c) {
            s.g1 = g1;
            s.p1 = p1;
            s.s1 = s1;
        }
    }

    /// `g0` of `(current, c)` from its left neighbour `c-1` and the given
    /// right neighbour, each replaced by the map itself where absent.
    pub(super) fn horizontal(&mut self, b: usize, c: usize, right: Option<usize>) {
        let ok = |m: &[u8; MAX_COLS], i: usize| m.get(i).is_some_and(|f| f & flags::NO_DATA == 0);
        if !ok(&self.meta[b], c) {
            return;
        }
        let left = if c >= 1 && ok(&self.meta[b], c - 1) {
            c - 1
        } else {
            c
        };
        let right = match right {
            Some(rc) if ok(&self.meta[b], rc) => rc,
            _ => c,
        };
        let (g0, p0, s0) = if left == right {
            (0, 0, 0)
        } else {
            (
                self.scorer
                    .distance(self.recent(b, left), self.recent(b, right)),
                contrast(self.power(b, left), self.power(b, right)),
                self.spread(b, left).abs_diff(self.spread(b, right)),
            )
        };
        if let Some(s) = self.cur_row().get_mut(c) {
            s.g0 = g0;
            s.p0 = p0;
            s.s0 = s0;
        }
    }

    /// Power of the map in slot `c` of buffer `buf` (0 where none is held).
    pub(super) fn power(&self, buf: usize, c: usize) -> u32 {
        self.powers
            .get(buf)
            .and_then(|p| p.get(c))
            .copied()
            .unwrap_or(0)
    }

    /// Spread `q` of the map in slot `c` of buffer `buf` (0 where none is
    /// held).
    pub(super) fn spread(&self, buf: usize, c: usize) -> u16 {
        self.spreads
            .get(buf)
            .and_then(|q| q.get(c))
            .copied()
            .unwrap_or(0)
    }
}
