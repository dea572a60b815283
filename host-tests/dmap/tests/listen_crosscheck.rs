//! `dmap listen`'s cross-checks (docs/protocol.md, "What a decoder
//! checks"): lines with a valid CRC but content that other lines of the
//! scan contradict. Each test forges one field of one line of a real
//! stream (`dmap stream`) and expects the problem to name that line and
//! field; the stream as written has none.

use crate::common;

use common::{dmap, ok, s, tmp_in};
use cvm_core::protocol;
use serde_json::Value;

const TAG: &str = "listen-crosscheck";

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

/// A noise-free 14 x 24 scan with a deflecting patch (rows 3-5, columns
/// 4-6) and a dimming one (rows 8-10, columns 14-17): two objects, one
/// for each channel, closed by different rows.
fn scan(name: &str) -> std::path::PathBuf {
    let (rows, cols) = (14, 24);
    let mut data = Vec::new();
    for r in 0..rows {
        for c in 0..cols {
            data.extend(if (3..=5).contains(&r) && (4..=6).contains(&c) {
                spot(4.0, 6.0, 40000.0)
            } else if (8..=10).contains(&r) && (14..=17).contains(&c) {
                spot(4.0, 4.0, 24000.0)
            } else {
                spot(4.0, 4.0, 40000.0)
            });
        }
    }
    let path = tmp_in(TAG, &format!("{name}.npy"));
    let g = cvm_reference::Geometry::new(9, 9).unwrap();
    dmap::npy::write_scan_u16(&path, rows, cols, g, &data).unwrap();
    path
}

/// The stream of [`scan`] with `args` for `dmap stream`, as lines.
fn stream(name: &str, args: &[&str]) -> Vec<String> {
    let out = dmap(&[&["stream", s(&scan(name))], args].concat());
    ok(&out);
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

/// With scores (every position's flags), and without (the defect lines
/// list every defect: `dcap` above any row's count).
const WITH_SCORES: &[&str] = &["--scores"];
const DEFECT_LINES: &[&str] = &["--max-defect-lines", "30"];

/// `dmap listen --json` on `lines`: exit status and document.
fn listen(name: &str, lines: &[String]) -> (Option<i32>, Value) {
    let input = tmp_in(TAG, &format!("{name}.txt"));
    std::fs::write(&input, lines.join("\n") + "\n").unwrap();
    let out = dmap(&["listen", "--input", s(&input), "--json"]);
    (
        out.status.code(),
        serde_json::from_slice(&out.stdout).expect("one JSON document"),
    )
}

/// (line, kind, what) of every problem.
fn problems(v: &Value) -> Vec<(u64, String, String)> {
    v["problems"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p["line"].as_u64().unwrap(),
                p["kind"].as_str().unwrap().to_string(),
                p["what"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

/// The line `l` with field `i` (0 = the type) set to `v`, sealed again.
fn with_field(l: &str, i: usize, v: &str) -> String {
    let body = l.split('*').next().unwrap();
    let mut f: Vec<&str> = body.split(',').collect();
    f[i] = v;
    let body = f.join(",");
    format!("{body}*{:04X}", protocol::crc16(body.as_bytes()))
}

/// The end line with `key` set to `v`, sealed again.
fn with_total(l: &str, key: &str, v: &str) -> String {
    let body = l.split('*').next().unwrap();
    let f: Vec<String> = body
        .split(',')
        .map(|f| match f.split_once('=') {
            Some((k, _)) if k == key => format!("{k}={v}"),
            _ => f.to_string(),
        })
        .collect();
    let body = f.join(",");
    format!("{body}*{:04X}", protocol::crc16(body.as_bytes()))
}

fn field(l: &str, i: usize) -> u64 {
    l.split('*')
        .next()
        .unwrap()
        .split(',')
        .nth(i)
        .unwrap()
        .parse()
        .unwrap()
}

fn index_of(lines: &[String], prefix: &str) -> usize {
    lines.iter().position(|l| l.starts_with(prefix)).unwrap()
}

/// The stream as written: two objects, no problem at all, with scores or
/// with every defect listed.
#[test]
fn the_streams_as_written_pass_every_cross_check() {
    for (name, args) in [("clean-s", WITH_SCORES), ("clean-d", DEFECT_LINES)] {
        let ls = stream(name, args);
        let (code, v) = listen(name, &ls);
        assert_eq!(code, Some(0), "{name}: {v}");
        assert_eq!(problems(&v), vec![], "{name}");
        assert_eq!(v["objects"].as_array().unwrap().len(), 2, "{name}");
        assert_eq!(v["objects"][0]["channels"], serde_json::json!(["cvm"]));
        assert_eq!(v["objects"][1]["channels"], serde_json::json!(["power"]));
    }
}

/// Every field of an `O` line forged by one (a valid CRC): flagged, on
/// that line, naming the field, in a stream with `S` lines and in one
/// with `D` lines only.
#[test]
fn a_forged_object_field_is_named() {
    // O,id,row0,row1,col0,col1,area,peak,peak_row,peak_col,peak_mag,
    // peak_power,peak_spread,centroid_row_q8,centroid_col_q8,channels
    let forged = [
        (2, "row0", -1),
        (3, "row1", 1),
        (4, "col0", -1),
        (5, "col1", 1),
        (6, "area", 1),
        (6, "area", -1),
        (7, "peak", 1),
        (7, "peak", -1),
        (10, "peak_mag", 1),
        (11, "peak_power", 1),
        (12, "peak_spread", 1),
        (13, "centroid_row_q8", 1),
        (13, "centroid_row_q8", -1),
        (14, "centroid_col_q8", 1),
    ];
    for (name, args) in [("o-s", WITH_SCORES), ("o-d", DEFECT_LINES)] {
        let ls = stream(name, args);
        let k = index_of(&ls, "O,");
        for (i, what, delta) in forged {
            let mut v = ls.clone();
            let was = field(&v[k], i);
            let now = (was as i64 + delta).to_string();
            v[k] = with_field(&v[k], i, &now);
            let (code, json) = listen(&format!("{name}-{what}{delta}"), &v);
            assert_eq!(code, Some(1), "{name} {what}{delta}");
            let p = problems(&json);
            let want = format!("{what} {now} (its positions make {was})");
            assert!(
                p.iter().any(|(l, kind, w)| *l == k as u64 + 1
                    && kind == "cross-check"
                    && w.starts_with("O line of object 0: ")
                    && w.contains(&want)),
                "{name} {what}{delta}: {p:?}"
            );
        }
        // The peak moved to another position of the object (its box):
        // its values no longer those of the position.
        let mut v = ls.clone();
        let col = field(&v[k], 9);
        v[k] = with_field(&v[k], 9, &(col + 1).to_string());
        let (_, json) = listen(&format!("{name}-peak-col"), &v);
        let p = problems(&json);
        assert!(
            p.iter().any(|(l, kind, w)| *l == k as u64 + 1
                && kind == "cross-check"
                && w.starts_with("O line of object 0: ")
                && (w.contains("peak_col") || w.contains("is no defective position"))),
            "{name} peak_col: {p:?}"
        );
        // Channels: the power channel added to the distance's object.
        let mut v = ls.clone();
        v[k] = with_field(&v[k], 15, "48");
        let (_, json) = listen(&format!("{name}-channels"), &v);
        assert!(
            problems(&json)
                .iter()
                .any(|(_, _, w)| w == "O line of object 0: channels 48 (its positions make 16)"),
            "{name}: {:?}",
            problems(&json)
        );
    }
}

/// An object line missing: the end line's count says so, and its
/// positions are in no object line; two objects' ids swapped: each line
/// alone is in order, but the ids no longer follow the order in which
/// the objects open.
#[test]
fn a_lost_object_and_swapped_ids_are_found() {
    let ls = stream("lost", WITH_SCORES);
    let k = index_of(&ls, "O,");
    let mut v = ls.clone();
    v.remove(k);
    let (_, json) = listen("lost-o", &v);
    let p = problems(&json);
    assert!(
        p.iter().any(|(_, kind, w)| kind == "missing"
            && w == "end line counts 2 object(s), 1 object line(s) arrived"),
        "{p:?}"
    );
    let objs: Vec<usize> = (0..ls.len()).filter(|&i| ls[i].starts_with("O,")).collect();
    let mut v = ls.clone();
    v[objs[0]] = with_field(&v[objs[0]], 1, "1");
    v[objs[1]] = with_field(&v[objs[1]], 1, "0");
    let (code, json) = listen("swapped-ids", &v);
    assert_eq!(code, Some(1));
    let p = problems(&json);
    assert!(
        p.iter().any(|(l, kind, w)| *l == objs[1] as u64 + 1
            && kind == "cross-check"
            && w.starts_with(
                "O line of object 0: its id is below that of object 1, which opens earlier"
            )),
        "{p:?}"
    );
}

/// A `D` line whose strength, magnitude or flags its thresholds or its
/// position's score contradict.
#[test]
fn a_forged_defect_line_is_named() {
    let ls = stream("d", &["--scores", "--max-defect-lines", "30"]);
    let k = index_of(&ls, "D,");
    let (row, col) = (field(&ls[k], 1), field(&ls[k], 2));
    let at = format!("D line of row {row} column {col}");
    // D,row,col,mag,pmag,smag,strength,flags
    let strength = field(&ls[k], 6);
    let mut v = ls.clone();
    v[k] = with_field(&v[k], 6, &(strength + 1).to_string());
    let (_, json) = listen("d-strength", &v);
    let p = problems(&json);
    let want = format!(
        "{at}: strength {}, but its magnitudes and the thresholds make {strength}",
        strength + 1
    );
    assert!(
        p.iter()
            .any(|(l, kind, w)| *l == k as u64 + 1 && kind == "field" && *w == want),
        "{p:?}"
    );
    // A magnitude one step up: its strength follows, so only the score
    // line tells.
    let mag = field(&ls[k], 3);
    let mut v = ls.clone();
    v[k] = with_field(&v[k], 3, &(mag + 1).to_string());
    let (_, json) = listen("d-mag", &v);
    let p = problems(&json);
    assert!(
        p.iter().any(|(l, kind, w)| *l == k as u64 + 1
            && kind == "cross-check"
            && w.starts_with(&format!("{at}: mag {} (its S line: {mag})", mag + 1))),
        "{p:?}"
    );
    // Flags claiming the power channel too.
    let flags = field(&ls[k], 7);
    let mut v = ls.clone();
    v[k] = with_field(&v[k], 7, &(flags | 32).to_string());
    let (_, json) = listen("d-flags", &v);
    let p = problems(&json);
    assert!(
        p.iter().any(|(l, kind, w)| *l == k as u64 + 1
            && kind == "field"
            && w.starts_with(&format!("{at}: flags {} say cvm+power, but ", flags | 32))),
        "{p:?}"
    );
}

/// A row line whose summary its score lines contradict, a score line whose
/// flags its thresholds contradict, end-line totals that contradict one
/// another or the row lines.
#[test]
fn forged_rows_scores_and_totals_are_named() {
    let ls = stream("rse", WITH_SCORES);
    // R,row,max,argmax,pmax,pargmax,defects,listed,no_data,dark,saturated
    let k = (0..ls.len())
        .find(|&i| ls[i].starts_with("R,") && field(&ls[i], 6) > 0)
        .unwrap();
    let row = field(&ls[k], 1);
    let max = field(&ls[k], 2);
    let mut v = ls.clone();
    v[k] = with_field(&v[k], 2, &(max - 1).to_string());
    let (_, json) = listen("r-max", &v);
    let p = problems(&json);
    assert!(
        p.iter().any(|(l, kind, w)| *l == k as u64 + 1
            && kind == "cross-check"
            && *w
                == format!(
                    "R line of row {row}: max {} (the S lines make {max})",
                    max - 1
                )),
        "{p:?}"
    );
    // A score line's position with CVM_DEFECT cleared (its magnitude
    // still above the threshold): the line contradicts the header.
    let sk = (0..ls.len())
        .find(|&i| {
            ls[i].starts_with("S,") && {
                let chars = ls[i].split('*').next().unwrap().split(',').nth(3).unwrap();
                chars
                    .as_bytes()
                    .chunks(protocol::SCORE_CHARS)
                    .any(|c| protocol::decode_score(c).unwrap().flags & 16 != 0)
            }
        })
        .unwrap();
    let chars = ls[sk].split('*').next().unwrap().split(',').nth(3).unwrap();
    let mut b = chars.as_bytes().to_vec();
    let at = b
        .chunks(protocol::SCORE_CHARS)
        .position(|c| protocol::decode_score(c).unwrap().flags == 16)
        .unwrap();
    // The first digit holds flag bits 1 to 6 (flags 16: `I`).
    b[at * protocol::SCORE_CHARS] = b'A'; // flags 0
    let mut v = ls.clone();
    v[sk] = with_field(&v[sk], 3, std::str::from_utf8(&b).unwrap());
    let (_, json) = listen("s-flags", &v);
    let p = problems(&json);
    assert!(
        p.iter().any(|(l, kind, w)| *l == sk as u64 + 1
            && kind == "field"
            && w.contains("position(s) whose flags contradict the thresholds")
            && w.contains("flags 0 say none, but mag ")),
        "{p:?}"
    );
    // The end line: one more position missing (frames + missing no
    // longer rows x columns, and the row lines say otherwise).
    let e = ls.len() - 1;
    let mut v = ls.clone();
    v[e] = with_total(&v[e], "missing", "1");
    let (_, json) = listen("e-missing", &v);
    let p = problems(&json);
    assert!(
        p.iter().any(|(l, kind, w)| *l == e as u64 + 1
            && kind == "field"
            && w == "end line: frames 336 and missing 1 do not add up to rows 14 x 24 columns = 336"),
        "{p:?}"
    );
    assert!(
        p.iter().any(|(_, kind, w)| kind == "cross-check"
            && w == "end line: missing 1, but the R lines' no_data add up to 0"),
        "{p:?}"
    );
    let mut v = ls.clone();
    v[e] = with_total(&v[e], "clipped", "1");
    let (_, json) = listen("e-clipped", &v);
    let p = problems(&json);
    assert!(
        p.iter().any(|(_, kind, w)| kind == "cross-check"
            && w == "end line: clipped 1, but the S lines flag 0 position(s) CLIPPED"),
        "{p:?}"
    );
}

/// A score line the firmware dropped and counted in `dropped` is no
/// damage; one lost otherwise is.
#[test]
fn dropped_score_lines_are_allowed_lost_ones_are_not() {
    let ls = stream("dropped", WITH_SCORES);
    let k = index_of(&ls, "S,");
    let e = ls.len() - 1;
    let mut v = ls.clone();
    v[e] = with_total(&v[e], "dropped", "1");
    v.remove(k);
    let (code, json) = listen("dropped-counted", &v);
    assert_eq!(code, Some(0), "{json}");
    assert_eq!(problems(&json), vec![]);
    let mut v = ls.clone();
    v.remove(k);
    let (code, json) = listen("dropped-lost", &v);
    assert_eq!(code, Some(1));
    let p = problems(&json);
    assert!(
        p.iter().any(|(_, kind, w)| kind == "missing"
            && w == "1 of 28 score line(s) missing, but the end line counts 0 dropped"),
        "{p:?}"
    );
}
