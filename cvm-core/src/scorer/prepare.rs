//! The per-map work, done once per beam: one entry point,
//! [`Scorer::prepare_map`], for both kernel sets, with the two shorter
//! forms the host tools use.

use crate::channels::flags;
use crate::channels::spread;
use crate::scorer::embed::embed;
use crate::scorer::error::FrameError;
use crate::scorer::setup::{Kind, Scorer};
use crate::scorer::square;
use crate::scorer::sum::{FrameCopy, sum_and_peak};
use crate::scorer::words::{copy_words, squared_difference};

/// What [`Scorer::prepare_map`] learnt about one map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Prepared {
    /// [`flags::DARK`], [`flags::SATURATED`].
    pub flags: u8,
    /// The map's power: the sum of its samples, below `256 * 65535 < 2^24`.
    pub power: u32,
    /// With `replacing`: the score of the distance between the map the
    /// state held and the new one; 0 otherwise.
    pub score: u32,
    /// The share of the power outside the core around the brightest cell,
    /// `Q16` ([`crate::channels::spread`]); 0 for a dark map, and when not measured
    /// ([`Scorer::prepare_beam`]).
    pub spread: u16,
}

/// Scratch space of the square kernels: a map's folded blocks, which the
/// embedding overwrites in place. (The paper kernels' row pass keeps its
/// output on the stack: see the module `embed`.)
#[derive(Clone)]
pub struct Scratch {
    z: [i32; square::FOLD_WORDS],
}

impl Scratch {
    pub const fn new() -> Self {
        Scratch {
            z: [0; square::FOLD_WORDS],
        }
    }
}

impl Default for Scratch {
    fn default() -> Self {
        Self::new()
    }
}

impl Scorer {
    /// Normalises and embeds one raw frame into `state`
    /// ([`Scorer::state_words`] words) and returns the map's flags:
    /// [`Scorer::prepare_map`] with scratch space of its own, no near
    /// copy and no distance.
    pub fn prepare(&self, frame: &[u16], state: &mut [i32]) -> Result<u8, FrameError> {
        self.prepare_with(frame, state, &mut Scratch::new())
    }

    /// [`Scorer::prepare`] with caller-owned scratch space, so that a loop
    /// over many maps does not clear 4.5 KiB of stack for every one.
    pub fn prepare_with(
        &self,
        frame: &[u16],
        state: &mut [i32],
        scratch: &mut Scratch,
    ) -> Result<u8, FrameError> {
        self.prepare_map(frame, state, &mut [], scratch, false)
            .map(|p| p.flags)
    }

    /// Normalises and embeds one raw frame into `state`
    /// ([`Scorer::state_words`] words): the per-map work of the streaming
    /// engine. Returns the map's flags and its power (sample sum), which
    /// the normalisation computes anyway.
    ///
    /// With `replacing`, `state` holds a prepared map, and the result also
    /// carries the score of the distance between that map and the new one
    /// (equal to `distance(old, new)`), computed while the new one
    /// overwrites it: the engine's vertical component, without a copy of
    /// the new map or a second pass.
    ///
    /// The prepared map is also written to `near` when it holds
    /// [`Scorer::state_words`] words (else not): the engine keeps the
    /// current row's last maps there, in memory it reads faster than the
    /// row buffers (DTCM on the H743), for the horizontal distances. With
    /// paper kernels the copy is one more store per word in the column
    /// pass; square kernels copy the state after.
    ///
    /// The map's spread ([`Prepared::spread`]) is measured too.
    pub fn prepare_map(
        &self,
        frame: &[u16],
        state: &mut [i32],
        near: &mut [i32],
        scratch: &mut Scratch,
        replacing: bool,
    ) -> Result<Prepared, FrameError> {
        self.prepare_beam(frame, state, near, scratch, replacing, true)
    }

    /// [`Scorer::prepare_map`], the spread measured only with `spread`
    /// (else [`Prepared::spread`] is 0): the streaming engine measures it
    /// only while its spread channel is on, so that a channel that is off
    /// costs the beam nothing.
    #[inline(always)]
    pub fn prepare_beam(
        &self,
        frame: &[u16],
        state: &mut [i32],
        near: &mut [i32],
        scratch: &mut Scratch,
        replacing: bool,
        spread: bool,
    ) -> Result<Prepared, FrameError> {
        let measure = spread;
        let n = self.cells();
        if frame.len() != n {
            return Err(FrameError::Length);
        }
        let Some(state) = state.get_mut(..self.state_words()) else {
            return Err(FrameError::Length);
        };
        match self.kind {
            Kind::Square { .. } => {
                if self.factors.is_empty() {
                    return Err(FrameError::Factors);
                }
                let blocks = self.blocks();
                let mut copy = FrameCopy::new();
                let (power, fl, frame, top) = self.sum_pass(frame, &mut copy);
                let spread = if measure {
                    self.spread(frame, power, top)
                } else {
                    0
                };
                square::fold(&blocks, frame, self.scale(power), &mut scratch.z);
                if !square::embed(&blocks, self.factors, &mut scratch.z) {
                    return Err(FrameError::Factors);
                }
                let e = scratch.z.get(..n).unwrap_or(&[]);
                let acc = if replacing {
                    squared_difference(state, e)
                } else {
                    0
                };
                copy_words(e, state);
                if let Some(near) = near.get_mut(..n) {
                    copy_words(e, near);
                }
                Ok(Prepared {
                    flags: fl,
                    power,
                    score: if replacing { self.to_score(acc) } else { 0 },
                    spread,
                })
            }
            Kind::Paper => {
                let mut copy = FrameCopy::new();
                let (sum, fl, frame, top) = self.sum_pass(frame, &mut copy);
                let spread = if measure {
                    self.spread(frame, sum, top)
                } else {
                    0
                };
                let conv = self.scale(sum);
                let acc = embed(
                    &self.passes,
                    &self.f1,
                    &self.f2,
                    frame,
                    conv,
                    state,
                    near,
                    replacing,
                );
                Ok(Prepared {
                    flags: fl,
                    power: sum,
                    score: if replacing { self.to_score(acc) } else { 0 },
                    spread,
                })
            }
        }
    }

    /// The spread channel's `q` of a map (read from the fast copy the sum
    /// pass made) whose power is `power` and largest sample `top`.
    #[inline(always)]
    fn spread(&self, frame: &[u16], power: u32, top: u16) -> u16 {
        let g = self.config.geometry;
        spread::outside_core_of_peak(
            frame,
            g.j1 as usize,
            g.j2 as usize,
            self.spread_half as usize,
            power,
            top,
        )
    }

    /// The sample sum of `frame`, its flags ([`flags::SATURATED`],
    /// [`flags::DARK`]), the frame to read from then (`copy` once the sum
    /// pass has copied it there) and its largest sample: the first pass of
    /// both kernel sets.
    #[inline(always)]
    fn sum_pass<'c>(&self, frame: &'c [u16], copy: &'c mut FrameCopy) -> (u32, u8, &'c [u16], u16) {
        let (sum, top, frame) = sum_and_peak(frame, copy);
        let mut fl = 0;
        if top >= self.config.full_scale {
            fl |= flags::SATURATED;
        }
        if sum == 0 {
            fl |= flags::DARK;
        }
        (sum, fl, frame, top)
    }
}
