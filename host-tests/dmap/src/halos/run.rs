//! One scan through the firmware's streaming engine and object labeller.

use cvm_core::stream::row_words_for;
use cvm_core::{Engine, Object, Objects, Position, PositionScore, RowView, Scorer};

use super::parts::Halo;
use super::thresholds::Thresholds;

/// Columns the engine is built for: the study's rasters (39) and the
/// paper-sim part (300).
pub const MAX_COLS: usize = 320;

/// What the engine and the labeller put out for one scan.
#[derive(Clone, Debug, Default)]
pub struct Outcome {
    /// Every position's score, raster order.
    pub scores: Vec<PositionScore>,
    /// The objects, as the board reports them.
    pub objects: Vec<Object>,
}

/// Streams a `rows x cols` scan (`u16` maps of the scorer's cells, raster
/// order) through [`Engine`] with `thr`, and its rows through [`Objects`].
///
/// # Panics
/// If the scan does not match its shape or has more than [`MAX_COLS`]
/// columns: the callers build both.
pub fn run_scan(
    scorer: &Scorer,
    rows: usize,
    cols: usize,
    data: &[u16],
    thr: Thresholds,
) -> Outcome {
    let n = scorer.cells();
    assert_eq!(data.len(), rows * cols * n, "scan does not match its shape");
    let words = row_words_for(cols, scorer.config());
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let mut engine = Box::new(
        Engine::<MAX_COLS>::new(scorer, cols as u32, thr.cvm, &mut a, &mut b).expect("columns"),
    );
    engine.set_power_threshold(thr.power);
    engine.set_spread_threshold(thr.spread);
    engine.set_rows(rows as u32);
    let mut labeller = Box::new(Objects::new());
    let mut out = Outcome::default();
    let mut take = |v: &RowView| {
        out.scores.extend_from_slice(v.scores);
        labeller.push_row(v, &mut |o| out.objects.push(*o));
    };
    for (i, frame) in data.chunks_exact(n).enumerate() {
        let pos = Position {
            row: (i / cols) as u32,
            col: (i % cols) as u32,
        };
        engine.push(pos, frame, &mut take);
    }
    let mut totals = engine.finish(&mut take);
    labeller.finish_with(&mut |o| out.objects.push(*o), &mut totals);
    out
}

/// Whether an object overlaps the halo's truth region grown by one
/// position each way (the reach of Eq. 1's central differences).
pub fn found(objects: &[Object], halo: &Halo) -> bool {
    objects.iter().any(|o| near(o, halo))
}

/// Whether `o` is within one position of `halo`'s truth.
pub fn near(o: &Object, halo: &Halo) -> bool {
    near_truth(o, &halo.truth)
}

/// Whether `o` is within one position of any of `truth` (`(row, col)`).
pub fn near_truth(o: &Object, truth: &[(usize, usize)]) -> bool {
    truth.iter().any(|&(r, c)| {
        let (r, c) = (r as u32, c as u32);
        r + 1 >= o.row0 && r <= o.row1 + 1 && c + 1 >= o.col0 && c <= o.col1 + 1
    })
}

/// Each channel's largest magnitude over its threshold among `positions`
/// (`(row, col)`) of a scan `cols` wide: CVM, power, spread. Above 1: that
/// channel fires there.
pub fn peak_ratios(
    scores: &[PositionScore],
    cols: usize,
    positions: impl IntoIterator<Item = (usize, usize)>,
    thr: Thresholds,
) -> [f64; 3] {
    let mut r = [0.0f64; 3];
    for (row, col) in positions {
        let Some(s) = scores.get(row * cols + col) else {
            continue;
        };
        let v = [
            s.mag as f64 / thr.cvm.max(1) as f64,
            f64::from(s.pmag) / thr.power.max(1) as f64,
            s.smag as f64 / thr.spread.max(1) as f64,
        ];
        for (a, b) in r.iter_mut().zip(v) {
            *a = a.max(b);
        }
    }
    r
}

/// The positions of `halo`'s truth and their neighbours within one
/// position, inside a `rows x cols` raster.
pub fn around(halo: &Halo, rows: usize, cols: usize) -> Vec<(usize, usize)> {
    around_truth(&halo.truth, rows, cols)
}

/// The positions of `truth` and their neighbours within one position,
/// inside a `rows x cols` raster.
pub fn around_truth(truth: &[(usize, usize)], rows: usize, cols: usize) -> Vec<(usize, usize)> {
    let mut v: Vec<(usize, usize)> = truth
        .iter()
        .flat_map(|&(r, c)| {
            (r.saturating_sub(1)..(r + 2).min(rows)).flat_map(move |rr| {
                (c.saturating_sub(1)..(c + 2).min(cols)).map(move |cc| (rr, cc))
            })
        })
        .collect();
    v.sort_unstable();
    v.dedup();
    v
}
