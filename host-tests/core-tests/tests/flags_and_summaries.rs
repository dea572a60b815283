//! The `DARK` and `SATURATED` flags against the frames themselves, and the
//! row summaries (`max`, `argmax`, `defects`, `dark`, `saturated`,
//! `no_data`) against a recomputation from the positions' scores.
//!
//! Flags are defined on the raw frame (docs/method.md §3): a map is dark
//! when its samples sum to zero, saturated when any sample is at or above
//! the configured full scale. The expectations below are taken from the
//! frames, never from the scorer.

use cvm_core::{Config, Geometry, Kernels, Position, RowSummary, Scorer, Weights};
use cvm_core::{flags, tables::box_range};
use cvm_core_tests::{frame_flags, random_map, rng, row_summary_of, run_engine};
use rand::RngExt;

const GEOMETRIES: &[(u8, u8)] = &[(1, 1), (1, 5), (2, 2), (3, 3), (4, 6), (9, 9), (16, 16)];
/// Full scales down to 1, the smallest a configuration takes (0 is
/// refused: `formats.rs`, `a_full_scale_of_zero_is_refused`).
const FULL_SCALES: &[u16] = &[u16::MAX, 60000, 1000, 1];

/// Every kernel family, normalised and raw, at the given full scale.
fn configs(j1: u8, j2: u8, full_scale: u16) -> Vec<Config> {
    let geometry = Geometry::new(j1, j2).unwrap();
    let mut v = Vec::new();
    for normalise in [true, false] {
        for kernels in [
            Kernels::Paper { bmax: 0 },
            Kernels::Square {
                kmax: j1.max(j2) - 1,
            },
        ] {
            v.push(Config {
                geometry,
                kernels,
                weights: Weights::Uniform,
                normalise,
                full_scale,
            });
        }
    }
    v
}

/// Hand-made frames: dark, full scale, one cell at the full scale and one
/// just below it (at every cell, so that every lane of the saturation scan
/// is exercised), a single count, and a few random maps.
fn frames(cells: usize, j2: usize, full_scale: u16, seed: u64) -> Vec<Vec<u16>> {
    let mut v = vec![vec![0; cells], vec![u16::MAX; cells]];
    for k in 0..cells {
        let mut at = vec![3u16; cells];
        at[k] = full_scale;
        v.push(at);
        let mut below = vec![0u16; cells];
        below[k] = full_scale.saturating_sub(1);
        v.push(below);
        let mut one = vec![0u16; cells];
        one[k] = 1;
        v.push(one);
    }
    let mut r = rng(seed);
    for _ in 0..8 {
        v.push(random_map(&mut r, cells, j2));
    }
    v
}

/// Every way a frame is prepared reports the flags its samples call for.
#[test]
fn flags_match_the_frame_for_every_entry_point() {
    let mut checked = [0usize; 4];
    for &(j1, j2) in GEOMETRIES {
        let cells = usize::from(j1) * usize::from(j2);
        for &fs in FULL_SCALES {
            for cfg in configs(j1, j2, fs) {
                let scorer = dmap::fixed::scorer(&cfg).unwrap();
                let mut held = vec![0i32; scorer.state_words()];
                scorer.prepare(&vec![7; cells], &mut held).unwrap();
                let mut scratch = cvm_core::scorer::Scratch::new();
                for frame in frames(cells, usize::from(j2), fs, u64::from(fs) + cells as u64) {
                    let want = frame_flags(&frame, fs);
                    let mut state = vec![0i32; scorer.state_words()];
                    let what = format!("{j1}x{j2} fs={fs} {cfg:?} frame {frame:?}");
                    assert_eq!(scorer.prepare(&frame, &mut state), Ok(want), "{what}");
                    let mut x = vec![0i32; cells];
                    assert_eq!(scorer.normalise(&frame, &mut x), Ok(want), "{what}");
                    let fl = scorer
                        .prepare_map(&frame, &mut held, &mut [], &mut scratch, true)
                        .unwrap()
                        .flags;
                    assert_eq!(fl, want, "replacing: {what}");
                    for (bit, n) in [flags::DARK, flags::SATURATED].iter().zip(&mut checked) {
                        *n += usize::from(want & bit != 0);
                    }
                    checked[2] += usize::from(want == 0);
                    checked[3] += 1;
                }
            }
        }
    }
    // Each outcome occurred many times: the loops above are not vacuous.
    assert!(checked[..3].iter().all(|&n| n > 100), "{checked:?}");
}

/// A dark map, a full-scale map and a map with one cell at the full scale,
/// in a scan: the positions carry the flags, each row counts them and so
/// do the totals.
#[test]
fn engine_reports_dark_and_saturated_positions() {
    let (j1, j2, cols, rows) = (4usize, 5usize, 6usize, 5usize);
    let cells = j1 * j2;
    for fs in [u16::MAX, 2000] {
        for cfg in configs(j1 as u8, j2 as u8, fs) {
            let scorer = dmap::fixed::scorer(&cfg).unwrap();
            let mut r = rng(u64::from(fs));
            let mut scan = Vec::new();
            for i in 0..rows * cols {
                let f = match i % 7 {
                    0 => vec![0; cells],
                    3 => vec![u16::MAX; cells],
                    5 => {
                        let mut f: Vec<u16> = (0..cells).map(|_| r.random_range(0..100)).collect();
                        f[i % cells] = fs;
                        f
                    }
                    _ => random_map(&mut r, cells, j2),
                };
                scan.push(f);
            }
            let frames: Vec<_> = scan
                .iter()
                .enumerate()
                .map(|(i, f)| {
                    let pos = Position {
                        row: (i / cols) as u32,
                        col: (i % cols) as u32,
                    };
                    (pos, Some(f.clone()))
                })
                .collect();
            let (out, totals) = run_engine(&scorer, cols, 1, &frames);
            assert_eq!(out.len(), rows);
            let (mut dark, mut sat) = (0, 0);
            for (row, (summary, scores)) in out.iter().enumerate() {
                let (mut rd, mut rs) = (0, 0);
                for (col, s) in scores.iter().enumerate() {
                    let want = frame_flags(&scan[row * cols + col], fs);
                    // The map's own flags; the decisions are checked elsewhere.
                    let own = s.flags & !(flags::CLIPPED | flags::DEFECT);
                    assert_eq!(own, want, "{cfg:?} ({row}, {col})");
                    rd += u32::from(want & flags::DARK != 0);
                    rs += u32::from(want & flags::SATURATED != 0);
                }
                assert_eq!(
                    (summary.dark, summary.saturated),
                    (rd, rs),
                    "{cfg:?} row {row}"
                );
                dark += rd;
                sat += rs;
            }
            assert!(dark >= 4 && sat >= 8, "{dark} {sat}");
            assert_eq!((totals.dark, totals.saturated), (dark, sat), "{cfg:?}");
        }
    }
}

fn paper(j1: u8, j2: u8) -> Scorer {
    Scorer::new(&Config::paper(Geometry::new(j1, j2).unwrap())).unwrap()
}

fn at(row: u32, col: u32) -> Position {
    Position { row, col }
}

/// One row `A B A B A` of 1x3 maps: the ends see `d(A, B)` (their missing
/// neighbour is the map itself), the inner positions `d(A, A) = d(B, B) = 0`
/// (Eq. 1). So the maximum is reached twice, at columns 0 and 4, and the
/// summary names the first. With the threshold at that maximum both ends
/// are defects.
#[test]
fn argmax_is_the_first_column_reaching_the_maximum() {
    let scorer = paper(1, 3);
    let (a, b) = (vec![9u16, 0, 0], vec![0u16, 0, 9]);
    let d_ab = {
        let (mut sa, mut sb) = (vec![0; 3], vec![0; 3]);
        scorer.prepare(&a, &mut sa).unwrap();
        scorer.prepare(&b, &mut sb).unwrap();
        scorer.distance(&sa, &sb)
    };
    assert!(d_ab > 0);
    // Two rows, so that one row is emitted when the next completes and the
    // last one by `finish`.
    let frames: Vec<_> = (0..10)
        .map(|i| {
            (
                at(i / 5, i % 5),
                Some(if (i % 5) % 2 == 0 { &a } else { &b }.clone()),
            )
        })
        .collect();
    let (out, _) = run_engine(&scorer, 5, d_ab, &frames);
    assert_eq!(out.len(), 2);
    for (row, (summary, scores)) in out.iter().enumerate() {
        let mags: Vec<u32> = scores.iter().map(|s| s.mag).collect();
        assert_eq!(mags, [d_ab, 0, 0, 0, d_ab], "row {row}");
        let want = RowSummary {
            row: row as u32,
            max: d_ab,
            argmax: Some(0),
            // Every map holds the same power: no contrast anywhere.
            pmax: 0,
            pargmax: Some(0),
            defects: 2,
            no_data: 0,
            dark: 0,
            saturated: 0,
        };
        assert_eq!(*summary, want);
    }
}

/// A row whose only positions with data score 0 still names the first of
/// them; a row without any data has no argmax.
#[test]
fn argmax_of_zero_rows_and_empty_rows() {
    let scorer = paper(2, 2);
    let m = vec![5u16, 1, 1, 5];
    let frames = vec![
        // Row 0: column 0 missing, columns 1 and 2 hold the same map.
        (at(0, 0), None),
        (at(0, 1), Some(m.clone())),
        (at(0, 2), Some(m.clone())),
        // Row 1: nothing at all.
        (at(1, 0), None),
        (at(1, 1), None),
        (at(1, 2), None),
    ];
    let (out, totals) = run_engine(&scorer, 3, 0, &frames);
    assert_eq!(out.len(), 2);
    let (s0, s1) = (out[0].0, out[1].0);
    assert_eq!(
        s0,
        RowSummary {
            row: 0,
            max: 0,
            argmax: Some(1),
            pmax: 0,
            pargmax: Some(1),
            defects: 2,
            no_data: 1,
            dark: 0,
            saturated: 0
        }
    );
    assert_eq!(
        s1,
        RowSummary {
            row: 1,
            max: 0,
            argmax: None,
            pmax: 0,
            pargmax: None,
            defects: 0,
            no_data: 3,
            dark: 0,
            saturated: 0
        }
    );
    assert_eq!(totals.defects, 2);
    assert_eq!(totals.missing, 4);
}

/// Random scans with gaps, ties (repeated maps), dark and saturated maps:
/// every emitted summary equals the recomputation from its scores, and the
/// totals add the rows up.
#[test]
fn summaries_equal_their_recomputation() {
    let mut r = rng(77);
    let mut ties = 0;
    for case in 0..60 {
        let (j1, j2) = [(1, 1), (2, 3), (3, 3), (5, 4)][case % 4];
        let cells = usize::from(j1) * usize::from(j2);
        let (rows, cols) = (r.random_range(1..6usize), r.random_range(1..9usize));
        let fs = [u16::MAX, 3000][case % 2];
        let cfg = Config {
            full_scale: fs,
            ..Config::paper(Geometry::new(j1, j2).unwrap())
        };
        let scorer = dmap::fixed::scorer(&cfg).unwrap();
        // A few distinct maps reused, so that equal magnitudes are common.
        let pool: Vec<Vec<u16>> = (0..3)
            .map(|k| match k {
                0 => vec![0; cells],
                _ => random_map(&mut r, cells, usize::from(j2)),
            })
            .collect();
        let mut frames = Vec::new();
        for i in 0..rows * cols {
            let pos = at((i / cols) as u32, (i % cols) as u32);
            match r.random_range(0..6) {
                0 => {}                        // a gap
                1 => frames.push((pos, None)), // an explicit overrun
                _ => frames.push((pos, Some(pool[r.random_range(0..3)].clone()))),
            }
        }
        let (probe, _) = run_engine(&scorer, cols, u32::MAX, &frames);
        let mags: Vec<u32> = probe
            .iter()
            .flat_map(|(_, s)| s.iter().map(|s| s.mag))
            .collect();
        let threshold = mags.get(mags.len() / 2).copied().unwrap_or(1);
        let (out, totals) = run_engine(&scorer, cols, threshold, &frames);
        let mut defects = 0;
        for (k, (summary, scores)) in out.iter().enumerate() {
            assert_eq!(scores.len(), cols);
            let want = row_summary_of(k as u32, scores, threshold);
            assert_eq!(*summary, want, "case {case}: {scores:?}");
            defects += want.defects;
            let at_max = scores
                .iter()
                .filter(|s| s.flags & flags::NO_DATA == 0 && s.mag == want.max)
                .count();
            ties += usize::from(at_max > 1);
        }
        assert_eq!(totals.defects, defects);
    }
    assert!(ties > 20, "too few rows with a tied maximum: {ties}");
}

/// The core's box bounds (0-based) are the cells within distance `h` of
/// the centre, found by testing every cell.
#[test]
fn core_box_range_is_the_set_of_cells_within_h() {
    for n in 1..=16usize {
        for j in 0..n {
            for h in 0..=17usize {
                let cells: Vec<usize> = (0..n).filter(|&i| i.abs_diff(j) <= h).collect();
                assert_eq!(
                    box_range(j, h, n),
                    (cells[0], *cells.last().unwrap()),
                    "j={j} h={h} n={n}"
                );
            }
        }
    }
}
