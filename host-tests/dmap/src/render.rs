//! `dmap render`: pseudo-colour PNG of gradient magnitudes (viridis, dark =
//! low, yellow = high) with a colour bar, one panel per input file side by
//! side, NaN positions in magenta.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{ArgAction, Args};

use crate::cli_values::{Component, index, trimmed};
use crate::fmt::fmt_num;
use crate::font::{draw_text, text_height, text_width};
use crate::render_marks::{MapPlace, axis_pad, draw_axes, draw_boxes, read_objects};

const NAN_RGB: [u8; 3] = [255, 0, 255];
const INK: [u8; 3] = [0, 0, 0];
const MARGIN: usize = 12;
const FONT: usize = 2;
const BAR_W: usize = 16;
const TICKS: usize = 5;

#[derive(Args, Clone, Debug)]
pub struct RenderArgs {
    /// Gradient images (.npy, rows x cols x 3 as written by `dmap score`) or bool masks
    #[arg(required = true, value_name = "GRAD.npy")]
    pub inputs: Vec<PathBuf>,
    /// Output PNG ("-" for standard output)
    #[arg(short, long = "output", alias = "out", value_name = "OUT.png")]
    pub out: PathBuf,
    /// Component of a rows x cols x 3 gradient image (or its index 0, 1, 2)
    #[arg(long, alias = "channel", value_enum, default_value = "magnitude")]
    pub component: Component,
    /// Panel titles, comma-separated, one per input (default: file names)
    #[arg(
        long,
        value_name = "T1,T2,...",
        value_delimiter = ',',
        action = ArgAction::Set,
        value_parser = trimmed
    )]
    pub titles: Option<Vec<String>>,
    /// Colour by log10 of the value (zero and negative values get the bottom colour)
    #[arg(long)]
    pub log: bool,
    /// Bottom of the colour scale (default: smallest finite value of each panel)
    #[arg(long, allow_hyphen_values = true)]
    pub vmin: Option<f64>,
    /// Top of the colour scale (default: largest finite value of each panel)
    #[arg(long, allow_hyphen_values = true)]
    pub vmax: Option<f64>,
    /// One colour scale for all panels instead of one each
    #[arg(long)]
    pub shared: bool,
    /// Draw only rows R0..R0+H and columns C0..C0+W of every input
    #[arg(
        long,
        value_name = "R0,C0,H,W",
        value_delimiter = ',',
        action = ArgAction::Set,
        value_parser = index
    )]
    pub crop: Option<Vec<usize>>,
    /// Pixels per scan position, 1..=64 (default: about 400 pixels per panel side)
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=64))]
    pub scale: Option<u8>,
    /// Draw the defect objects' boxes and ids on every panel: the objects of the last scan of
    /// FILE, result lines (as `dmap listen --input` reads them) or a `dmap listen --json`
    /// document
    #[arg(long, value_name = "FILE")]
    pub objects: Option<PathBuf>,
    /// Scan pitch in µm (the same on both axes): millimetre axes along each panel
    #[arg(long, value_name = "P", value_parser = crate::cli_values::positive_f64)]
    pub pitch_um: Option<f64>,
}

/// One image to draw: `values[row * cols + col]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Panel {
    pub rows: usize,
    pub cols: usize,
    pub values: Vec<f64>,
    pub title: String,
}

/// How values map to colours.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Style {
    pub log: bool,
    pub vmin: Option<f64>,
    pub vmax: Option<f64>,
    pub shared: bool,
    pub scale: Option<usize>,
    /// Millimetre axes at this scan pitch (µm).
    pub pitch_um: Option<f64>,
}

/// An RGB image, row-major, 3 bytes per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<u8>,
    /// Where each panel's map is.
    pub maps: Vec<MapPlace>,
}

impl Image {
    pub fn pixel(&self, x: usize, y: usize) -> [u8; 3] {
        let i = 3 * (y * self.width + x);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    fn fill(&mut self, x: usize, y: usize, w: usize, h: usize, c: [u8; 3]) {
        for yy in y..(y + h).min(self.height) {
            for xx in x..(x + w).min(self.width) {
                let i = 3 * (yy * self.width + xx);
                self.rgb[i..i + 3].copy_from_slice(&c);
            }
        }
    }
}

/// Value as placed on the colour axis (log10 when asked; non-positive
/// values go to -inf, i.e. the bottom of the scale).
fn axis(v: f64, log: bool) -> f64 {
    if !log {
        v
    } else if v > 0.0 {
        v.log10()
    } else if v.is_nan() {
        v
    } else {
        f64::NEG_INFINITY
    }
}

/// Colour-axis range of some values: finite min and max, overridden by the
/// style's limits, widened when empty or flat.
fn range<'a>(values: impl Iterator<Item = &'a f64>, s: &Style) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &v in values {
        let a = axis(v, s.log);
        if a.is_finite() {
            lo = lo.min(a);
            hi = hi.max(a);
        }
    }
    if let Some(v) = s.vmin {
        lo = axis(v, s.log);
    }
    if let Some(v) = s.vmax {
        hi = axis(v, s.log);
    }
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    if hi <= lo {
        let pad = if lo == 0.0 { 1.0 } else { lo.abs() * 0.5 };
        return (lo - pad, lo + pad);
    }
    (lo, hi)
}

/// Colour of a value given the colour-axis range.
pub fn colour(v: f64, lo: f64, hi: f64, log: bool) -> [u8; 3] {
    let a = axis(v, log);
    if a.is_nan() {
        return NAN_RGB;
    }
    let c = colorous::VIRIDIS.eval_continuous(position(a, lo, hi));
    [c.r, c.g, c.b]
}

/// Where `a` sits between `lo` and `hi`, in [0, 1]; halved first so that
/// a range as wide as the f64 numbers (-1e308..1e308) does not overflow.
fn position(a: f64, lo: f64, hi: f64) -> f64 {
    let t = (a / 2.0 - lo / 2.0) / (hi / 2.0 - lo / 2.0);
    if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) }
}

/// The colour bar's tick values (on the colour axis) and labels, from
/// `lo` to `hi`.
pub fn ticks(lo: f64, hi: f64, log: bool) -> Vec<(f64, String)> {
    (0..TICKS)
        .map(|k| {
            let f = k as f64 / (TICKS - 1) as f64;
            // Interpolated, not `lo + (hi - lo) * f`, which overflows.
            let a = lo * (1.0 - f) + hi * f;
            (a, label(if log { 10f64.powf(a) } else { a }))
        })
        .collect()
}

/// Short tick label: up to 4 significant digits, exponent form outside [0.01, 1e4).
pub fn label(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if (1e-2..1e4).contains(&a) {
        let decimals = (3 - a.log10().floor() as i32).max(0) as usize;
        let s = format!("{v:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{v:.2E}")
    }
}

/// Draw the panels side by side.
pub fn render(panels: &[Panel], s: &Style) -> Result<Image> {
    if panels.is_empty() {
        bail!("nothing to render");
    }
    let biggest = panels
        .iter()
        .map(|p| p.rows.max(p.cols))
        .max()
        .unwrap_or(1)
        .max(1);
    let px = s.scale.unwrap_or((400 / biggest).clamp(1, 64));
    if width_at_least(panels, px).is_none_or(|a| a > MAX_PIXELS) {
        bail!(
            "image of at least {} pixels is too large: lower --scale",
            fmt_big(width_at_least(panels, px))
        );
    }
    if px == 0 || px > 64 {
        bail!("--scale must be 1..=64, got {px}");
    }
    let shared = s
        .shared
        .then(|| range(panels.iter().flat_map(|p| p.values.iter()), s));
    let ranges: Vec<(f64, f64)> = panels
        .iter()
        .map(|p| shared.unwrap_or_else(|| range(p.values.iter(), s)))
        .collect();
    let labels: Vec<Vec<(f64, String)>> = ranges
        .iter()
        .map(|&(lo, hi)| ticks(lo, hi, s.log))
        .collect();
    let th = text_height(FONT);
    let legend_h = th + 8;
    let pads: Vec<usize> = panels
        .iter()
        .map(|p| s.pitch_um.map_or(0, |pitch| axis_pad(p.rows, pitch)))
        .collect();
    let widths: Vec<usize> = panels
        .iter()
        .zip(&labels)
        .zip(&pads)
        .map(|((p, l), pad)| {
            let label_w = l
                .iter()
                .map(|(_, t)| text_width(t, FONT))
                .max()
                .unwrap_or(0)
                .max(text_width("NAN", FONT) + th + 4);
            (pad + p.cols * px + 10 + BAR_W + 6 + label_w).max(text_width(&p.title, FONT)) + MARGIN
        })
        .collect();
    let img_h = panels.iter().map(|p| p.rows * px).max().unwrap_or(0);
    let width = MARGIN + widths.iter().sum::<usize>();
    let height = MARGIN + th + 8 + img_h.max(th * 3) + 8 + legend_h + MARGIN;
    if width.saturating_mul(height) > MAX_PIXELS {
        bail!("image of {width}x{height} pixels is too large: lower --scale");
    }
    let mut im = Image {
        width,
        height,
        rgb: vec![255; width * height * 3],
        maps: Vec::new(),
    };
    let mut left = MARGIN;
    for ((((p, &(lo, hi)), ticks), w), pad) in panels
        .iter()
        .zip(&ranges)
        .zip(&labels)
        .zip(&widths)
        .zip(&pads)
    {
        let y_title = MARGIN;
        draw_text(&mut im.rgb, width, left, y_title, &p.title, FONT, INK);
        let y0 = MARGIN + th + 8;
        let x0 = left + pad;
        let place = MapPlace {
            x: x0,
            y: y0,
            px,
            rows: p.rows,
            cols: p.cols,
        };
        im.maps.push(place);
        if let Some(pitch) = s.pitch_um {
            draw_axes(&mut im.rgb, width, place, pitch);
        }
        for r in 0..p.rows {
            for c in 0..p.cols {
                im.fill(
                    x0 + c * px,
                    y0 + r * px,
                    px,
                    px,
                    colour(p.values[r * p.cols + c], lo, hi, s.log),
                );
            }
        }
        // Colour bar: top is the high end.
        let bx = x0 + p.cols * px + 10;
        let bh = (p.rows * px).max(th * 3);
        for yy in 0..bh {
            let t = 1.0 - yy as f64 / (bh - 1).max(1) as f64;
            let c = colorous::VIRIDIS.eval_continuous(t);
            im.fill(bx, y0 + yy, BAR_W, 1, [c.r, c.g, c.b]);
        }
        for (a, text) in ticks {
            let t = if hi > lo { position(*a, lo, hi) } else { 0.0 };
            let yy = y0 + ((1.0 - t) * (bh - 1) as f64).round() as usize;
            // Ticks sit on the bar itself so they cannot be read as minus signs.
            im.fill(bx + BAR_W / 2, yy, BAR_W - BAR_W / 2, 1, INK);
            let ty = yy
                .saturating_sub(th / 2)
                .clamp(y0.saturating_sub(th / 2), y0 + bh - th / 2);
            draw_text(&mut im.rgb, width, bx + BAR_W + 5, ty, text, FONT, INK);
        }
        if p.values.iter().any(|v| v.is_nan()) {
            let ly = y0 + bh + 8;
            im.fill(bx, ly, th, th, NAN_RGB);
            draw_text(&mut im.rgb, width, bx + th + 4, ly, "NAN", FONT, INK);
        }
        left += w;
    }
    Ok(im)
}

/// Most pixels an image may have.
pub const MAX_PIXELS: usize = 100_000_000;

/// A lower bound of the image's pixels from the panels' sizes alone: what
/// can be refused before any value is looked at.
fn width_at_least(panels: &[Panel], px: usize) -> Option<usize> {
    let w = panels
        .iter()
        .try_fold(0usize, |acc, p| acc.checked_add(p.cols.checked_mul(px)?))?;
    let h = panels.iter().map(|p| p.rows).max()?.checked_mul(px)?;
    w.checked_mul(h)
}

fn fmt_big(v: Option<usize>) -> String {
    v.map_or_else(|| "more than 2^64".to_string(), |v| v.to_string())
}

/// Write an RGB image as an 8-bit PNG.
pub fn write_png(path: &Path, im: &Image) -> Result<()> {
    write_png_to(&crate::out::Target::File(path.to_path_buf()), im)
}

/// [`write_png`] to a file or standard output.
pub fn write_png_to(target: &crate::out::Target, im: &Image) -> Result<()> {
    let name = target.name();
    crate::out::write_target(target, |out| {
        let mut enc = png::Encoder::new(out, im.width as u32, im.height as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc
            .write_header()
            .with_context(|| format!("writing {name}"))?;
        w.write_image_data(&im.rgb)
            .with_context(|| format!("writing {name}"))?;
        w.finish().with_context(|| format!("writing {name}"))?;
        Ok(())
    })
}

/// Load one channel of a gradient image (rows x cols x 3) as a panel; a
/// boolean mask (rows x cols) is also accepted and drawn as 0/1.
pub fn load_panel(path: &Path, channel: usize, title: String) -> Result<Panel> {
    let (rows, cols, values) = match crate::npy::read_gradient(path) {
        Ok(g) => {
            if channel >= 3 {
                bail!(
                    "--component {channel} does not exist: 0 horizontal, 1 vertical, 2 magnitude"
                );
            }
            (
                g.rows,
                g.cols,
                g.data.chunks_exact(3).map(|c| c[channel]).collect(),
            )
        }
        Err(e) => match crate::npy::read_mask(path) {
            Ok(m) => (
                m.rows,
                m.cols,
                m.data.iter().map(|&b| f64::from(u8::from(b))).collect(),
            ),
            Err(_) => return Err(e),
        },
    };
    if rows == 0 || cols == 0 {
        bail!("{}: empty array {rows}x{cols}", path.display());
    }
    Ok(Panel {
        rows,
        cols,
        values,
        title,
    })
}

/// Whether `start..start + len` lies within `0..all` (no overflow: the
/// numbers come from the user).
fn fits(start: usize, len: usize, all: usize) -> bool {
    start.checked_add(len).is_some_and(|end| end <= all)
}

/// The part of a panel at rows r0..r0+h, columns c0..c0+w.
pub fn crop_panel(p: &Panel, (r0, c0, h, w): (usize, usize, usize, usize)) -> Result<Panel> {
    if !fits(r0, h, p.rows) || !fits(c0, w, p.cols) {
        bail!(
            "--crop {r0},{c0},{h},{w} exceeds the {}x{} image",
            p.rows,
            p.cols
        );
    }
    let values = (r0..r0 + h)
        .flat_map(|r| {
            p.values[r * p.cols + c0..r * p.cols + c0 + w]
                .iter()
                .copied()
        })
        .collect();
    Ok(Panel {
        rows: h,
        cols: w,
        values,
        title: p.title.clone(),
    })
}

pub fn run(a: &RenderArgs) -> Result<()> {
    let titles: Vec<String> = match &a.titles {
        Some(v) => {
            if v.len() != a.inputs.len() {
                bail!(
                    "--titles has {} entries for {} input files",
                    v.len(),
                    a.inputs.len()
                );
            }
            v.clone()
        }
        None => a
            .inputs
            .iter()
            .map(|p| {
                p.file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default()
            })
            .collect(),
    };
    for (name, v) in [("--vmin", a.vmin), ("--vmax", a.vmax)] {
        if let Some(v) = v
            && !v.is_finite()
        {
            bail!("{name} must be a finite number, got {v}");
        }
    }
    if let (Some(lo), Some(hi)) = (a.vmin, a.vmax)
        && lo >= hi
    {
        bail!(
            "--vmin {} must be below --vmax {}",
            fmt_num(lo),
            fmt_num(hi)
        );
    }
    let target = crate::out::Target::new(&a.out);
    if let crate::out::Target::File(out) = &target {
        let inputs: Vec<&Path> = a.inputs.iter().map(PathBuf::as_path).collect();
        crate::out::refuse_inputs(out, &inputs)?;
    }
    if a.log && (a.vmin.is_some_and(|v| v <= 0.0) || a.vmax.is_some_and(|v| v <= 0.0)) {
        bail!("--log needs positive --vmin/--vmax");
    }
    let crop = match a.crop.as_deref() {
        None => None,
        Some(&[r0, c0, h, w]) if h >= 1 && w >= 1 => Some((r0, c0, h, w)),
        Some(v) => {
            let given: Vec<String> = v.iter().map(usize::to_string).collect();
            bail!(
                "--crop {}: expected R0,C0,H,W with H, W >= 1",
                given.join(",")
            );
        }
    };
    // The image's size follows from the inputs' shapes: refuse one too
    // large before reading any values.
    let shapes = a
        .inputs
        .iter()
        .map(|p| {
            let (rows, cols) = crate::npy::image_shape(p)?;
            Ok(match crop {
                Some((r0, c0, h, w)) => {
                    if !fits(r0, h, rows) || !fits(c0, w, cols) {
                        bail!(
                            "{}: --crop {r0},{c0},{h},{w} exceeds the {rows}x{cols} image",
                            p.display()
                        );
                    }
                    (h, w)
                }
                None => (rows, cols),
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let outlines: Vec<Panel> = shapes
        .iter()
        .map(|&(rows, cols)| Panel {
            rows,
            cols,
            values: Vec::new(),
            title: String::new(),
        })
        .collect();
    let biggest = shapes
        .iter()
        .map(|&(r, c)| r.max(c))
        .max()
        .unwrap_or(1)
        .max(1);
    let px = a.scale.map_or((400 / biggest).clamp(1, 64), usize::from);
    if width_at_least(&outlines, px).is_none_or(|n| n > MAX_PIXELS) {
        bail!(
            "image of at least {} pixels is too large: lower --scale",
            fmt_big(width_at_least(&outlines, px))
        );
    }
    let panels = a
        .inputs
        .iter()
        .zip(titles)
        .map(|(p, t)| {
            let panel = load_panel(p, a.component.index(), t)?;
            match crop {
                Some(c) => crop_panel(&panel, c).with_context(|| p.display().to_string()),
                None => Ok(panel),
            }
        })
        .collect::<Result<Vec<_>>>()?;
    let im = render(
        &panels,
        &Style {
            log: a.log,
            vmin: a.vmin,
            vmax: a.vmax,
            shared: a.shared,
            scale: a.scale.map(usize::from),
            pitch_um: a.pitch_um,
        },
    )?;
    let mut im = im;
    if let Some(path) = &a.objects {
        let boxes = read_objects(path)?;
        let origin = crop.map_or((0, 0), |(r0, c0, _, _)| (r0, c0));
        for &m in &im.maps.clone() {
            draw_boxes(&mut im.rgb, im.width, m, &boxes, origin);
        }
    }
    write_png_to(&target, &im)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn style() -> Style {
        Style {
            log: false,
            vmin: None,
            vmax: None,
            shared: false,
            scale: Some(2),
            pitch_um: None,
        }
    }

    #[test]
    fn extremes_take_the_ends_of_viridis_and_nan_is_magenta() {
        let p = Panel {
            rows: 1,
            cols: 3,
            values: vec![0.0, 10.0, f64::NAN],
            title: "T".into(),
        };
        let im = render(&[p], &style()).unwrap();
        let y = MARGIN + text_height(FONT) + 8;
        // viridis starts dark purple (68, 1, 84) and ends yellow (253, 231, 37).
        let lo = im.pixel(MARGIN, y);
        let hi = im.pixel(MARGIN + 2, y);
        assert!(lo[2] > lo[1] && lo[0] < 90 && lo[1] < 10, "{lo:?}");
        assert!(hi[0] > 240 && hi[1] > 220 && hi[2] < 50, "{hi:?}");
        assert_eq!(im.pixel(MARGIN + 4, y + 1), NAN_RGB);
    }

    #[test]
    fn log_scale_puts_decades_evenly() {
        let (lo, hi) = range(
            [1.0, 10.0, 100.0, 0.0].iter(),
            &Style {
                log: true,
                ..style()
            },
        );
        assert_eq!((lo, hi), (0.0, 2.0));
        assert_eq!(colour(10.0, lo, hi, true), colour(0.5, 0.0, 1.0, false));
        assert_eq!(colour(0.0, lo, hi, true), colour(0.0, 0.0, 1.0, false));
    }

    #[test]
    fn labels_are_short() {
        assert_eq!(label(0.0), "0");
        assert_eq!(label(1.5), "1.5");
        assert_eq!(label(123.456), "123.5");
        assert_eq!(label(0.012345), "0.01235");
        assert_eq!(label(0.00012), "1.20E-4");
        assert_eq!(label(-2.0), "-2");
    }

    #[test]
    fn crop_keeps_the_asked_window() {
        let p = Panel {
            rows: 3,
            cols: 4,
            values: (0..12).map(f64::from).collect(),
            title: "T".into(),
        };
        let c = crop_panel(&p, (1, 2, 2, 2)).unwrap();
        assert_eq!(c.values, vec![6.0, 7.0, 10.0, 11.0]);
        assert!(crop_panel(&p, (2, 0, 2, 1)).is_err());
    }

    #[test]
    fn panels_sit_side_by_side() {
        let a = Panel {
            rows: 4,
            cols: 4,
            values: vec![1.0; 16],
            title: "A".into(),
        };
        let one = render(std::slice::from_ref(&a), &style()).unwrap();
        let two = render(&[a.clone(), a], &style()).unwrap();
        assert_eq!(two.height, one.height);
        assert_eq!(two.width, 2 * one.width - MARGIN);
    }
}
