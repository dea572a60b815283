//! The paper kernels' sum pass copies each frame to the stack while it
//! reads it (on the H743 the copy is in DTCM, the frame in AXI SRAM) and
//! the row pass reads the copy. The copy is made only for a frame that
//! starts on a 32-bit word; any other frame is embedded from where it is.
//! Both must give the same map, bit for bit, for every length (odd lengths
//! leave one sample after the last word), with the frame's own sum and
//! flags.

use cvm_core::scorer::Scratch;
use cvm_core::{Config, Geometry, Kernels, Weights};
use cvm_core_tests::{frame_flags, random_map, rng};

/// `words` as `u16` samples (little endian: sample `2i` is the low half of
/// word `i`).
fn samples(words: &mut [u32]) -> &mut [u16] {
    // SAFETY: a `u32` slice is two `u16`s per word, suitably aligned, and
    // every bit pattern is a valid `u16`.
    unsafe { core::slice::from_raw_parts_mut(words.as_mut_ptr().cast::<u16>(), 2 * words.len()) }
}

/// One frame stored twice in word-aligned memory: starting on a word and
/// starting two bytes past one.
struct Placed {
    on: Vec<u32>,
    off: Vec<u32>,
    cells: usize,
}

impl Placed {
    fn new(frame: &[u16]) -> Self {
        let cells = frame.len();
        let mut on = vec![0u32; cells.div_ceil(2) + 1];
        let mut off = on.clone();
        samples(&mut on)[..cells].copy_from_slice(frame);
        samples(&mut off)[1..=cells].copy_from_slice(frame);
        Placed { on, off, cells }
    }

    /// The copy that starts on a word.
    fn on(&self) -> &[u16] {
        // SAFETY: as in `samples`; `cells < 2 * on.len()`.
        unsafe { core::slice::from_raw_parts(self.on.as_ptr().cast::<u16>(), self.cells) }
    }

    /// The copy that starts two bytes past a word.
    fn off(&self) -> &[u16] {
        // SAFETY: as in `samples`; `1 + cells <= 2 * off.len()`.
        unsafe { core::slice::from_raw_parts(self.off.as_ptr().cast::<u16>().add(1), self.cells) }
    }
}

#[test]
fn aligned_and_unaligned_frames_embed_the_same() {
    const FULL_SCALE: u16 = 60000;
    let mut r = rng(77);
    let mut lengths = [0usize; 2];
    for j1 in 1..=16u8 {
        for j2 in [1u8, 2, 3, 5, 8, 9, 15, 16] {
            let cfg = Config {
                geometry: Geometry::new(j1, j2).unwrap(),
                kernels: Kernels::Paper { bmax: 0 },
                weights: Weights::Uniform,
                normalise: true,
                full_scale: FULL_SCALE,
            };
            let scorer = dmap::fixed::scorer(&cfg).unwrap();
            let cells = usize::from(j1) * usize::from(j2);
            for case in 0..4 {
                let mut frame = random_map(&mut r, cells, usize::from(j2));
                match case {
                    // Saturated only in the last sample: after the last
                    // whole word when the length is odd.
                    1 => frame[cells - 1] = FULL_SCALE,
                    // Saturated only in the first.
                    2 => frame[0] = FULL_SCALE,
                    _ => {}
                }
                let placed = Placed::new(&frame);
                let (on, off) = (placed.on(), placed.off());
                assert_eq!(on.as_ptr() as usize % 4, 0);
                assert_eq!(off.as_ptr() as usize % 4, 2);
                let mut scratch = Scratch::new();
                let mut a = vec![0i32; scorer.state_words()];
                let mut b = vec![i32::MIN; scorer.state_words()];
                let pa = scorer
                    .prepare_map(on, &mut a, &mut [], &mut scratch, false)
                    .unwrap();
                let pb = scorer
                    .prepare_map(off, &mut b, &mut [], &mut scratch, false)
                    .unwrap();
                let what = format!("{j1}x{j2} case {case}");
                assert_eq!(a, b, "{what}");
                let sum: u32 = frame.iter().map(|&v| u32::from(v)).sum();
                let want = frame_flags(&frame, FULL_SCALE);
                assert_eq!((pa.flags, pb.flags), (want, want), "{what}");
                assert_eq!((pa.power, pb.power), (sum, sum), "{what}");
                // And the same as a frame in its own allocation.
                let mut c = vec![0i32; scorer.state_words()];
                scorer
                    .prepare_map(&frame, &mut c, &mut [], &mut scratch, false)
                    .unwrap();
                assert_eq!(a, c, "{what}");
                lengths[cells % 2] += 1;
            }
        }
    }
    assert!(lengths.iter().all(|&n| n > 100), "{lengths:?}");
}

/// The sum pass copies a frame that starts on a word (and returns the
/// copy), and hands back any other frame itself; always with the frame's
/// sum and largest sample.
#[test]
fn the_sum_pass_copies_word_aligned_frames() {
    use cvm_core::scorer::{FrameCopy, sum_and_peak};
    let mut r = rng(78);
    for cells in [1usize, 2, 3, 4, 5, 8, 9, 81, 224, 225, 255, 256] {
        for spike in [None, Some(0), Some(cells - 1), Some(cells / 2)] {
            let mut frame = random_map(&mut r, cells, 1);
            // The largest sample first, last, in the middle, or where the
            // random map put it.
            if let Some(k) = spike {
                frame[k] = u16::MAX;
            }
            let placed = Placed::new(&frame);
            let (on, off) = (placed.on(), placed.off());
            let sum: u32 = frame.iter().map(|&v| u32::from(v)).sum();
            let top = frame.iter().copied().max().unwrap();
            let mut copy = FrameCopy::new();
            let (s, t, got) = sum_and_peak(on, &mut copy);
            assert_eq!((s, t, got), (sum, top, on), "{cells} cells, aligned");
            assert_ne!(got.as_ptr(), on.as_ptr(), "{cells} cells: not copied");
            let mut copy = FrameCopy::new();
            let (s, t, got) = sum_and_peak(off, &mut copy);
            assert_eq!((s, t, got), (sum, top, off), "{cells} cells, unaligned");
            assert_eq!(got.as_ptr(), off.as_ptr(), "{cells} cells: copied");
        }
    }
}
