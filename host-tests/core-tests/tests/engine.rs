//! The streaming engine against batch scoring of the whole scan
//! (`dmap score --distance cvm-fixed`), and its handling of damaged input.

use cvm_core::{Position, PositionScore, Scorer, flags};
use cvm_core_tests::{
    contrast_f64, decide, frame_flags, power_magnitude_ref, random_scan, rng, row_summary_with,
    run_engine, run_engine_with, variants,
};
use dmap::fixed::score_scan;
use proptest::prelude::*;

fn clean_frames(
    rows: usize,
    cols: usize,
    n: usize,
    data: &[u16],
) -> Vec<(Position, Option<Vec<u16>>)> {
    cvm_core_tests::scan_frames(data, n, rows, cols, None)
}

fn flatten(rows: &[(cvm_core::RowSummary, Vec<PositionScore>)]) -> Vec<PositionScore> {
    rows.iter().flat_map(|(_, s)| s.iter().copied()).collect()
}

/// Batch scoring with positions missing: a missing neighbour is replaced by
/// the map itself (the border rule), written directly from Eq. 1.
fn batch_with_gaps(
    scorer: &Scorer,
    rows: usize,
    cols: usize,
    data: &[u16],
    present: &[bool],
) -> Vec<PositionScore> {
    let n = scorer.cells();
    let w = scorer.state_words();
    let mut st = vec![0i32; rows * cols * w];
    let mut fl = vec![0u8; rows * cols];
    for i in 0..rows * cols {
        fl[i] = scorer
            .prepare(&data[i * n..(i + 1) * n], &mut st[i * w..(i + 1) * w])
            .unwrap();
    }
    let s = |i: usize| &st[i * w..(i + 1) * w];
    let pw = |i: usize| {
        data[i * n..(i + 1) * n]
            .iter()
            .map(|&a| u64::from(a))
            .sum::<u64>()
    };
    let at = |r: isize, c: isize| -> Option<usize> {
        if r < 0 || c < 0 || r >= rows as isize || c >= cols as isize {
            return None;
        }
        let i = r as usize * cols + c as usize;
        present[i].then_some(i)
    };
    (0..rows * cols)
        .map(|i| {
            if !present[i] {
                return PositionScore {
                    flags: flags::NO_DATA,
                    ..Default::default()
                };
            }
            let (r, c) = ((i / cols) as isize, (i % cols) as isize);
            let l = at(r, c - 1).unwrap_or(i);
            let rr = at(r, c + 1).unwrap_or(i);
            let u = at(r - 1, c).unwrap_or(i);
            let d = at(r + 1, c).unwrap_or(i);
            let g0 = if l == rr {
                0
            } else {
                scorer.distance(s(l), s(rr))
            };
            let g1 = if u == d {
                0
            } else {
                scorer.distance(s(u), s(d))
            };
            let p0 = if l == rr {
                0
            } else {
                contrast_f64(pw(l), pw(rr))
            };
            let p1 = if u == d {
                0
            } else {
                contrast_f64(pw(u), pw(d))
            };
            PositionScore {
                g0,
                g1,
                mag: cvm_core::magnitude(g0, g1),
                p0,
                p1,
                pmag: power_magnitude_ref(p0, p1),
                flags: fl[i],
                ..Default::default()
            }
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Bit-identical to batch scoring for complete scans, including 1x1,
    /// 1xN, Nx1 and 2x2 scans, for every scoring variant.
    #[test]
    fn engine_equals_batch(rows in 1usize..7, cols in 1usize..9, g in 0usize..5, seed in any::<u64>()) {
        let (j1, j2) = [(1, 1), (2, 2), (3, 5), (9, 9), (15, 15)][g];
        let n = j1 * j2;
        let mut r = rng(seed);
        let data = random_scan(&mut r, rows, cols, j1, j2);
        for args in variants(j1, j2) {
            let scorer = args.scorer(j1, j2).unwrap();
            let mut batch = score_scan(&scorer, rows, cols, &data);
            let thr = batch.iter().map(|s| s.mag).max().unwrap_or(0) / 2 + 1;
            // A power threshold that splits the positions too.
            let pthr = u32::from(batch.iter().map(|s| s.pmag).max().unwrap_or(0)) * 2 / 3 + 1;
            decide(&mut batch, thr, pthr);
            let (out, totals) =
                run_engine_with(&scorer, cols, thr, pthr, &clean_frames(rows, cols, n, &data));
            prop_assert_eq!(out.len(), rows);
            for (k, (sum, _)) in out.iter().enumerate() {
                prop_assert_eq!(sum.row as usize, k);
            }
            prop_assert_eq!(&flatten(&out), &batch);
            // Flags from the frames, summaries recomputed from the scores.
            for (i, s) in batch.iter().enumerate() {
                let want = frame_flags(&data[i * n..(i + 1) * n], u16::MAX);
                prop_assert_eq!(s.flags & (flags::DARK | flags::SATURATED), want);
            }
            for (k, (sum, _)) in out.iter().enumerate() {
                let want = row_summary_with(k as u32, &batch[k * cols..(k + 1) * cols], thr, pthr);
                prop_assert_eq!(*sum, want);
            }
            prop_assert_eq!(totals.frames as usize, rows * cols);
            prop_assert_eq!(totals.missing, 0);
            let defects = batch
                .iter()
                .filter(|s| s.mag >= thr || u32::from(s.pmag) >= pthr)
                .count();
            prop_assert_eq!(totals.defects as usize, defects);
            let dark = batch.iter().filter(|s| s.flags & flags::DARK != 0).count();
            prop_assert_eq!(totals.dark as usize, dark);
            let sat = batch.iter().filter(|s| s.flags & flags::SATURATED != 0).count();
            prop_assert_eq!(totals.saturated as usize, sat);
        }
    }

    /// Missing frames (gaps, short rows, whole rows, explicit overruns)
    /// are reported as no-data positions and counted; every other position
    /// is scored at its own place with the border rule around the gaps.
    #[test]
    fn gaps_do_not_shift_positions(rows in 1usize..7, cols in 1usize..9, seed in any::<u64>(), holes in prop::collection::vec(prop::bool::weighted(0.3), 48), forced in any::<prop::sample::Index>()) {
        let (j1, j2) = (5, 4);
        let n = j1 * j2;
        let mut r = rng(seed);
        let data = random_scan(&mut r, rows, cols, j1, j2);
        let scorer = dmap::options::ScoringArgs::default().scorer(j1, j2).unwrap();
        // One hole per position drawn independently (a scan has at most 48
        // positions), plus one forced hole: every case has a gap.
        let forced = forced.index(rows * cols);
        let present: Vec<bool> = (0..rows * cols).map(|i| !holes[i] && i != forced).collect();
        let mut frames = Vec::new();
        for (i, f) in clean_frames(rows, cols, n, &data).into_iter().enumerate() {
            if present[i] {
                frames.push(f);
            } else if i.is_multiple_of(3) {
                // An explicit "no frame here" (detector overrun).
                frames.push((f.0, None));
            }
        }
        // Power threshold 0.05: random maps give contrasts on both sides of it.
        let pthr = cvm_core::power::threshold_from_units(0.05);
        let (out, totals) = run_engine_with(&scorer, cols, 1, pthr, &frames);
        let mut want = batch_with_gaps(&scorer, rows, cols, &data, &present);
        decide(&mut want, 1, pthr);
        // Trailing missing rows are never seen by the engine: it cannot
        // know the scan had them.
        let last_row = (0..rows * cols).rev().find(|&i| present[i] || i.is_multiple_of(3)).map_or(0, |i| i / cols + 1);
        prop_assert_eq!(out.len(), last_row);
        prop_assert_eq!(&flatten(&out)[..], &want[..last_row * cols]);
        for (k, (sum, _)) in out.iter().enumerate() {
            prop_assert_eq!(*sum, row_summary_with(k as u32, &want[k * cols..(k + 1) * cols], 1, pthr));
        }
        let missing = want[..last_row * cols].iter().filter(|s| s.flags & flags::NO_DATA != 0).count();
        prop_assert_eq!(totals.missing as usize, missing);
        prop_assert_eq!(totals.frames as usize + missing, last_row * cols);
    }
}

/// Repeated frames, repeated rows, frames from the past and frames beyond
/// the last column are counted and change nothing else.
#[test]
fn repeats_and_extras_are_counted_not_placed() {
    let (rows, cols, j1, j2) = (5, 6, 9, 9);
    let n = j1 * j2;
    let mut r = rng(11);
    let data = random_scan(&mut r, rows, cols, j1, j2);
    let scorer = dmap::options::ScoringArgs::default()
        .scorer(j1, j2)
        .unwrap();
    let clean = clean_frames(rows, cols, n, &data);
    let (want, _) = run_engine(&scorer, cols, 1000, &clean);

    let mut damaged = Vec::new();
    let junk = vec![123u16; n];
    for (i, f) in clean.iter().enumerate() {
        damaged.push(f.clone());
        if i == 7 {
            damaged.push(f.clone()); // the same frame twice
        }
        if i == 2 * cols + 2 {
            // A stale frame from the row before, then one beyond the last column.
            damaged.push((Position { row: 1, col: 0 }, Some(junk.clone())));
            damaged.push((
                Position {
                    row: 2,
                    col: cols as u32,
                },
                Some(junk.clone()),
            ));
        }
        if i == 4 * cols - 1 {
            // Row 3 repeated in full after it ended.
            for c in 0..cols {
                damaged.push((
                    Position {
                        row: 3,
                        col: c as u32,
                    },
                    Some(junk.clone()),
                ));
            }
        }
    }
    let (got, totals) = run_engine(&scorer, cols, 1000, &damaged);
    assert_eq!(flatten(&got), flatten(&want));
    assert_eq!(totals.rejected, 1 + 1 + cols as u32);
    assert_eq!(totals.extra, 1);
    assert_eq!(totals.frames as usize, rows * cols);
}

/// A frame of the wrong length is counted as bad and its position reported
/// without data; a frame implausibly far ahead is rejected.
#[test]
fn bad_frames_and_wild_positions() {
    let (j1, j2) = (3, 3);
    let scorer = dmap::options::ScoringArgs::default()
        .scorer(j1, j2)
        .unwrap();
    let good = vec![10u16; 9];
    let frames = vec![
        (Position { row: 0, col: 0 }, Some(good.clone())),
        (Position { row: 0, col: 1 }, Some(vec![1u16; 5])),
        (Position { row: 0, col: 2 }, Some(good.clone())),
        (
            Position {
                row: u32::MAX,
                col: 0,
            },
            Some(good.clone()),
        ),
    ];
    let (out, totals) = run_engine(&scorer, 3, 1, &frames);
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].1[1].flags, flags::NO_DATA);
    assert_eq!(totals.bad, 1);
    assert_eq!(totals.missing, 1);
    assert_eq!(totals.rejected, 1);
    assert_eq!(totals.frames, 2);
}

/// After `finish` the engine starts the next scan from row 0 with nothing
/// carried over.
#[test]
fn consecutive_scans_are_independent() {
    let (rows, cols, j1, j2) = (4, 5, 4, 4);
    let n = j1 * j2;
    let mut r = rng(5);
    let d1 = random_scan(&mut r, rows, cols, j1, j2);
    let d2 = random_scan(&mut r, rows, cols, j1, j2);
    let scorer = dmap::options::ScoringArgs::default()
        .scorer(j1, j2)
        .unwrap();
    let words = cvm_core::stream::row_words(cols, n, 1);
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let mut engine = cvm_core::Engine::<8>::new(&scorer, cols as u32, 1, &mut a, &mut b).unwrap();
    for data in [&d1, &d2] {
        let mut rows_out = Vec::new();
        let mut out = |v: &cvm_core::RowView| rows_out.push((v.summary, v.scores.to_vec()));
        for (pos, f) in clean_frames(rows, cols, n, data) {
            engine.push(pos, &f.unwrap(), &mut out);
        }
        let t = engine.finish(&mut out);
        let mut want = score_scan(&scorer, rows, cols, data);
        decide(&mut want, 1, cvm_core::power::POWER_OFF);
        assert_eq!(flatten(&rows_out), want);
        assert_eq!(t.frames as usize, rows * cols);
    }
}

#[test]
fn window_size_table() {
    // Two rows of J1*J2 i32 words per column plus per-column bookkeeping:
    // two flag bytes, two u32 powers, two positions' results.
    assert_eq!(cvm_core::stream::row_words(300, 15, 15), 300 * 225);
    let w = cvm_core::stream::window_bytes(300, 15, 15);
    assert_eq!(
        w,
        2 * 300 * 225 * 4 + 300 * (2 + 2 * 4 + 2 * 2 + 2 * std::mem::size_of::<PositionScore>())
    );
}

/// Set-up is refused without columns, beyond the engine's capacity and
/// with a row buffer one word short; a good set-up reports its columns and
/// threshold.
#[test]
fn engine_set_up_is_checked() {
    use cvm_core::stream::{EngineError, row_words};
    let scorer = dmap::options::ScoringArgs::default().scorer(3, 3).unwrap();
    // Four columns of 3x3 maps: 36 words per row buffer.
    let words = row_words(4, 3, 3);
    assert_eq!(words, 36);
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let (mut short, mut c) = (vec![0i32; words - 1], vec![0i32; words]);
    let err = |r: Result<cvm_core::Engine<'_, 4>, EngineError>| r.err();
    assert_eq!(
        err(cvm_core::Engine::new(&scorer, 0, 1, &mut a, &mut b)),
        Some(EngineError::Columns)
    );
    assert_eq!(
        err(cvm_core::Engine::new(&scorer, 5, 1, &mut a, &mut b)),
        Some(EngineError::Columns)
    );
    assert_eq!(
        err(cvm_core::Engine::new(&scorer, 4, 1, &mut short, &mut c)),
        Some(EngineError::Buffer)
    );
    assert_eq!(
        err(cvm_core::Engine::new(&scorer, 4, 1, &mut c, &mut short)),
        Some(EngineError::Buffer)
    );
    // What a board prints when it refuses its buffers.
    assert_eq!(
        EngineError::Columns.to_string(),
        "no columns, or more than the engine holds"
    );
    assert_eq!(
        EngineError::Buffer.to_string(),
        "a row buffer or the near buffer is too short for the maps"
    );
    // The near buffer: empty (none) or three 3x3 maps, 27 words.
    assert_eq!(cvm_core::stream::near_words(scorer.config()), 27);
    let mut near = vec![0i32; 27];
    assert_eq!(
        err(cvm_core::Engine::with_near(
            &scorer,
            4,
            1,
            &mut a,
            &mut b,
            &mut near[..26]
        )),
        Some(EngineError::Buffer)
    );
    assert!(cvm_core::Engine::<4>::with_near(&scorer, 4, 1, &mut a, &mut b, &mut near).is_ok());
    assert!(cvm_core::Engine::<4>::with_near(&scorer, 4, 1, &mut a, &mut b, &mut []).is_ok());
    let mut e = cvm_core::Engine::<4>::new(&scorer, 4, 77, &mut a, &mut b).unwrap();
    assert_eq!((e.cols(), e.threshold()), (4, 77));
    assert_eq!(e.totals(), &cvm_core::Totals::default());
    assert_eq!(
        e.power_threshold(),
        cvm_core::power::POWER_OFF,
        "off by default"
    );
    e.set_power_threshold(1234);
    assert_eq!(e.power_threshold(), 1234);
}

/// A frame `MAX_ROW_JUMP` rows beyond the next expected row is placed,
/// the rows in between reported without data; one row further is rejected.
#[test]
fn row_jump_limit_is_inclusive() {
    use cvm_core::stream::MAX_ROW_JUMP;
    let scorer = dmap::options::ScoringArgs::default().scorer(2, 2).unwrap();
    let map = vec![1u16, 2, 3, 4];
    let at = |row: u32| (Position { row, col: 0 }, Some(map.clone()));
    // After row 0 (one column) the next expected row is 1.
    let (out, totals) = run_engine(&scorer, 1, 1, &[at(0), at(1 + MAX_ROW_JUMP)]);
    assert_eq!(out.len() as u32, MAX_ROW_JUMP + 2);
    assert_eq!((totals.missing, totals.rejected), (MAX_ROW_JUMP, 0));
    let (out, totals) = run_engine(&scorer, 1, 1, &[at(0), at(2 + MAX_ROW_JUMP)]);
    assert_eq!(out.len(), 1);
    assert_eq!((totals.missing, totals.rejected), (0, 1));
}

/// Told the row count, the engine puts out nothing of the scan's last two
/// rows before it is closed: after the last beam both are final and
/// unsent, and they are the rows the engine put out without the count.
#[test]
fn last_two_rows_wait_for_the_end_when_the_row_count_is_known() {
    let mut r = rng(41);
    for &(rows, cols, j) in &[(5usize, 7usize, 3usize), (2, 4, 4), (1, 3, 3), (3, 1, 3)] {
        let scorer = dmap::options::ScoringArgs::default().scorer(j, j).unwrap();
        let data = random_scan(&mut r, rows, cols, j, j);
        let frames = clean_frames(rows, cols, j * j, &data);
        let (want, _) = run_engine(&scorer, cols, scorer.threshold_from_units(0.02), &frames);
        let words = cvm_core::stream::row_words_for(cols, scorer.config());
        let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
        let mut engine = Box::new(
            cvm_core::Engine::<256>::new(
                &scorer,
                cols as u32,
                scorer.threshold_from_units(0.02),
                &mut a,
                &mut b,
            )
            .unwrap(),
        );
        engine.set_rows(rows as u32);
        let mut out = Vec::new();
        for (pos, f) in &frames {
            engine.push(*pos, f.as_deref().unwrap(), &mut |v| {
                out.push(v.summary.row)
            });
        }
        let early = rows.saturating_sub(2) as u32;
        assert_eq!(out, (0..early).collect::<Vec<_>>(), "{rows}x{cols}");
        // Nothing is left to compute after the last beam: `unsent` shows
        // the final rows even before `close`.
        let mut unsent = Vec::new();
        engine.unsent(&mut |v| unsent.push((v.summary, v.scores.to_vec())));
        assert_eq!(unsent.len(), rows.min(2), "{rows}x{cols}");
        assert!(unsent[..] == want[early as usize..], "{rows}x{cols}");
        let t = engine.finish(&mut |v| out.push(v.summary.row));
        assert_eq!(t.rows as usize, rows);
        assert_eq!(out, (0..rows as u32).collect::<Vec<_>>());
    }
}

/// Beams of rows past the row count given are still scored and put out
/// (the last counted row keeping its border-rule decisions), every
/// position once and in order.
#[test]
fn rows_past_the_count_given_are_put_out_in_order() {
    let mut r = rng(42);
    let (rows, cols, j) = (5usize, 6usize, 3usize);
    let scorer = dmap::options::ScoringArgs::default().scorer(j, j).unwrap();
    let data = random_scan(&mut r, rows, cols, j, j);
    let frames = clean_frames(rows, cols, j * j, &data);
    let words = cvm_core::stream::row_words_for(cols, scorer.config());
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let thr = scorer.threshold_from_units(0.02);
    let mut engine =
        Box::new(cvm_core::Engine::<256>::new(&scorer, cols as u32, thr, &mut a, &mut b).unwrap());
    engine.set_rows(3);
    let mut out = Vec::new();
    for (pos, f) in &frames {
        engine.push(*pos, f.as_deref().unwrap(), &mut |v| {
            out.push((v.summary.row, v.scores.len()))
        });
    }
    let t = engine.finish(&mut |v| out.push((v.summary.row, v.scores.len())));
    let want: Vec<_> = (0..rows as u32).map(|r| (r, cols)).collect();
    assert_eq!(out, want);
    assert_eq!((t.rows, t.frames, t.missing), (5, 30, 0));
}
