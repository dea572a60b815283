//! The whole streams among the conformance vectors: what the encoder
//! writes for each kind of scene, every line type, every flag and every
//! rule of docs/protocol.md that a whole stream can show.

use super::Vector;
use super::edit::Lines;
use super::scenes::{Map, Scene, stream, stream_with, two_defects};
use anyhow::Result;
use cvm_core::command::{Key, Refusal, Reply, encode_reply};
use cvm_core::protocol::ResetCause;
use cvm_core::settings::Source;

/// Positions without data (a gap of three beams, a whole lost row's
/// start), two dark maps with a position between them (both its
/// horizontal neighbours dark: a contrast of 0/0), a saturated map, and
/// the deflecting patch.
fn flagged(r: u32, c: u32) -> Map {
    match (r, c) {
        (4, 10..=12) | (8, 0..=3) => Map::Missing,
        (1, 15) | (1, 17) => Map::Dark,
        (5, 2) => Map::Saturated,
        _ => two_defects(r, c),
    }
}

/// Every other column of row 2 deflected: rows 1 and 3 get 35 separate
/// one-position runs each, more than the 32 the labeller holds.
fn many_runs(r: u32, c: u32) -> Map {
    if r == 2 && c.is_multiple_of(2) {
        Map::Deflected
    } else {
        Map::Clear
    }
}

/// A U of deflected maps (two arms that open two objects which merge at
/// the bottom) and a single deflected map further on.
fn u_shape(r: u32, c: u32) -> Map {
    let arm = (2..=6).contains(&r) && (c == 4 || c == 10);
    let bottom = r == 6 && (4..=10).contains(&c);
    if arm || bottom || (r, c) == (9, 20) {
        Map::Deflected
    } else {
        Map::Clear
    }
}

/// Two patches side by side: one row closes both objects.
fn side_by_side(r: u32, c: u32) -> Map {
    if (2..=3).contains(&r) && ((3..=4).contains(&c) || (12..=13).contains(&c)) {
        Map::Deflected
    } else {
        Map::Clear
    }
}

/// A single deflected map.
fn one_deflected(r: u32, c: u32) -> Map {
    if (r, c) == (3, 0) || (r, c) == (0, 5) {
        Map::Deflected
    } else {
        Map::Clear
    }
}

/// A haloed patch, rows 2-3, columns 10-12.
fn haloed(r: u32, c: u32) -> Map {
    if (2..=3).contains(&r) && (10..=12).contains(&c) {
        Map::Haloed
    } else {
        Map::Clear
    }
}

fn v(name: &str, about: &str, bytes: Vec<u8>) -> Vector {
    Vector {
        name: name.to_string(),
        about: about.to_string(),
        bytes,
        changes: None,
    }
}

/// The scene most damaged vectors start from: both channels, scores and
/// up to 4 defect lines per row.
pub fn scores_scene() -> Scene {
    Scene {
        scores: true,
        dcap: 4,
        ..Scene::default()
    }
}

/// The good vectors.
pub fn all() -> Result<Vec<Vector>> {
    let mut out = vec![
        v(
            "good-clear",
            "A part without defect: no object, verdict good",
            stream(&Scene {
                rows: 4,
                cols: 8,
                map: |_, _| Map::Clear,
                ..Scene::default()
            })?,
        ),
        v(
            "good-default",
            "Defaults (dcap=0, no scores): H, R, O and E lines; a distance object and a power object, closed by different rows",
            stream(&Scene::default())?,
        ),
        v(
            "good-scores",
            "Every line type: scores=1 (two S lines per row of 30 columns, the second of 6 positions), dcap=4 (D lines strongest first, leftmost among equals)",
            stream(&scores_scene())?,
        ),
        v(
            "good-defect-lines",
            "No S lines, every defect listed (dcap=30): the D lines alone show every defective position",
            stream(&Scene {
                dcap: 30,
                ..Scene::default()
            })?,
        ),
        v(
            "good-flags",
            "NO_DATA (a gap and a row's start), DARK (a position between two dark maps: contrast 0/0), SATURATED (fs=4095); missing neighbours replaced by the position itself; verdict fault-missing",
            stream(&Scene {
                map: flagged,
                scores: true,
                dcap: 8,
                ..Scene::default()
            })?,
        ),
        v(
            "good-threshold-zero",
            "thr=0 and pthr=0: every position with data is a defect of strength 4294967295; equal strengths listed leftmost first; one object",
            stream(&Scene {
                rows: 4,
                cols: 6,
                threshold: 0.0,
                power_threshold: 0.0,
                scores: true,
                dcap: 3,
                ..Scene::default()
            })?,
        ),
        v(
            "good-power-off",
            "pthr=4294967295: the power channel off, the dimmed patch unseen",
            stream(&Scene {
                power_threshold: f64::INFINITY,
                scores: true,
                ..Scene::default()
            })?,
        ),
        v(
            "good-spread",
            "sthr=3277 (0.05 of the power), thr at 0.2: a haloed patch (rows 2-3, columns 10-12; a quarter of the spot's light on the map's rim) found by the spread channel alone (flags 64); above it, at (1, 10), smag = 21638 - 7084 = 14554, the share outside the 3x3 core of a haloed map (2440 of 7390) less a clear one's (800 of 7400), in Q16 (the vectors' scorer takes a core of half-width 1: the boards' 5x5 core would cover these 5x5 maps whole)",
            stream(&Scene {
                map: haloed,
                threshold: 0.2,
                spread_threshold: 0.05,
                scores: true,
                dcap: 4,
                ..Scene::default()
            })?,
        ),
        v(
            "good-one-column",
            "cols=1: no horizontal neighbours (both replaced by the position itself); a deflected map in row 3",
            stream(&Scene {
                rows: 7,
                cols: 1,
                map: one_deflected,
                scores: true,
                dcap: 1,
                ..Scene::default()
            })?,
        ),
        v(
            "good-one-row",
            "rows=1: no vertical neighbours; a deflected map in column 5; the objects close at the scan's end",
            stream(&Scene {
                rows: 1,
                cols: 12,
                map: one_deflected,
                scores: true,
                dcap: 2,
                ..Scene::default()
            })?,
        ),
        v(
            "good-capacity",
            "35 separate runs in a row, more than the 32 objects and runs the labeller holds: the rest counted in unobj, verdict obj",
            stream(&Scene {
                rows: 5,
                cols: 70,
                map: many_runs,
                ..Scene::default()
            })?,
        ),
        v(
            "good-merge",
            "Two arms open objects 0 and 1, which merge (id 0 survives); the next object opens as id 2",
            stream(&Scene {
                rows: 12,
                cols: 26,
                map: u_shape,
                ..Scene::default()
            })?,
        ),
        v(
            "good-same-row",
            "One row closes two objects: their O lines in increasing id",
            stream(&Scene {
                rows: 7,
                cols: 18,
                map: side_by_side,
                ..Scene::default()
            })?,
        ),
        v(
            "good-dropped",
            "Two S lines dropped by the board's output and counted (dropped=2): allowed, no damage",
            stream(&Scene {
                drop: |row, col0| (row == 3 || row == 5) && col0 == 24,
                ..scores_scene()
            })?,
        ),
    ];
    out.push(v(
        "good-fault-frames",
        "A frame of the wrong length (bad; its position without data, missing=1), one for a position already passed (rejected), one past the last column (extra): verdict fault-frames, which comes before fault-missing",
        stream(&Scene {
            map: |r, c| if (r, c) == (3, 12) { Map::Bad } else { two_defects(r, c) },
            stray_frames: true,
            ..Scene::default()
        })?,
    ));
    out.push(v(
        "fault-misplaced",
        "Two maps the board scored at a wrong position (misplaced=2): verdict fault-misplaced, and a problem of the scan (its scores near the short row are unreliable)",
        stream(&Scene {
            misplaced: 2,
            ..Scene::default()
        })?,
    ));
    let default = stream(&Scene::default())?;
    let scores = stream(&scores_scene())?;
    let second = stream_with(&scores_scene(), |s, boot| {
        boot.reset_cause = ResetCause::Watchdog;
        boot.boots = 2;
        s.sources[0] = Source::Changed;
    })?;
    out.push(v(
        "good-two-scans",
        "Two scans one after the other, the second after a watchdog reset with a changed setting (rst=wdg, boots=2, src)",
        [default.clone(), second].concat(),
    ));
    out.push(v(
        "good-crlf",
        "Lines ending in \\r\\n (the \\r not covered by the CRC, nor counted in the length)",
        String::from_utf8_lossy(&scores)
            .replace('\n', "\r\n")
            .into_bytes(),
    ));
    out.push(v(
        "good-no-final-newline",
        "The last line without its newline: still a whole line",
        default[..default.len() - 1].to_vec(),
    ));
    let mut blank = Lines::of(&default);
    blank.insert(3, b"\n".to_vec()).insert(1, b"\r\n".to_vec());
    out.push(v(
        "good-blank-lines",
        "Empty lines, skipped (they count in the line numbers)",
        blank.bytes(),
    ));
    out.push(v(
        "good-replies",
        "Command replies (A lines, the command channel) between result lines: passed over and counted",
        with_replies(&default),
    ));
    out.push(v(
        "version-6",
        "A version 6 header (no sthr, 15 src letters) before version 7 lines: the header parses, the version is a problem of the scan (version 7 changed the D, S and O lines)",
        version_6(&default),
    ));
    out.push(v(
        "version-5",
        "A version 5 header (no sthr; it ends at boots) before version 7 lines: the header parses, the version is a problem of the scan",
        old_header(&default, 5),
    ));
    Ok(out)
}

/// `stream` with three replies among its lines.
fn with_replies(stream: &[u8]) -> Vec<u8> {
    let mut lines = Lines::of(stream);
    let reply = |id: Option<u32>, r: Reply| {
        let mut sink = crate::stream::VecSink::default();
        encode_reply(id, &r, &mut sink);
        sink.0
    };
    let value = Reply::Value {
        key: Key::Threshold,
        value: 4194304,
        source: Source::Changed,
    };
    lines
        .insert(2, reply(Some(1), value))
        .insert(5, reply(None, Reply::Refused(Refusal::Checksum)))
        .insert(7, reply(Some(2), Reply::Saved));
    lines.bytes()
}

/// `stream` with its header written as version 6 wrote it.
fn version_6(stream: &[u8]) -> Vec<u8> {
    old_header(stream, 6)
}

/// `stream` with its header written as a board of `version` (5 or 6)
/// wrote it: no `sthr`; version 6 with 15 `src` letters (no `sthr`'s),
/// version 5 ending at `boots`.
fn old_header(stream: &[u8], version: u32) -> Vec<u8> {
    let mut lines = Lines::of(stream);
    let body = lines.body(0);
    let fields: Vec<String> = body
        .split(',')
        .filter(|f| !f.starts_with("sthr="))
        .filter(|f| version >= 6 || !["rows=", "src=", "store="].iter().any(|k| f.starts_with(k)))
        .map(|f| match f.split_once('=') {
            Some(("v", _)) => format!("v={version}"),
            Some(("src", letters)) => {
                let mut l = letters.to_string();
                l.remove(cvm_core::protocol::SPREAD_KEY);
                format!("src={l}")
            }
            _ => f.to_string(),
        })
        .collect();
    lines.seal(0, &fields.join(","));
    lines.bytes()
}
