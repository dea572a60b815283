//! The header (`H`) line: what a scan is scored with and how the board
//! started, written first.

use super::fields::{Fields, ParseError, parse_i32, parse_u32};
use super::frame::{LineBuf, LineSink, Priority};
use crate::config::{Config, Kernels, Weights};
use crate::scorer::Scorer;
use crate::settings::{Boot, KEYS, ResetCause, Settings, Source, Store};

/// Protocol version written in the header.
pub const VERSION: u32 = 7;
/// Longest firmware version string carried in the header.
pub const MAX_FW: usize = 24;

/// What the header says about the scan, the scoring and the board's start.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeaderInfo<'s> {
    pub version: u32,
    pub firmware: &'s str,
    pub j1: u8,
    pub j2: u8,
    pub cols: u32,
    /// `b'P'` paper kernels or `b'S'` square kernels.
    pub kernels: u8,
    /// `bmax` (paper, 0 = all) or `kmax` (square).
    pub kernel_size: u8,
    /// `"uniform"`, `"unit"` or `"separable"`.
    pub weights: &'s str,
    pub normalise: bool,
    pub full_scale: u16,
    pub threshold: u32,
    /// Power channel threshold, `Q15` (`pthr`; [`crate::channels::power::POWER_OFF`]: off).
    pub power_threshold: u32,
    /// Spread channel threshold, `Q16` (`sthr`, version 7 on;
    /// [`crate::channels::spread::SPREAD_OFF`]: off, as in an older header).
    pub spread_threshold: u32,
    /// Score format: a score `s` is `s / 2^q` distance units.
    pub q: i32,
    pub scores: bool,
    /// Most `D` lines per row (`dcap`).
    pub max_defect_lines: u16,
    /// Why the board last started (`rst`).
    pub reset_cause: ResetCause,
    /// Starts since power-on, this one included (`boots`; 1 after power-on).
    pub boots: u32,
    /// What version 6 added (`None` in a version 5 header).
    pub origin: Option<Origin>,
}

/// The scan's rows and where its settings came from (version 6 on).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Origin {
    /// Rows of the scan (`rows`).
    pub rows: u32,
    /// Each runtime setting's source, in `command::Key::ALL`'s order (`src`).
    pub sources: [Source; KEYS],
    /// What became of the settings record at start-up (`store`).
    pub store: Store,
}

impl HeaderInfo<'static> {
    /// The header of a pipeline with these settings, on a board that
    /// started so.
    pub fn new(scorer: &Scorer, settings: &Settings, boot: &Boot) -> Self {
        let cfg: &Config = scorer.config();
        let (kernels, kernel_size) = match cfg.kernels {
            Kernels::Paper { bmax } => (b'P', bmax),
            Kernels::Square { kmax } => (b'S', kmax),
        };
        let weights = match (cfg.kernels, cfg.weights) {
            (Kernels::Square { .. }, _) | (_, Weights::Unit) => "unit",
            (_, Weights::Uniform) => "uniform",
            (_, Weights::Separable { .. }) => "separable",
        };
        HeaderInfo {
            version: VERSION,
            firmware: boot.firmware,
            j1: cfg.geometry.j1,
            j2: cfg.geometry.j2,
            cols: settings.cols,
            kernels,
            kernel_size,
            weights,
            normalise: cfg.normalise,
            full_scale: cfg.full_scale,
            threshold: settings.threshold,
            power_threshold: settings.power_threshold,
            spread_threshold: settings.spread_threshold,
            q: scorer.score_frac_bits(),
            scores: settings.scores,
            max_defect_lines: settings.max_defect_lines_per_row,
            reset_cause: boot.reset_cause,
            boots: boot.boots,
            origin: Some(Origin {
                rows: settings.rows,
                sources: settings.sources,
                store: boot.store,
            }),
        }
    }
}

/// `H,v=7,fw=..,j=15x15,cols=300,k=P,b=0,w=uniform,norm=1,fs=65535,thr=..,pthr=..,sthr=..,q=23,scores=0,dcap=0,rst=por,boots=1,rows=..,src=ddddddddddddddd,store=none`
pub fn encode_header(h: &HeaderInfo, sink: &mut impl LineSink) {
    let mut l = LineBuf::new(b'H');
    l.kv_u64(b"v", h.version as u64);
    l.field(b"fw=");
    let fw = h.firmware.as_bytes();
    // Only characters that cannot break the line's syntax.
    for &b in fw.iter().take(MAX_FW) {
        l.byte(if b.is_ascii_graphic() && b != b',' && b != b'*' {
            b
        } else {
            b'?'
        });
    }
    l.field(b"j=");
    l.u64(h.j1 as u64);
    l.byte(b'x');
    l.u64(h.j2 as u64);
    l.kv_u64(b"cols", h.cols as u64);
    l.field(b"k=");
    l.byte(h.kernels);
    l.kv_u64(b"b", h.kernel_size as u64);
    l.field(b"w=");
    l.bytes(h.weights.as_bytes());
    l.kv_u64(b"norm", h.normalise as u64);
    l.kv_u64(b"fs", h.full_scale as u64);
    l.kv_u64(b"thr", h.threshold as u64);
    l.kv_u64(b"pthr", h.power_threshold as u64);
    if h.version >= 7 {
        l.kv_u64(b"sthr", h.spread_threshold as u64);
    }
    l.field(b"q=");
    l.i64(h.q as i64);
    l.kv_u64(b"scores", h.scores as u64);
    l.kv_u64(b"dcap", h.max_defect_lines as u64);
    l.field(b"rst=");
    l.bytes(h.reset_cause.as_str().as_bytes());
    l.kv_u64(b"boots", h.boots as u64);
    if let Some(o) = &h.origin {
        l.kv_u64(b"rows", o.rows as u64);
        l.field(b"src=");
        for s in o.sources {
            l.byte(s.as_char());
        }
        l.field(b"store=");
        l.bytes(o.store.word().as_bytes());
    }
    sink.line(l.finish(), Priority::Keep);
}

/// `sthr`'s place among the settings keys (`command::Key::ALL`; checked
/// by core-tests `protocol_versions`).
pub const SPREAD_KEY: usize = 4;

pub(super) fn parse_header<'s>(
    f: &mut Fields<'s, impl Iterator<Item = &'s [u8]>>,
) -> Result<HeaderInfo<'s>, ParseError> {
    let e = ParseError::Format;
    let version = f.key_u32("v")?;
    let firmware = f.key_str("fw")?;
    let (j1, j2) = {
        let j = f.key("j")?;
        let x = j.iter().position(|&b| b == b'x').ok_or(e)?;
        let (a, b) = j.split_at(x);
        let axis = |s: &[u8]| parse_u32(s).and_then(|v| u8::try_from(v).ok()).ok_or(e);
        (axis(a)?, axis(b.get(1..).ok_or(e)?)?)
    };
    let cols = f.key_u32("cols")?;
    let kernels = match f.key("k")? {
        b"P" => b'P',
        b"S" => b'S',
        _ => return Err(e),
    };
    let kernel_size = f.key_u8("b")?;
    let weights = f.key_str("w")?;
    let normalise = f.key_flag("norm", "norm: 0 or 1")?;
    let full_scale = u16::try_from(f.key_u32("fs")?).map_err(|_| e)?;
    let threshold = f.key_u32("thr")?;
    let power_threshold = f.key_u32("pthr")?;
    let spread_threshold = if version >= 7 {
        f.key_u32("sthr")?
    } else {
        crate::channels::spread::SPREAD_OFF
    };
    let q = parse_i32(f.key("q")?).ok_or(e)?;
    let scores = f.key_flag("scores", "scores: 0 or 1")?;
    let max_defect_lines = u16::try_from(f.key_u32("dcap")?).map_err(|_| e)?;
    let reset_cause = ResetCause::parse(f.key("rst")?).ok_or(e)?;
    let boots = f.key_u32("boots")?;
    // Version 5 ended here; from 6 on the fields are always there.
    let origin = if version >= 6 {
        let rows = f.key_u32("rows")?;
        let src = f.key("src")?;
        let mut sources = [Source::Default; KEYS];
        // Version 6 had 15 settings: `sthr`, the fifth key, came with 7
        // (its source then reads `d`, as its channel is off).
        let slots = if version == 6 { KEYS - 1 } else { KEYS };
        if src.len() != slots {
            return Err(e);
        }
        let mut at = 0;
        for &c in src {
            if slots < KEYS && at == SPREAD_KEY {
                at += 1;
            }
            *sources.get_mut(at).ok_or(e)? = Source::from_char(c).ok_or(e)?;
            at += 1;
        }
        let store = Store::parse(f.key("store")?).ok_or(e)?;
        Some(Origin {
            rows,
            sources,
            store,
        })
    } else {
        None
    };
    Ok(HeaderInfo {
        version,
        firmware,
        j1,
        j2,
        cols,
        kernels,
        kernel_size,
        weights,
        normalise,
        full_scale,
        threshold,
        power_threshold,
        spread_threshold,
        q,
        scores,
        max_defect_lines,
        reset_cause,
        boots,
        origin,
    })
}
