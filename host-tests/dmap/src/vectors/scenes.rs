//! The scans the conformance vectors are made from: small synthetic parts
//! (integer maps, so the very same frames on every machine) scored by the
//! firmware's own pipeline (`cvm_core::Pipeline`, what `dmap stream` and
//! both boards run), with positions left without data, dark and saturated
//! maps, and score lines dropped as a board's full queue drops them.

use crate::settings::MAX_COLS;
use crate::stream::VecSink;
use anyhow::{Result, anyhow};
use cvm_core::protocol::{LineSink, Priority};
use cvm_core::stream::Position;
use cvm_core::{Boot, Config, Geometry, Pipeline, Scorer, Settings};

/// Detector size of every scene: 5x5 maps keep the vectors small.
const J: usize = 5;

/// What one position of a scene receives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Map {
    /// The part without defect: a spot in the detector's centre.
    Clear,
    /// The beam deflected: the spot one cell off (the distance channel).
    Deflected,
    /// The beam dimmed to 3/5 of its power, its shape unchanged (the power
    /// channel alone: normalised, the map is the clear one).
    Dimmed,
    /// A quarter of the spot's light scattered into a halo over the
    /// map's rim (the spread channel): the spot at 3/4, 115 on each of the
    /// 16 cells outside the 3x3 core, the power within 0.2 %.
    Haloed,
    /// No light at all (flag DARK).
    Dark,
    /// A sample at full scale (flag SATURATED).
    Saturated,
    /// No frame (flag NO_DATA): a lost beam.
    Missing,
    /// A frame of the wrong length (counted `bad`; the position without data).
    Bad,
}

/// The map of `kind`, row-major `J x J`: integer samples, a cone
/// `1000 - 50 d²` in half-cells around its centre.
fn frame(kind: Map, full_scale: u16) -> Vec<u16> {
    let (cy, cx) = match kind {
        Map::Deflected => (4, 6),
        _ => (4, 4),
    };
    let mut f: Vec<u16> = (0..J * J)
        .map(|i| {
            let (a, b) = ((2 * (i / J)) as i64, (2 * (i % J)) as i64);
            let d2 = (a - cy).pow(2) + (b - cx).pow(2);
            (1000 - 50 * d2).max(0) as u16
        })
        .collect();
    match kind {
        // Multiples of 50: 3/5 of each is exact, so the shape is kept.
        Map::Dimmed => f.iter_mut().for_each(|v| *v = *v / 5 * 3),
        // The cone's samples are multiples of 200: 3/4 of each is exact.
        Map::Haloed => {
            for (i, v) in f.iter_mut().enumerate() {
                let rim = matches!(i / J, 0 | 4) || matches!(i % J, 0 | 4);
                *v = *v / 4 * 3 + if rim { 115 } else { 0 };
            }
        }
        Map::Dark => f.fill(0),
        Map::Saturated => f[J * J / 2] = full_scale,
        _ => {}
    }
    f
}

/// A scene: its size, what each position receives, and the settings.
pub struct Scene {
    pub rows: u32,
    pub cols: u32,
    pub map: fn(u32, u32) -> Map,
    /// Threshold of the distance channel, in distance units.
    pub threshold: f64,
    /// Threshold of the power channel, a contrast (`inf`: off).
    pub power_threshold: f64,
    /// Threshold of the spread channel, a share of the power (`inf`: off).
    pub spread_threshold: f64,
    pub scores: bool,
    pub dcap: u16,
    pub full_scale: u16,
    /// Which score lines (row, first column) the output drops.
    pub drop: fn(u32, u32) -> bool,
    /// After row 5: a frame for a position already passed (`rejected`)
    /// and one beyond the last column (`extra`).
    pub stray_frames: bool,
    /// Maps the board found it had scored at a wrong position (`misplaced`).
    pub misplaced: u32,
}

impl Default for Scene {
    fn default() -> Self {
        Scene {
            rows: 10,
            cols: 30,
            map: two_defects,
            threshold: 0.05,
            power_threshold: 0.1,
            spread_threshold: f64::INFINITY,
            scores: false,
            dcap: 0,
            full_scale: 4095,
            drop: |_, _| false,
            stray_frames: false,
            misplaced: 0,
        }
    }
}

/// A deflecting patch (rows 2-3, columns 4-6) and a dimming one (rows
/// 6-7, columns 20-23): one object of each channel, closed by different
/// rows.
pub fn two_defects(r: u32, c: u32) -> Map {
    if (2..=3).contains(&r) && (4..=6).contains(&c) {
        Map::Deflected
    } else if (6..=7).contains(&r) && (20..=23).contains(&c) {
        Map::Dimmed
    } else {
        Map::Clear
    }
}

/// Keeps the lines a board's output keeps: the score lines `drop` names
/// are dropped and counted.
struct Dropping {
    out: VecSink,
    drop: fn(u32, u32) -> bool,
    dropped: u32,
}

impl LineSink for Dropping {
    fn line(&mut self, line: &[u8], priority: Priority) {
        if priority == Priority::Droppable && line.starts_with(b"S,") {
            let mut f = line.split(|&b| b == b',').skip(1);
            let mut num = || -> u32 {
                f.next()
                    .and_then(|s| std::str::from_utf8(s).ok())
                    .and_then(|s| s.parse().ok())
                    .unwrap_or(0)
            };
            let (row, col0) = (num(), num());
            if (self.drop)(row, col0) {
                self.dropped += 1;
                return;
            }
        }
        self.out.line(line, priority);
    }
}

/// The scorer of every scene: 5x5 paper kernels, uniform weights,
/// normalised maps, and `full_scale`; the spread channel's core 3x3
/// (half-width 1), since the boards' 5x5 core would be the whole map.
fn scorer(full_scale: u16) -> Result<Scorer> {
    let mut cfg = Config::paper(Geometry::new(J as u8, J as u8).map_err(|e| anyhow!("{e}"))?);
    cfg.full_scale = full_scale;
    Ok(Scorer::new(&cfg)
        .map_err(|e| anyhow!("{e}"))?
        .with_spread_half(1))
}

/// The settings of `scene`, with `edit` applied (the board's start, the
/// version string).
pub fn settings(scene: &Scene, scorer: &Scorer) -> Settings {
    let mut s = Settings::new(
        scene.cols,
        scene.rows,
        scorer.threshold_from_units(scene.threshold),
        cvm_core::power::threshold_from_units(scene.power_threshold),
    );
    s.spread_threshold = cvm_core::spread::threshold_from_units(scene.spread_threshold);
    s.scores = scene.scores;
    s.max_defect_lines_per_row = scene.dcap;
    s
}

/// The stream the pipeline writes for `scene`, its settings and the
/// board's start (a power-on of version 0.1.0) changed by `edit` first.
pub fn stream_with(scene: &Scene, edit: impl FnOnce(&mut Settings, &mut Boot)) -> Result<Vec<u8>> {
    let scorer = scorer(scene.full_scale)?;
    let mut settings = settings(scene, &scorer);
    let mut boot = Boot::power_on("0.1.0");
    edit(&mut settings, &mut boot);
    let words = cvm_core::stream::row_words_for(scene.cols as usize, scorer.config());
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let mut pipeline = Pipeline::<MAX_COLS>::new(&scorer, settings, &mut a, &mut b)
        .map_err(|e| anyhow!("pipeline refused the scene: {e}"))?;
    pipeline.set_boot(boot);
    let mut sink = Dropping {
        out: VecSink::default(),
        drop: scene.drop,
        dropped: 0,
    };
    pipeline.begin(&mut sink);
    for row in 0..scene.rows {
        for col in 0..scene.cols {
            let pos = Position { row, col };
            match (scene.map)(row, col) {
                Map::Missing => pipeline.mark_missing(pos, &mut sink),
                Map::Bad => pipeline.push(pos, &[0; 3], &mut sink),
                kind => pipeline.push(pos, &frame(kind, scene.full_scale), &mut sink),
            };
        }
        if scene.stray_frames && row == 5 {
            let clear = frame(Map::Clear, scene.full_scale);
            pipeline.push(Position { row, col: 3 }, &clear, &mut sink);
            let col = scene.cols;
            pipeline.push(Position { row, col }, &clear, &mut sink);
        }
    }
    pipeline.count_misplaced(scene.misplaced);
    let dropped = sink.dropped;
    pipeline.finish(dropped, &mut sink);
    Ok(sink.out.0)
}

/// The stream of `scene` with its own settings.
pub fn stream(scene: &Scene) -> Result<Vec<u8>> {
    stream_with(scene, |_, _| {})
}
