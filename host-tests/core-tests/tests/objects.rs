//! The streaming object labeller against a whole-image reference: 8-connected
//! components found by flood fill over the complete defect mask, with their
//! statistics recomputed from the definitions in `cvm_core::objects`.

use cvm_core::objects::{MAX_OBJECTS, Object, Objects};
use cvm_core::{PositionScore, RowSummary, RowView, flags};
use cvm_core_tests::rng;
use proptest::prelude::*;

/// A scan's scores: `rows x cols`, defect flags and strengths set.
struct Grid {
    rows: usize,
    cols: usize,
    s: Vec<PositionScore>,
}

impl Grid {
    fn at(&self, r: usize, c: usize) -> &PositionScore {
        &self.s[r * self.cols + c]
    }

    /// Feeds the rows to a labeller; returns the objects in the order they
    /// were reported and the labeller's counts.
    fn stream(&self) -> (Vec<Object>, u32, u32) {
        let mut lab = Objects::new();
        let mut got = Vec::new();
        for r in 0..self.rows {
            let view = RowView {
                summary: RowSummary {
                    row: r as u32,
                    ..RowSummary::default()
                },
                scores: &self.s[r * self.cols..(r + 1) * self.cols],
                threshold: 1,
                power_threshold: 1,
            };
            lab.push_row(&view, &mut |o| got.push(*o));
        }
        // Before the end: the objects the rows closed, the positions left out.
        let (reported, unobjected) = (lab.reported(), lab.unobjected());
        assert_eq!(reported as usize, got.len());
        let mut totals = cvm_core::Totals::default();
        lab.finish_with(&mut |o| got.push(*o), &mut totals);
        assert_eq!(totals.objects as usize, got.len());
        // Left-out positions are counted when their row is taken in.
        assert_eq!(unobjected, totals.unobjected);
        // A finished labeller starts again from nothing.
        assert_eq!((lab.reported(), lab.unobjected()), (0, 0));
        (got, totals.objects, totals.unobjected)
    }
}

/// A random grid: blobs of defects (random walks) on a clean background,
/// strengths from 1 to 40 000 000, either channel.
fn random_grid(seed: u64, rows: usize, cols: usize, blobs: usize) -> Grid {
    let mut r = rng(seed);
    let mut s = vec![PositionScore::default(); rows * cols];
    for _ in 0..blobs {
        let (mut y, mut x) = (r.random_range(0..rows), r.random_range(0..cols));
        for _ in 0..r.random_range(1..12) {
            let p = &mut s[y * cols + x];
            p.flags |= [flags::CVM_DEFECT, flags::POWER_DEFECT, flags::SPREAD_DEFECT]
                [r.random_range(0..3)];
            // Ties on purpose: a few strength levels.
            p.strength = [65_536u32, 70_000, 1, 40_000_000][r.random_range(0..4)];
            p.mag = r.random_range(0..1000);
            p.pmag = r.random_range(0..46_341);
            p.smag = r.random_range(0..92_681);
            y = (y as i64 + r.random_range(-1i64..=1)).clamp(0, rows as i64 - 1) as usize;
            x = (x as i64 + r.random_range(-1i64..=1)).clamp(0, cols as i64 - 1) as usize;
        }
    }
    Grid { rows, cols, s }
}

/// The reference objects: flood fill, then each statistic from its
/// definition. Returned in raster order of their first position.
fn reference(g: &Grid) -> Vec<Object> {
    let mut seen = vec![false; g.rows * g.cols];
    let mut out = Vec::new();
    for r0 in 0..g.rows {
        for c0 in 0..g.cols {
            if seen[r0 * g.cols + c0] || !g.at(r0, c0).is_defect() {
                continue;
            }
            let mut comp = Vec::new();
            let mut stack = vec![(r0, c0)];
            seen[r0 * g.cols + c0] = true;
            while let Some((r, c)) = stack.pop() {
                comp.push((r, c));
                for dr in -1isize..=1 {
                    for dc in -1isize..=1 {
                        let (y, x) = (r as isize + dr, c as isize + dc);
                        if y < 0 || x < 0 || y >= g.rows as isize || x >= g.cols as isize {
                            continue;
                        }
                        let (y, x) = (y as usize, x as usize);
                        if !seen[y * g.cols + x] && g.at(y, x).is_defect() {
                            seen[y * g.cols + x] = true;
                            stack.push((y, x));
                        }
                    }
                }
            }
            comp.sort();
            // Peak: the largest strength, the first in raster order.
            let &(pr, pc) = comp
                .iter()
                .min_by_key(|&&(r, c)| (std::cmp::Reverse(g.at(r, c).strength), r, c))
                .unwrap();
            let weight = |r: usize, c: usize| -> u128 {
                u128::from((g.at(r, c).strength >> 8).clamp(1, 1 << 24))
            };
            let w: u128 = comp.iter().map(|&(r, c)| weight(r, c)).sum();
            let wr: u128 = comp.iter().map(|&(r, c)| weight(r, c) * r as u128).sum();
            let wc: u128 = comp.iter().map(|&(r, c)| weight(r, c) * c as u128).sum();
            let p = g.at(pr, pc);
            out.push(Object {
                id: 0,
                row0: comp.iter().map(|p| p.0).min().unwrap() as u32,
                row1: comp.iter().map(|p| p.0).max().unwrap() as u32,
                col0: comp.iter().map(|p| p.1).min().unwrap() as u32,
                col1: comp.iter().map(|p| p.1).max().unwrap() as u32,
                area: comp.len() as u32,
                peak: p.strength,
                peak_row: pr as u32,
                peak_col: pc as u32,
                peak_mag: p.mag,
                peak_power: p.pmag,
                peak_spread: p.smag,
                channels: comp
                    .iter()
                    .fold(0, |a, &(r, c)| a | (g.at(r, c).flags & flags::DEFECT)),
                centroid_row_q8: (wr * 256 / w) as u64,
                centroid_col_q8: (wc * 256 / w) as u64,
            });
        }
    }
    out
}

/// Reported objects equal the reference components (ids aside), are
/// reported when the row after their last one ends (in increasing id), and
/// ids increase with the raster order of the components' first positions.
fn check(g: &Grid) {
    // In raster order of each component's first position.
    let want = reference(g);
    let (got, n, unobjected) = g.stream();
    assert_eq!(unobjected, 0);
    assert_eq!(n as usize, want.len());
    // Reporting order: by last row, then id.
    for pair in got.windows(2) {
        assert!(
            (pair[0].row1, pair[0].id) < (pair[1].row1, pair[1].id),
            "{pair:?}"
        );
    }
    let mut by_first = got.clone();
    by_first.sort_by_key(|o| o.id);
    let strip = |o: &Object| Object { id: 0, ..*o };
    let got_sorted: Vec<Object> = by_first.iter().map(strip).collect();
    // The reference lists components by first position; so must the ids.
    assert_eq!(got_sorted, want);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn streaming_objects_equal_flood_fill(seed in any::<u64>(), rows in 1usize..14, cols in 1usize..14, blobs in 0usize..8) {
        check(&random_grid(seed, rows, cols, blobs));
    }
}

fn mark(g: &mut Grid, cells: &[(usize, usize)]) {
    for &(r, c) in cells {
        let p = &mut g.s[r * g.cols + c];
        p.flags |= flags::CVM_DEFECT;
        p.strength = 65_536 + (r * 10 + c) as u32;
    }
}

fn empty(rows: usize, cols: usize) -> Grid {
    Grid {
        rows,
        cols,
        s: vec![PositionScore::default(); rows * cols],
    }
}

/// A U opens as two objects that merge at its bottom; a diagonal step
/// connects; a gap of one column does not; an object closes with the first
/// row that does not touch it.
#[test]
fn merges_diagonals_and_gaps() {
    let mut g = empty(6, 9);
    // U: columns 0 and 2 in rows 0-2, joined at row 3.
    mark(
        &mut g,
        &[
            (0, 0),
            (1, 0),
            (2, 0),
            (0, 2),
            (1, 2),
            (2, 2),
            (3, 0),
            (3, 1),
            (3, 2),
        ],
    );
    // Diagonal chain, then a separate cell one column away from its end.
    mark(&mut g, &[(0, 5), (1, 6), (2, 7), (2, 5)]);
    mark(&mut g, &[(5, 8)]);
    check(&g);
    let (got, _, _) = g.stream();
    assert_eq!(got.len(), 3);
    // The chain (and the cell at (2, 5), diagonal to (1, 6)) closes after row 2, the U after 3.
    assert_eq!(
        (
            got[0].row0,
            got[0].row1,
            got[0].col0,
            got[0].col1,
            got[0].area
        ),
        (0, 2, 5, 7, 4)
    );
    assert_eq!(
        (
            got[1].row0,
            got[1].row1,
            got[1].col0,
            got[1].col1,
            got[1].area
        ),
        (0, 3, 0, 2, 9)
    );
    // The U opened twice (ids 0 and 1); the merged object keeps 0.
    assert_eq!(got[1].id, 0);
    assert_eq!((got[2].row0, got[2].col0, got[2].area), (5, 8, 1));
    // Its peak: the strongest cell, (3, 2) by construction.
    assert_eq!((got[1].peak_row, got[1].peak_col), (3, 2));
}

/// More runs in a row than the table holds: the rest are counted, never
/// given to a wrong object.
#[test]
fn overflow_is_counted() {
    let cols = 2 * MAX_OBJECTS + 20;
    let mut g = empty(1, cols);
    let cells: Vec<(usize, usize)> = (0..cols).step_by(2).map(|c| (0, c)).collect();
    mark(&mut g, &cells);
    let (got, n, unobjected) = g.stream();
    assert_eq!(n as usize, MAX_OBJECTS);
    assert_eq!(got.len(), MAX_OBJECTS);
    assert_eq!(unobjected as usize, cells.len() - MAX_OBJECTS);
    assert!(got.iter().all(|o| o.area == 1));
}

/// A row with more runs than the run table holds: the first `MAX_OBJECTS`
/// runs join the object of the row above, the rest (which touch nothing
/// above) find the run table full: their positions are counted and no
/// object is opened for them (it would be reported empty).
#[test]
fn run_table_overflow_is_counted() {
    let runs = MAX_OBJECTS + 8;
    let cols = 3 * runs;
    let mut g = empty(2, cols);
    // Row 0 under the first MAX_OBJECTS runs only.
    let mut cells: Vec<(usize, usize)> = (0..3 * MAX_OBJECTS - 2).map(|c| (0, c)).collect();
    // Row 1: runs of two positions, one apart.
    for k in 0..runs {
        cells.extend([(1, 3 * k), (1, 3 * k + 1)]);
    }
    mark(&mut g, &cells);
    let (got, n, unobjected) = g.stream();
    assert_eq!(n, 1, "{got:?}");
    assert_eq!(unobjected as usize, 2 * (runs - MAX_OBJECTS));
    assert_eq!(got[0].area as usize, 3 * MAX_OBJECTS - 2 + 2 * MAX_OBJECTS);
    assert_eq!((got[0].row0, got[0].row1), (0, 1));
}

/// The centroid weighs positions by strength: a position 3 times as strong
/// pulls the centroid to 3/4 of the way, in 1/256 positions.
#[test]
fn centroid_is_strength_weighted() {
    let mut g = empty(1, 2);
    g.s[0].flags = flags::POWER_DEFECT;
    g.s[0].strength = 65_536;
    g.s[1].flags = flags::CVM_DEFECT;
    g.s[1].strength = 3 * 65_536;
    let (got, _, _) = g.stream();
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].centroid_col_q8, 192);
    assert_eq!(got[0].centroid_row_q8, 0);
    assert_eq!(got[0].channels, flags::CVM_DEFECT | flags::POWER_DEFECT);
    assert_eq!((got[0].peak_col, got[0].peak), (1, 3 * 65_536));
}
