//! `dmap stream` | `dmap listen --json`: the defect objects (`O` lines)
//! against an independent expectation, the 8-connected components of the
//! positions the `S` lines mark defective (a flood fill here), their sizes
//! in mm, and the decoder's checks of damaged, missing and misplaced `O`
//! lines.

mod common;

use common::{dmap, ok, s, tmp_in};
use cvm_core::flags;
use cvm_core::protocol::{self, Line};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Bounding box, area and channels of one component.
#[derive(Clone, Debug, PartialEq)]
struct Component {
    rows: [u64; 2],
    cols: [u64; 2],
    area: u64,
    channels: Vec<String>,
}

/// Defective positions and their flags.
type Defective = BTreeMap<(usize, usize), u8>;

/// The positions the `S` lines of the stream's only scan mark defective
/// (`CVM_DEFECT` or `POWER_DEFECT`), with their flags, and the scan's
/// power magnitudes as contrasts.
fn defective(bytes: &[u8]) -> (usize, usize, Defective, Vec<f64>) {
    let (mut rows, mut cols) = (0, 0);
    let mut set = BTreeMap::new();
    let mut power = BTreeMap::new();
    for l in bytes.split_inclusive(|&b| b == b'\n') {
        match protocol::parse(l).expect("a clean stream") {
            Line::Header(h) => cols = h.cols as usize,
            Line::Scores { row, col0, chars } => {
                rows = rows.max(row as usize + 1);
                for (k, c) in chars.chunks(protocol::SCORE_CHARS).enumerate() {
                    let v = protocol::decode_score(c).unwrap();
                    let pos = (row as usize, col0 as usize + k);
                    power.insert(pos, v.pmag as f64 / 32768.0);
                    if v.flags & flags::DEFECT != 0 {
                        set.insert(pos, v.flags);
                    }
                }
            }
            _ => {}
        }
    }
    assert_eq!(power.len(), rows * cols, "every position has a score");
    (rows, cols, set, power.into_values().collect())
}

/// 8-connected components of `set`, by a flood fill, sorted by first
/// row and column.
fn components(set: &Defective) -> Vec<Component> {
    let mut seen = std::collections::BTreeSet::new();
    let mut out = Vec::new();
    for &start in set.keys() {
        if !seen.insert(start) {
            continue;
        }
        let mut stack = vec![start];
        let (mut r0, mut r1, mut c0, mut c1) = (start.0, start.0, start.1, start.1);
        let (mut area, mut fl) = (0, 0u8);
        while let Some((r, c)) = stack.pop() {
            (r0, r1, c0, c1) = (r0.min(r), r1.max(r), c0.min(c), c1.max(c));
            area += 1;
            fl |= set[&(r, c)];
            for nr in r.saturating_sub(1)..=r + 1 {
                for nc in c.saturating_sub(1)..=c + 1 {
                    if set.contains_key(&(nr, nc)) && seen.insert((nr, nc)) {
                        stack.push((nr, nc));
                    }
                }
            }
        }
        let mut channels = Vec::new();
        if fl & flags::CVM_DEFECT != 0 {
            channels.push("cvm".to_string());
        }
        if fl & flags::POWER_DEFECT != 0 {
            channels.push("power".to_string());
        }
        out.push(Component {
            rows: [r0 as u64, r1 as u64],
            cols: [c0 as u64, c1 as u64],
            area,
            channels,
        });
    }
    out.sort_by_key(|c| (c.rows[0], c.cols[0]));
    out
}

/// The objects of `listen --json`'s top level as components, sorted alike.
fn objects(v: &Value) -> Vec<Component> {
    let pair = |x: &Value| [x[0].as_u64().unwrap(), x[1].as_u64().unwrap()];
    let mut out: Vec<Component> = v["objects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| Component {
            rows: pair(&o["rows"]),
            cols: pair(&o["cols"]),
            area: o["area"].as_u64().unwrap(),
            channels: o["channels"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| c.as_str().unwrap().to_string())
                .collect(),
        })
        .collect();
    out.sort_by_key(|c| (c.rows[0], c.cols[0]));
    out
}

/// A 9x9 map: a round spot of `power` counts centred at `(cy, cx)`.
fn spot(cy: f64, cx: f64, power: f64) -> Vec<u16> {
    let w: Vec<f64> = (0..81)
        .map(|i| {
            let (y, x) = ((i / 9) as f64, (i % 9) as f64);
            (-((y - cy).powi(2) + (x - cx).powi(2)) / 4.0).exp()
        })
        .collect();
    let sum: f64 = w.iter().sum();
    w.iter().map(|v| (v / sum * power).round() as u16).collect()
}

/// Rows and columns of the two defects of [`two_defect_scan`]: a patch
/// where the beam is deflected (distance channel), and one where it loses
/// 40 % of its light without changing shape (power channel only).
const DEFLECTED: ([usize; 2], [usize; 2]) = ([4, 6], [5, 8]);
const DIMMED: ([usize; 2], [usize; 2]) = ([12, 15], [18, 22]);

/// A noise-free scan of 20 x 30 positions, the same map everywhere but in
/// the two patches.
fn two_defect_scan(path: &Path) {
    let (rows, cols) = (20, 30);
    let inside = |(r, c): (usize, usize), (pr, pc): ([usize; 2], [usize; 2])| {
        (pr[0]..=pr[1]).contains(&r) && (pc[0]..=pc[1]).contains(&c)
    };
    let mut data = Vec::new();
    for r in 0..rows {
        for c in 0..cols {
            data.extend(if inside((r, c), DEFLECTED) {
                spot(4.0, 6.0, 40000.0)
            } else if inside((r, c), DIMMED) {
                spot(4.0, 4.0, 24000.0)
            } else {
                spot(4.0, 4.0, 40000.0)
            });
        }
    }
    dmap::npy::write_scan_u16(
        path,
        rows,
        cols,
        cvm_reference::Geometry::new(9, 9).unwrap(),
        &data,
    )
    .unwrap();
}

fn stream(scan: &Path) -> Vec<u8> {
    let out = dmap(&["stream", "--scores", s(scan)]);
    ok(&out);
    out.stdout
}

/// `dmap listen` on `bytes` with `args`: its output and the JSON document.
fn listen(tag: &str, bytes: &[u8], args: &[&str]) -> (std::process::Output, Value) {
    let input = tmp_in("listen-objects", &format!("{tag}.txt"));
    std::fs::write(&input, bytes).unwrap();
    let out = dmap(&[&["listen", "--input", s(&input), "--json"], args].concat());
    let v: Value = serde_json::from_slice(&out.stdout).expect("one JSON document");
    (out, v)
}

fn problems(v: &Value) -> Vec<String> {
    v["problems"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["what"].as_str().unwrap().to_string())
        .collect()
}

fn lines(bytes: &[u8]) -> Vec<Vec<u8>> {
    bytes
        .split_inclusive(|&b| b == b'\n')
        .map(|l| l.to_vec())
        .collect()
}

/// `body*XXXX\n` with its CRC.
fn with_crc(body: &str) -> Vec<u8> {
    format!("{body}*{:04X}\n", protocol::crc16(body.as_bytes())).into_bytes()
}

/// The stream of [`two_defect_scan`], from a scan file of the test `tag`
/// (tests run in parallel: each its own file).
fn two_defect_stream(tag: &str) -> (PathBuf, Vec<u8>) {
    let scan = tmp_in("listen-objects", &format!("{tag}.npy"));
    two_defect_scan(&scan);
    let bytes = stream(&scan);
    (scan, bytes)
}

/// Two separated defects: exactly two objects, the components of the
/// defective positions, each one position wider on each side than its
/// patch, with sizes in mm for a pitch of 250 µm and the right channel.
#[test]
fn two_defects_are_two_objects_of_the_right_extent() {
    let (_, bytes) = two_defect_stream("two");
    let (_, _, set, _) = defective(&bytes);
    let want = components(&set);
    let (out, v) = listen("two", &bytes, &["--pitch-um", "250"]);
    ok(&out);
    assert_eq!(v["problems"], serde_json::json!([]));
    assert_eq!(v["damaged"], false);
    assert_eq!(objects(&v), want);
    assert_eq!(want.len(), 2, "{want:?}");
    // The patches grown by one position on each side, found by their channel.
    for (c, (patch, channels)) in want
        .iter()
        .zip([(DEFLECTED, vec!["cvm"]), (DIMMED, vec!["power"])])
    {
        let grown = |[a, b]: [usize; 2]| [a as u64 - 1, b as u64 + 1];
        assert_eq!((c.rows, c.cols), (grown(patch.0), grown(patch.1)));
        assert_eq!(c.channels, channels);
    }
    let totals = &v["totals"];
    assert_eq!(totals["obj"], 2);
    assert_eq!(totals["unobj"], 0);
    assert_eq!(totals["defects"].as_u64().unwrap(), set.len() as u64);
    assert_eq!(totals["sat"], 0);
    for (o, patch) in v["objects"]
        .as_array()
        .unwrap()
        .iter()
        .zip([DEFLECTED, DIMMED])
    {
        let h = (patch.0[1] - patch.0[0] + 1) as f64;
        let w = (patch.1[1] - patch.1[0] + 1) as f64;
        // The corrected size is the patch's; the extent two positions more.
        assert_eq!(o["size"], serde_json::json!([h as u64, w as u64]));
        assert_eq!(o["size_mm"], serde_json::json!([h * 0.25, w * 0.25]));
        assert_eq!(
            o["extent_mm"],
            serde_json::json!([(h + 2.0) * 0.25, (w + 2.0) * 0.25])
        );
        assert!(o["peak"].as_f64().unwrap() >= 1.0, "{o}");
        let (at, c) = (&o["peak_at"], &o["centroid"]);
        let rows = o["rows"].as_array().unwrap();
        let cols = o["cols"].as_array().unwrap();
        let within =
            |x: f64, r: &[Value]| r[0].as_f64().unwrap() <= x && x <= r[1].as_f64().unwrap();
        assert!(within(at[0].as_f64().unwrap(), rows) && within(at[1].as_f64().unwrap(), cols));
        assert!(within(c[0].as_f64().unwrap(), rows) && within(c[1].as_f64().unwrap(), cols));
        // A symmetric ring of equal strengths: the centroid is the patch's centre.
        let centre = |p: [usize; 2]| (p[0] + p[1]) as f64 / 2.0;
        assert!(
            (c[0].as_f64().unwrap() - centre(patch.0)).abs() < 0.5,
            "{o}"
        );
        assert!(
            (c[1].as_f64().unwrap() - centre(patch.1)).abs() < 0.5,
            "{o}"
        );
    }
    // One scan: the scan's own entry carries the same objects and totals.
    assert_eq!(v["scans"].as_array().unwrap().len(), 1);
    assert_eq!(v["scans"][0]["objects"], v["objects"]);
    assert_eq!(v["scans"][0]["totals"], v["totals"]);
    assert_eq!(v["scans"][0]["header"]["version"], protocol::VERSION);
    // Without a pitch, sizes in positions only.
    let (_, v) = listen("two-no-pitch", &bytes, &[]);
    assert!(v["objects"][0].get("size_mm").is_none());
    assert_eq!(v["objects"][0]["size"], serde_json::json!([3, 4]));
}

/// The human report: one line per object with its sizes in positions and
/// mm, its peak as a ratio, its centroid and channels.
#[test]
fn the_report_lists_each_object() {
    let (_, bytes) = two_defect_stream("report");
    let input = tmp_in("listen-objects", "report.txt");
    std::fs::write(&input, &bytes).unwrap();
    let out = dmap(&["listen", "--input", s(&input), "--pitch-um", "250"]);
    ok(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("  objects: 2\n"), "{text}");
    assert!(
        text.contains(
            "object 0: rows 3-7, cols 4-9, area 24, extent 5x6 positions (1.25 x 1.50 mm), defect 3x4 positions (0.75 x 1.00 mm); peak "
        ),
        "{text}"
    );
    let second = text
        .lines()
        .find(|l| l.trim_start().starts_with("object 1:"))
        .expect("second object");
    assert!(
        second.contains(
            "extent 6x7 positions (1.50 x 1.75 mm), defect 4x5 positions (1.00 x 1.25 mm)"
        ),
        "{second}"
    );
    assert!(second.ends_with("channels power"), "{second}");
    assert!(second.contains("x threshold at row "), "{second}");
    assert!(text.contains("power threshold 0.1000 (contrast)"), "{text}");
    // Without --pitch-um: positions only.
    let out = dmap(&["listen", "--input", s(&input)]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("extent 5x6 positions, defect 3x4 positions;"),
        "{text}"
    );
    assert!(!text.contains(" mm"), "{text}");
    for bad in ["0", "-1", "nan", "inf"] {
        let out = dmap(&["listen", "--input", s(&input), "--pitch-um", bad]);
        assert_eq!(out.status.code(), Some(2), "--pitch-um {bad}");
    }
}

/// A simulated part (`dmap simulate --preset prototype`, two rough
/// patches, with noise): the objects are the components of the positions
/// the score lines mark, and each patch of the truth mask lies in one.
#[test]
fn simulated_part_objects_are_the_components_of_its_defects() {
    let scan = tmp_in("listen-objects", "proto.npy");
    let truth = tmp_in("listen-objects", "proto-truth.npy");
    ok(&dmap(&[
        "simulate",
        "--preset",
        "prototype",
        "--threads",
        "1",
        "-o",
        s(&scan),
        "--truth",
        s(&truth),
    ]));
    let bytes = stream(&scan);
    let (_, cols, set, _) = defective(&bytes);
    let want = components(&set);
    let (out, v) = listen("proto", &bytes, &["--pitch-um", "334"]);
    ok(&out);
    assert_eq!(objects(&v), want);
    assert_eq!(v["totals"]["obj"].as_u64().unwrap(), want.len() as u64);
    // Every truth position lies in the box of some object.
    let mask = dmap::npy::read_mask(&truth).unwrap();
    assert_eq!(mask.cols, cols);
    let boxes: Vec<&Component> = want.iter().filter(|c| c.area > 4).collect();
    assert_eq!(boxes.len(), 2, "{want:?}");
    for (i, _) in mask.data.iter().enumerate().filter(|(_, t)| **t) {
        let (r, c) = ((i / cols) as u64, (i % cols) as u64);
        assert!(
            boxes
                .iter()
                .any(|b| (b.rows[0]..=b.rows[1]).contains(&r)
                    && (b.cols[0]..=b.cols[1]).contains(&c)),
            "truth position ({r}, {c}) in no object: {want:?}"
        );
    }
}

/// A damaged `O` line is a line error, and the end line's `obj` then
/// counts one object more than arrived: both are reported and the run
/// fails.
#[test]
fn a_damaged_object_line_is_reported() {
    let (_, bytes) = two_defect_stream("damaged");
    let mut ls = lines(&bytes);
    let k = ls.iter().position(|l| l.starts_with(b"O,")).unwrap();
    let at = ls[k].len() / 2;
    ls[k][at] = if ls[k][at] == b'7' { b'8' } else { b'7' };
    let (out, v) = listen("damaged-o", &ls.concat(), &[]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(v["damaged"], true);
    assert_eq!(v["line_errors"][0]["line"], k + 1);
    let p = problems(&v);
    assert!(p.iter().any(|w| w.contains("checksum mismatch")), "{p:?}");
    assert!(
        p.iter()
            .any(|w| w == "end line counts 2 object(s), 1 object line(s) arrived"),
        "{p:?}"
    );
    assert_eq!(v["objects"].as_array().unwrap().len(), 1);
}

/// An end line whose `obj` does not match the `O` lines is reported.
#[test]
fn an_end_line_object_count_mismatch_is_reported() {
    let (_, bytes) = two_defect_stream("mismatch");
    let mut ls = lines(&bytes);
    let e = ls.len() - 1;
    let text = String::from_utf8(ls[e].clone()).unwrap();
    let body = text
        .split('*')
        .next()
        .unwrap()
        .replace(",obj=2,", ",obj=3,");
    ls[e] = with_crc(&body);
    let (out, v) = listen("obj-mismatch", &ls.concat(), &[]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(v["line_errors"], serde_json::json!([]));
    let p = problems(&v);
    assert_eq!(p, ["end line counts 3 object(s), 2 object line(s) arrived"]);
    assert_eq!(v["scans"][0]["problems"][0]["line"], e + 1);
    // An `O` line's area changed (with a valid CRC): the areas and `unobj`
    // no longer add up to `defects`.
    let mut ls = lines(&bytes);
    let k = ls.iter().position(|l| l.starts_with(b"O,")).unwrap();
    let text = String::from_utf8(ls[k].clone()).unwrap();
    let mut f: Vec<String> = text
        .split('*')
        .next()
        .unwrap()
        .split(',')
        .map(String::from)
        .collect();
    let area: u64 = f[6].parse().unwrap();
    f[6] = (area - 1).to_string();
    ls[k] = with_crc(&f.join(","));
    let (_, v) = listen("area-mismatch", &ls.concat(), &[]);
    let p = problems(&v);
    assert!(
        p.iter()
            .any(|w| w.starts_with("objects cover ") && w.contains("but the end line counts")),
        "{p:?}"
    );
}

/// `O` lines out of their place: too early (before the row that closes
/// them), twice, ids going down among the objects one row closes, an
/// object of the last row followed by another row, impossible fields.
#[test]
fn misplaced_and_impossible_object_lines_are_reported() {
    let (_, bytes) = two_defect_stream("misplaced");
    let ls = lines(&bytes);
    let obj: Vec<usize> = ls
        .iter()
        .enumerate()
        .filter(|(_, l)| l.starts_with(b"O,"))
        .map(|(i, _)| i)
        .collect();
    assert_eq!(obj.len(), 2);
    let run = |tag: &str, v: Vec<Vec<u8>>| {
        let (out, json) = listen(tag, &v.concat(), &[]);
        assert_eq!(out.status.code(), Some(1), "{tag}");
        problems(&json)
    };
    // The first object's line right after the first row line.
    let mut v = ls.clone();
    let o = v.remove(obj[0]);
    v.insert(2, o);
    let p = run("early", v);
    assert!(
        p.iter()
            .any(|w| w.contains("object 0 ends in row 7, after the last row reported (0)")),
        "{p:?}"
    );
    // Twice.
    let mut v = ls.clone();
    v.insert(obj[0] + 1, ls[obj[0]].clone());
    let p = run("twice", v);
    assert!(
        p.iter().any(|w| w == "object 0 reported twice in the scan"),
        "{p:?}"
    );
    // Two objects closed by one row, in decreasing id: object 1's line
    // moved right after object 0's, as if the same row had closed both.
    let mut v = ls.clone();
    let o1 = v.remove(obj[1]);
    let mut o1_text = String::from_utf8(o1).unwrap();
    // Its last row made that of object 0 so that one row closes both.
    let f0: Vec<String> = String::from_utf8(ls[obj[0]].clone())
        .unwrap()
        .split('*')
        .next()
        .unwrap()
        .split(',')
        .map(String::from)
        .collect();
    let mut f1: Vec<String> = o1_text
        .split('*')
        .next()
        .unwrap()
        .split(',')
        .map(String::from)
        .collect();
    f1[1] = "1".into();
    f1[2] = f0[2].clone();
    f1[3] = f0[3].clone();
    o1_text = String::from_utf8(with_crc(&f1.join(","))).unwrap();
    let mut f0b = f0.clone();
    f0b[1] = "5".into();
    v[obj[0]] = with_crc(&f0b.join(","));
    v.insert(obj[0] + 1, o1_text.into_bytes());
    let p = run("ids-down", v);
    assert!(
        p.iter()
            .any(|w| w.contains("not in increasing id (1 after 5)")),
        "{p:?}"
    );
    // An object ending in the last row reported, followed by a row line.
    let r_after = ls
        .iter()
        .enumerate()
        .skip(obj[0])
        .find(|(_, l)| l.starts_with(b"R,"))
        .map(|(i, _)| i)
        .unwrap();
    let mut v = ls.clone();
    let o = v.remove(obj[0]);
    // Right after the `S` lines of the object's last row.
    let row1 = f0[3].clone();
    let last_of_row = v
        .iter()
        .rposition(|l| l.starts_with(format!("S,{row1},").as_bytes()))
        .unwrap();
    v.insert(last_of_row + 1, o);
    assert!(r_after > last_of_row);
    let p = run("closed-early", v);
    assert!(
        p.iter().any(|w| w.contains(&format!(
            "object 0 ends in row {row1} but row {}'s line follows it",
            row1.parse::<u32>().unwrap() + 1
        ))),
        "{p:?}"
    );
    // A peak outside the box, past the scan's columns (valid CRCs): the
    // line is kept and the contradiction reported; no channel, a field
    // out of its range, makes the line malformed.
    for (tag, field, value, needle) in [
        (
            "peak-outside",
            "peak_row",
            "0",
            "object 0: peak_row 0 peak_col",
        ),
        (
            "no-channel",
            "channels",
            "0",
            "field outside its range: channels: a sum of 16, 32 and 64",
        ),
        ("past-cols", "col1", "30", "object 0: columns"),
    ] {
        let mut v = ls.clone();
        let mut f = f0.clone();
        f[cvm_core::protocol::layout::place(b'O', field).unwrap()] = value.into();
        v[obj[0]] = with_crc(&f.join(","));
        let p = run(tag, v);
        assert!(p.iter().any(|w| w.starts_with(needle)), "{tag}: {p:?}");
    }
}

/// `--power-output`: the power magnitudes of the score lines, as contrasts,
/// in the layout of the `-o` image, which `dmap eval` and `dmap render`
/// read.
#[test]
fn power_output_is_the_power_image() {
    let (_, bytes) = two_defect_stream("power");
    let (rows, cols, _, power) = defective(&bytes);
    let input = tmp_in("listen-objects", "power.txt");
    std::fs::write(&input, &bytes).unwrap();
    let (img, pimg) = (
        tmp_in("listen-objects", "mag.npy"),
        tmp_in("listen-objects", "power.npy"),
    );
    ok(&dmap(&[
        "listen",
        "--input",
        s(&input),
        "-o",
        s(&img),
        "--power-output",
        s(&pimg),
    ]));
    let g = dmap::npy::read_gradient(&pimg).unwrap();
    assert_eq!((g.rows, g.cols), (rows, cols));
    let got: Vec<f64> = g.data.chunks(3).map(|p| p[2]).collect();
    assert_eq!(got, power);
    assert!(g.data.chunks(3).all(|p| p[0].is_nan() && p[1].is_nan()));
    // The dimmed patch's edge: 40 % less light, contrast 0.25 and more.
    assert!(power.iter().any(|&p| p >= 0.25));
    let m = dmap::npy::read_gradient(&img).unwrap();
    assert_ne!(m.data.chunks(3).map(|p| p[2]).collect::<Vec<_>>(), got);
    // The two images may not share a file.
    let out = dmap(&[
        "listen",
        "--input",
        s(&input),
        "-o",
        s(&img),
        "--power-output",
        s(&img),
    ]);
    assert_eq!(out.status.code(), Some(1));
}
