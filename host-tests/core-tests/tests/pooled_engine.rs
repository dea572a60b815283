//! The engine's pooled decisions (`Engine::set_pooled_thresholds`) against
//! the footprints taken from the whole scan at once: every position's
//! pooled loss and raise, the decisions they add and the rows' defect
//! counts, on random scans with positions missing, with the row count
//! told or not and with or without the near buffer. The footprints and
//! rings are written here from their description (docs/method.md), not
//! from the engine's window.

use cvm_core::channels::pooled::{POOLED_OFF, loss, raise};
use cvm_core::spread::{CORE_HALF, SPREAD_OFF};
use cvm_core::{PositionScore, RowSummary, Scorer, flags};
use cvm_core_tests::{
    random_scan, rng, run_engine_pooled, run_engine_thresholds, scan_frames, spread_q_ref,
};
use rand::RngExt;

type Rows = Vec<(RowSummary, Vec<PositionScore>)>;

/// The footprints ending at a position, as offsets (row, column) from it.
/// Each one's ring is the rest of the box of rows -1..=1 and columns from
/// one left of the footprint to one right of the position.
const FOOTPRINTS: [&[(isize, isize)]; 4] = [
    &[(0, 0)],
    &[(0, -1), (0, 0)],
    &[(-1, 0), (0, 0)],
    &[(-1, -1), (-1, 0), (0, -1), (0, 0)],
];

/// Each position's (pooled loss, pooled raise) from the whole scan.
fn pooled_ref(
    rows: usize,
    cols: usize,
    powers: &[u32],
    spreads: &[u16],
    present: &[bool],
) -> Vec<(u16, u32)> {
    let at = |r: isize, c: isize| -> Option<usize> {
        (r >= 0 && c >= 0 && (r as usize) < rows && (c as usize) < cols)
            .then(|| r as usize * cols + c as usize)
            .filter(|&i| present[i])
    };
    let mut out = vec![(0u16, 0u32); rows * cols];
    for r in 0..rows as isize {
        for c in 0..cols as isize {
            if at(r, c).is_none() {
                continue;
            }
            let mut best = (0u32, 0u32);
            for foot in FOOTPRINTS {
                let fp: Option<Vec<usize>> =
                    foot.iter().map(|&(dr, dc)| at(r + dr, c + dc)).collect();
                let Some(fp) = fp else { continue };
                let left = foot.iter().map(|&(_, dc)| dc).min().unwrap() - 1;
                let mut ring = Vec::new();
                for dr in -1..=1 {
                    for dc in left..=1 {
                        if foot.contains(&(dr, dc)) {
                            continue;
                        }
                        if let Some(i) = at(r + dr, c + dc) {
                            ring.push(i);
                        }
                    }
                }
                if ring.len() < 3 {
                    continue;
                }
                let (k, m) = (fp.len() as u32, ring.len() as u32);
                let sp = |v: &[usize]| v.iter().map(|&i| powers[i]).sum::<u32>();
                let sq = |v: &[usize]| v.iter().map(|&i| spreads[i] as u32).sum::<u32>();
                best.0 = best.0.max(loss(sp(&fp), k, sp(&ring), m));
                best.1 = best.1.max(raise(sq(&fp), k, sq(&ring), m));
            }
            out[at(r, c).unwrap()] = (best.0 as u16, best.1);
        }
    }
    out
}

fn flat(rows: &Rows) -> Vec<PositionScore> {
    rows.iter().flat_map(|(_, s)| s.iter().copied()).collect()
}

/// A value in the middle of the non-zero ones: some positions fire, some not.
fn middle(v: impl Iterator<Item = u32>) -> u32 {
    let mut v: Vec<u32> = v.filter(|&x| x > 0).collect();
    v.sort_unstable();
    v.get(v.len() / 2).copied().unwrap_or(1)
}

#[test]
fn pooled_values_and_decisions_are_the_whole_scans() {
    let mut g = rng(5050);
    for case in 0..60 {
        let (j1, j2) = [(3, 3), (5, 5), (4, 6)][case % 3];
        let rows = g.random_range(1..7usize);
        let cols = g.random_range(1..10usize);
        let n = j1 * j2;
        let data = random_scan(&mut g, rows, cols, j1, j2);
        let present: Vec<bool> = (0..rows * cols)
            .map(|_| g.random_range(0..7) != 0)
            .collect();
        let frames = scan_frames(&data, n, rows, cols, Some(&present));
        let scorer = Scorer::new(&cvm_core::Config::paper(
            cvm_core::Geometry::new(j1 as u8, j2 as u8).unwrap(),
        ))
        .unwrap();
        let frame = |i: usize| &data[i * n..(i + 1) * n];
        let powers: Vec<u32> = (0..rows * cols)
            .map(|i| frame(i).iter().map(|&a| a as u32).sum())
            .collect();
        let spreads: Vec<u16> = (0..rows * cols)
            .map(|i| spread_q_ref(frame(i), j1, j2, CORE_HALF as usize))
            .collect();
        let want = pooled_ref(rows, cols, &powers, &spreads, &present);
        let thr = [u32::MAX, cvm_core::power::POWER_OFF, SPREAD_OFF];
        // First measured only (thresholds no value reaches), then deciding
        // at the middle of the values measured.
        let measure = (POOLED_OFF - 1, POOLED_OFF - 1);
        let (got, _) = run_engine_pooled(&scorer, cols, thr, measure, &frames, false, 0);
        let got = flat(&got);
        assert_eq!(got.len(), rows * cols, "case {case}");
        for (i, s) in got.iter().enumerate() {
            assert_eq!(
                (s.pl, s.pr),
                want[i],
                "case {case}, position {i} ({}x{} of {j1}x{j2})",
                rows,
                cols
            );
            assert!(
                !s.is_defect(),
                "case {case}: nothing reaches the thresholds"
            );
        }
        let tl = middle(want.iter().map(|w| w.0 as u32));
        let tr = middle(want.iter().map(|w| w.1));
        let reference = run_engine_pooled(&scorer, cols, thr, (tl, tr), &frames, false, 0);
        for (with_near, told) in [(false, rows as u32), (true, 0), (true, rows as u32 + 2)] {
            let other = run_engine_pooled(&scorer, cols, thr, (tl, tr), &frames, with_near, told);
            assert!(
                other == reference,
                "case {case}: near {with_near}, told {told} rows"
            );
        }
        for (summary, scores) in &reference.0 {
            let mut defects = 0;
            for (c, s) in scores.iter().enumerate() {
                let i = summary.row as usize * cols + c;
                let (pl, pr) = want[i];
                let power = pl as u32 >= tl;
                let spread = pr >= tr;
                assert_eq!(
                    s.flags & flags::POWER_DEFECT != 0,
                    power,
                    "case {case}, position {i}"
                );
                assert_eq!(
                    s.flags & flags::SPREAD_DEFECT != 0,
                    spread,
                    "case {case}, position {i}"
                );
                assert_eq!(s.flags & flags::CVM_DEFECT, 0);
                if power || spread {
                    defects += 1;
                    let st = [(power, pl as u32, tl), (spread, pr, tr)]
                        .iter()
                        .filter(|x| x.0)
                        .map(|&(_, v, t)| cvm_core::stream::strength(v, t))
                        .max()
                        .unwrap();
                    assert_eq!(s.strength, st, "case {case}, position {i}");
                }
            }
            assert_eq!(summary.defects, defects, "case {case}, row {}", summary.row);
        }
    }
}

/// Pooling off (the default) changes nothing: the rows are the engine's
/// without it, every pooled value 0.
#[test]
fn pooling_off_changes_nothing() {
    let mut g = rng(5051);
    for case in 0..20 {
        let (rows, cols, j) = (g.random_range(1..6usize), g.random_range(1..8usize), 5);
        let data = random_scan(&mut g, rows, cols, j, j);
        let frames = scan_frames(&data, j * j, rows, cols, None);
        let scorer = Scorer::new(&cvm_core::Config::paper(
            cvm_core::Geometry::new(5, 5).unwrap(),
        ))
        .unwrap();
        let thr = [1 << 20, 3277, 600];
        let plain = run_engine_thresholds(&scorer, cols, thr, &frames);
        let off = run_engine_pooled(
            &scorer,
            cols,
            thr,
            (POOLED_OFF, POOLED_OFF),
            &frames,
            false,
            0,
        );
        assert!(plain == off, "case {case}");
        assert!(
            flat(&off.0).iter().all(|s| s.pl == 0 && s.pr == 0),
            "case {case}"
        );
    }
}
