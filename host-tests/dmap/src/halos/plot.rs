//! Line charts of detection curves (fraction found against a parameter),
//! drawn into an RGB [`Image`] with the toolkit's own font: panels side by
//! side sharing one legend.

use crate::font::{draw_text, text_height, text_width};
use crate::render::Image;

/// One curve: points `(x, y)`, `y` a fraction in `[0, 1]`.
#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub colour: [u8; 3],
    pub points: Vec<(f64, f64)>,
}

/// One panel.
#[derive(Clone, Debug)]
pub struct Chart {
    pub title: String,
    pub series: Vec<Series>,
}

const PLOT_W: usize = 300;
const PLOT_H: usize = 220;
const LEFT: usize = 60;
const TOP: usize = 30;
const BOTTOM: usize = 50;
const GAP: usize = 30;
const TEXT: usize = 2;
const INK: [u8; 3] = [0, 0, 0];
const GRID: [u8; 3] = [220, 220, 220];

struct Canvas {
    im: Image,
}

impl Canvas {
    fn set(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < self.im.width && (y as usize) < self.im.height {
            let i = 3 * (y as usize * self.im.width + x as usize);
            self.im.rgb[i..i + 3].copy_from_slice(&c);
        }
    }

    /// A line two pixels wide (Bresenham, doubled downwards and right).
    fn line(&mut self, (x0, y0): (i64, i64), (x1, y1): (i64, i64), c: [u8; 3]) {
        let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
        let (sx, sy) = ((x1 - x0).signum(), (y1 - y0).signum());
        let (mut x, mut y, mut err) = (x0, y0, dx + dy);
        loop {
            for (ox, oy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                self.set(x + ox, y + oy, c);
            }
            if x == x1 && y == y1 {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    fn rect(&mut self, x: i64, y: i64, w: i64, h: i64, c: [u8; 3]) {
        for yy in y..y + h {
            for xx in x..x + w {
                self.set(xx, yy, c);
            }
        }
    }

    fn text(&mut self, x: usize, y: usize, s: &str, c: [u8; 3]) {
        let w = self.im.width;
        draw_text(&mut self.im.rgb, w, x, y, s, TEXT, c);
    }
}

/// The panels of `charts` side by side, `x` from `x_range.0` to
/// `x_range.1` with labels at `x_ticks`, `y` from 0 to 1, and one legend
/// below (the first chart's series names).
pub fn draw(charts: &[Chart], x_range: (f64, f64), x_ticks: &[f64], x_label: &str) -> Image {
    let panel_w = LEFT + PLOT_W + GAP;
    let legend_rows = charts.first().map_or(0, |c| c.series.len());
    let legend_h = legend_rows * (text_height(TEXT) + 8) + 10;
    let (w, h) = (
        charts.len() * panel_w + 10,
        TOP + PLOT_H + BOTTOM + legend_h,
    );
    let mut cv = Canvas {
        im: Image {
            width: w,
            height: h,
            rgb: vec![255; w * h * 3],
            maps: Vec::new(),
        },
    };
    let sx = |x: f64| ((x - x_range.0) / (x_range.1 - x_range.0) * PLOT_W as f64).round() as i64;
    let sy = |y: f64| ((1.0 - y.clamp(0.0, 1.0)) * PLOT_H as f64).round() as i64;
    for (i, chart) in charts.iter().enumerate() {
        let (ox, oy) = ((i * panel_w + LEFT) as i64, TOP as i64);
        for k in 0..=4 {
            let y = oy + sy(k as f64 / 4.0);
            cv.rect(ox, y, PLOT_W as i64, 1, GRID);
            let label = format!("{:.2}", k as f64 / 4.0);
            let lx = (ox as usize).saturating_sub(text_width(&label, TEXT) + 6);
            cv.text(
                lx,
                (y as usize).saturating_sub(text_height(TEXT) / 2),
                &label,
                INK,
            );
        }
        for &t in x_ticks {
            let x = ox + sx(t);
            cv.rect(x, oy, 1, PLOT_H as i64, GRID);
            let label = format!("{t}");
            let lx = (x as usize).saturating_sub(text_width(&label, TEXT) / 2);
            cv.text(lx, TOP + PLOT_H + 6, &label, INK);
        }
        cv.rect(ox, oy, 1, PLOT_H as i64 + 1, INK);
        cv.rect(ox, oy + PLOT_H as i64, PLOT_W as i64 + 1, 1, INK);
        let title_x = ox as usize + (PLOT_W.saturating_sub(text_width(&chart.title, TEXT))) / 2;
        cv.text(title_x, 8, &chart.title, INK);
        let xl_x = ox as usize + (PLOT_W.saturating_sub(text_width(x_label, TEXT))) / 2;
        cv.text(xl_x, TOP + PLOT_H + 24, x_label, INK);
        for s in &chart.series {
            let pts: Vec<(i64, i64)> = s
                .points
                .iter()
                .map(|&(x, y)| (ox + sx(x), oy + sy(y)))
                .collect();
            for p in pts.windows(2) {
                cv.line(p[0], p[1], s.colour);
            }
            for &(x, y) in &pts {
                cv.rect(x - 3, y - 3, 7, 7, s.colour);
            }
        }
    }
    if let Some(first) = charts.first() {
        for (k, s) in first.series.iter().enumerate() {
            let y = TOP + PLOT_H + BOTTOM + k * (text_height(TEXT) + 8);
            cv.rect(LEFT as i64, y as i64 + 2, 24, 6, s.colour);
            cv.text(LEFT + 32, y, &s.name, INK);
        }
    }
    cv.im
}
