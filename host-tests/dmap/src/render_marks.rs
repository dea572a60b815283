//! What `dmap render` draws over a panel: the defect objects' boxes with
//! their ids (`--objects`: a stream of result lines, or a `dmap listen
//! --json` document) and millimetre axes (`--pitch-um`).

use crate::font::{draw_text, text_height, text_width};
use anyhow::{Context, Result, bail};
use std::path::Path;

/// The boxes' colour: one the scale (viridis) and NaN (magenta) never take.
pub const BOX_RGB: [u8; 3] = [230, 0, 0];
const INK: [u8; 3] = [0, 0, 0];
const FONT: usize = 2;

/// An object's box: rows `r0..=r1`, columns `c0..=c1`, and its id.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ObjectBox {
    pub id: u32,
    pub rows: (u32, u32),
    pub cols: (u32, u32),
}

/// Where a panel's map is in the image: its top left pixel, the pixels
/// per position, its rows and columns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MapPlace {
    pub x: usize,
    pub y: usize,
    pub px: usize,
    pub rows: usize,
    pub cols: usize,
}

/// The objects of the last scan of `path`: result lines (decoded as `dmap
/// listen` decodes them) or a `dmap listen --json` document.
pub fn read_objects(path: &Path) -> Result<Vec<ObjectBox>> {
    let p = path.display();
    let bytes = std::fs::read(path).with_context(|| format!("reading --objects {p}"))?;
    if bytes.trim_ascii_start().starts_with(b"{") {
        let v: serde_json::Value =
            serde_json::from_slice(&bytes).with_context(|| format!("--objects {p}: not JSON"))?;
        let Some(list) = v["objects"].as_array() else {
            bail!("--objects {p}: no \"objects\" list (a `dmap listen --json` document has one)");
        };
        let pair = |o: &serde_json::Value, k: &str| -> Option<(u32, u32)> {
            Some((o[k][0].as_u64()? as u32, o[k][1].as_u64()? as u32))
        };
        let one = |o: &serde_json::Value| {
            Some(ObjectBox {
                id: o["id"].as_u64()? as u32,
                rows: pair(o, "rows")?,
                cols: pair(o, "cols")?,
            })
        };
        return list
            .iter()
            .map(|o| {
                one(o)
                    .with_context(|| format!("--objects {p}: an object without id, rows and cols"))
            })
            .collect();
    }
    let dec = crate::listen::decode(bytes.as_slice(), 0)?;
    let Some(scan) = dec.scans.last() else {
        bail!(
            "--objects {p}: no scan in it (neither result lines nor a `dmap listen --json` document)"
        );
    };
    Ok(scan
        .objects
        .iter()
        .map(|o| ObjectBox {
            id: o.id,
            rows: (o.row0, o.row1),
            cols: (o.col0, o.col1),
        })
        .collect())
}

fn fill(rgb: &mut [u8], width: usize, (x, y, w, h): (usize, usize, usize, usize), c: [u8; 3]) {
    let height = rgb.len() / 3 / width.max(1);
    for yy in y..(y + h).min(height) {
        for xx in x..(x + w).min(width) {
            let i = 3 * (yy * width + xx);
            rgb[i..i + 3].copy_from_slice(&c);
        }
    }
}

/// Draws each box (shifted by the crop's first row and column, `origin`)
/// that falls on the map, two pixels wide inside its positions, its id
/// above it.
pub fn draw_boxes(
    rgb: &mut [u8],
    width: usize,
    m: MapPlace,
    boxes: &[ObjectBox],
    origin: (usize, usize),
) {
    let line = 2.min(m.px).max(1);
    for b in boxes {
        let (r0, r1) = (b.rows.0 as usize, b.rows.1 as usize);
        let (c0, c1) = (b.cols.0 as usize, b.cols.1 as usize);
        if r1 < origin.0 || c1 < origin.1 || r0 >= origin.0 + m.rows || c0 >= origin.1 + m.cols {
            continue;
        }
        let clip = |v: usize, o: usize, n: usize| v.saturating_sub(o).min(n - 1);
        let (top, bottom) = (clip(r0, origin.0, m.rows), clip(r1, origin.0, m.rows) + 1);
        let (left, right) = (clip(c0, origin.1, m.cols), clip(c1, origin.1, m.cols) + 1);
        let (x0, y0) = (m.x + left * m.px, m.y + top * m.px);
        let (w, h) = ((right - left) * m.px, (bottom - top) * m.px);
        for rect in [
            (x0, y0, w, line),
            (x0, y0 + h - line, w, line),
            (x0, y0, line, h),
            (x0 + w - line, y0, line, h),
        ] {
            fill(rgb, width, rect, BOX_RGB);
        }
        let th = text_height(FONT);
        let ty = if y0 >= m.y + th + 2 {
            y0 - th - 2
        } else {
            y0 + h + 2
        };
        draw_text(rgb, width, x0 + 1, ty, &b.id.to_string(), FONT, BOX_RGB);
    }
}

/// Tick marks in mm for `n` positions at `pitch_um`: (position, label).
fn mm_ticks(n: usize, pitch_um: f64) -> Vec<(f64, String)> {
    let span = n as f64 * pitch_um / 1000.0;
    let raw = span / 5.0;
    let p = 10f64.powf(raw.log10().floor());
    let step = p * match raw / p {
        m if m < 1.5 => 1.0,
        m if m < 3.5 => 2.0,
        m if m < 7.5 => 5.0,
        _ => 10.0,
    };
    (0..)
        .map(|k| k as f64 * step)
        .take_while(|t| *t <= span + 1e-9)
        .map(|t| {
            (
                t * 1000.0 / pitch_um,
                crate::fmt::fmt_num((t * 1000.0).round() / 1000.0),
            )
        })
        .collect()
}

/// Pixels left of a map that its row axis's labels take.
pub fn axis_pad(rows: usize, pitch_um: f64) -> usize {
    let widest = mm_ticks(rows, pitch_um)
        .iter()
        .map(|(_, t)| text_width(t, FONT))
        .max()
        .unwrap_or(0);
    widest.max(text_width("mm", FONT)) + 8
}

/// Millimetre axes along the map's left and bottom edges.
pub fn draw_axes(rgb: &mut [u8], width: usize, m: MapPlace, pitch_um: f64) {
    let th = text_height(FONT);
    for (at, label) in mm_ticks(m.cols, pitch_um) {
        let x = m.x + (at * m.px as f64).round() as usize;
        fill(rgb, width, (x, m.y + m.rows * m.px, 1, 4), INK);
        let tx = x.saturating_sub(text_width(&label, FONT) / 2);
        draw_text(rgb, width, tx, m.y + m.rows * m.px + 6, &label, FONT, INK);
    }
    for (at, label) in mm_ticks(m.rows, pitch_um) {
        let y = m.y + (at * m.px as f64).round() as usize;
        fill(rgb, width, (m.x.saturating_sub(4), y, 4, 1), INK);
        let tx = m.x.saturating_sub(6 + text_width(&label, FONT));
        draw_text(rgb, width, tx, y.saturating_sub(th / 2), &label, FONT, INK);
    }
    draw_text(
        rgb,
        width,
        m.x + m.cols * m.px + 4,
        m.y + m.rows * m.px + 6,
        "mm",
        FONT,
        INK,
    );
}
