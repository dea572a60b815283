//! `dmap listen --json` on the streams of the conformance vectors
//! (docs/protocol/vectors): it finds in each exactly the kinds of damage
//! the vectors' index names and exits 1 exactly when there are some, and
//! reports each line the decoder refuses at its number; of a
//! whole stream it reports what the lines carry, as their decodes
//! (`NAME.jsonl`, checked against the lines in `conformance.rs`) say: each
//! scan's header, rows, defects, objects, totals and verdict, and the
//! replies; and of a vector that changes one field it names that field.

use crate::common;

use common::{dmap, s, vectors_dir as dir, vectors_index as index};
use serde_json::{Value, json};
use std::collections::BTreeSet;

/// `dmap listen --json` on vector `name`: its document and exit status.
fn listen(name: &str) -> (Value, Option<i32>) {
    let input = dir().join(format!("{name}.txt"));
    let out = dmap(&["listen", "--input", s(&input), "--json"]);
    let doc = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{name}: no JSON document: {e}"));
    (doc, out.status.code())
}

/// The decoded records of vector `name`'s lines (errors and empty lines left out).
fn records(name: &str) -> Vec<Value> {
    std::fs::read_to_string(dir().join(format!("{name}.jsonl")))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).unwrap())
        .filter(|d| d["type"].is_string())
        .collect()
}

/// `x` as the report's JSON carries it: written as the shortest text that
/// reads back as `x`, then read as the report is (serde_json may read a
/// float's text one unit in the last place off; the texts are compared).
fn float(x: f64) -> Value {
    serde_json::from_str(&serde_json::to_string(&x).unwrap()).unwrap()
}

fn channel_names(bits: u64) -> Value {
    let names: Vec<&str> = [(16, "cvm"), (32, "power"), (64, "spread")]
        .iter()
        .filter(|(b, _)| bits & b != 0)
        .map(|(_, n)| *n)
        .collect();
    json!(names)
}

#[test]
fn listen_finds_the_damage_each_vector_names() {
    let all = index();
    assert!(all.len() > 80, "{}", all.len());
    for e in all {
        let name = e["name"].as_str().unwrap();
        let (doc, code) = listen(name);
        let want: BTreeSet<&str> = e["damage"]
            .as_array()
            .unwrap()
            .iter()
            .map(|k| k.as_str().unwrap())
            .collect();
        let got: BTreeSet<&str> = doc["problems"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["kind"].as_str().unwrap())
            .collect();
        assert_eq!(got, want, "{name}");
        assert_eq!(doc["damaged"], json!(!want.is_empty()), "{name}");
        assert_eq!(code, Some(i32::from(!want.is_empty())), "{name}");
        check_line_errors(name, &doc);
    }
}

/// The line errors `dmap listen` reports against the lines' decodes: a
/// line the decoder refuses is reported at its number, as the decode's
/// kind or `cut` (a whole line found inside it); a line reported with a
/// decoder's kind is a line refused so.
fn check_line_errors(name: &str, doc: &Value) {
    let decoded: Vec<Value> = std::fs::read_to_string(dir().join(format!("{name}.jsonl")))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let reported: Vec<(usize, &str)> = doc["line_errors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            (
                e["line"].as_u64().unwrap() as usize,
                e["kind"].as_str().unwrap(),
            )
        })
        .collect();
    let decoder_kinds = [
        "no-checksum",
        "checksum",
        "malformed",
        "range",
        "unknown-type",
        "too-long",
    ];
    for (i, d) in decoded.iter().enumerate() {
        let Some(kind) = d["error"].as_str() else {
            continue;
        };
        let line = i + 1;
        assert!(
            reported
                .iter()
                .any(|&(l, k)| l == line && (k == kind || k == "cut")),
            "{name}: line {line}, refused as {kind}, not reported: {reported:?}"
        );
    }
    for &(line, kind) in &reported {
        if decoder_kinds.contains(&kind) {
            assert_eq!(
                decoded[line - 1]["error"].as_str(),
                Some(kind),
                "{name}: line {line} reported {kind}"
            );
        }
    }
}

/// The report's header of a scan against its `H` record.
fn check_header(at: &str, h: &Value, f: &Value) {
    let q = q_of(f);
    let pairs = [
        ("version", "v"),
        ("firmware", "fw"),
        ("geometry", "j"),
        ("cols", "cols"),
        ("kernels", "k"),
        ("kernel_size", "b"),
        ("weights", "w"),
        ("normalise", "norm"),
        ("full_scale", "fs"),
        ("q", "q"),
        ("scores", "scores"),
        ("max_defect_lines", "dcap"),
        ("reset_cause", "rst"),
        ("boots", "boots"),
        ("rows", "rows"),
        ("sources", "src"),
        ("store", "store"),
    ];
    for (report, field) in pairs {
        assert_eq!(h[report], f[field], "{at}: header {report}");
    }
    let thr = f["thr"].as_f64().unwrap();
    assert_eq!(h["threshold"], float(thr / 2f64.powi(q)), "{at}");
    let (pthr, sthr) = (f["pthr"].as_u64().unwrap(), f["sthr"].as_u64().unwrap());
    // A channel that is off (its threshold above every magnitude): null.
    let off = |v: u64, max: u64, one: f64| {
        if v <= max {
            float(v as f64 / one)
        } else {
            Value::Null
        }
    };
    assert_eq!(h["power_threshold"], off(pthr, 46340, 32768.0), "{at}");
    assert_eq!(h["spread_threshold"], off(sthr, 92680, 65536.0), "{at}");
}

fn q_of(header: &Value) -> i32 {
    header["q"].as_i64().unwrap() as i32
}

/// The report's object against its `O` record (`units`: `2^q`).
fn check_object(at: &str, o: &Value, f: &Value, units: f64) {
    let n = |k: &str| f[k].as_u64().unwrap();
    let want = json!({
        "id": n("id"),
        "rows": [n("row0"), n("row1")],
        "cols": [n("col0"), n("col1")],
        "area": n("area"),
        "peak_at": [n("peak_row"), n("peak_col")],
        "channels": channel_names(n("channels")),
    });
    for (k, v) in want.as_object().unwrap() {
        assert_eq!(&o[k], v, "{at}: object {k}");
    }
    assert_eq!(o["peak"], float(n("peak") as f64 / 65536.0), "{at}");
    let centroid = [
        float(n("centroid_row_q8") as f64 / 256.0),
        float(n("centroid_col_q8") as f64 / 256.0),
    ];
    assert_eq!(o["centroid"], json!(centroid), "{at}: centroid");
    for (report, field, one) in [
        ("peak_magnitude", "peak_mag", units),
        ("peak_power", "peak_power", 32768.0),
        ("peak_spread", "peak_spread", 65536.0),
    ] {
        let want = float(n(field) as f64 / one);
        assert_eq!(o[report], want, "{at}: object {report}");
    }
}

#[test]
fn listen_reports_what_the_lines_of_a_whole_stream_carry() {
    let mut scans = 0;
    for e in index() {
        if !e["damage"].as_array().unwrap().is_empty() {
            continue;
        }
        let name = e["name"].as_str().unwrap();
        let (doc, _) = listen(name);
        let recs = records(name);
        let replies = recs.iter().filter(|r| r["type"] == "A").count();
        assert_eq!(doc["replies"], json!(replies), "{name}");
        // The records of each scan: from its H record to its E record.
        let mut per_scan: Vec<Vec<&Value>> = Vec::new();
        for r in recs.iter().filter(|r| r["type"] != "A") {
            if r["type"] == "H" {
                per_scan.push(Vec::new());
            }
            per_scan.last_mut().expect("a header first").push(r);
        }
        let got = doc["scans"].as_array().unwrap();
        assert_eq!(got.len(), per_scan.len(), "{name}: scans");
        for (k, (scan, recs)) in got.iter().zip(&per_scan).enumerate() {
            let at = format!("{name} scan {}", k + 1);
            let of = |t: &str| -> Vec<&Value> {
                recs.iter()
                    .filter(|r| r["type"] == t)
                    .map(|r| &r["fields"])
                    .collect()
            };
            check_header(&at, &scan["header"], of("H")[0]);
            let rows: BTreeSet<u64> = of("R").iter().map(|f| f["row"].as_u64().unwrap()).collect();
            assert_eq!(scan["rows"], json!(rows.len()), "{at}: rows");
            let end = of("E")[0];
            assert_eq!(&scan["totals"], end, "{at}: totals");
            assert_eq!(scan["verdict"], end["verdict"], "{at}: verdict");
            let units = 2f64.powi(q_of(of("H")[0]));
            let defects: Vec<Value> = of("D")
                .iter()
                .map(|f| {
                    let n = |k: &str| f[k].as_u64().unwrap();
                    let x = |k: &str, one: f64| float(n(k) as f64 / one);
                    json!([
                        n("row"),
                        n("col"),
                        n("flags"),
                        x("strength", 65536.0),
                        x("mag", units),
                        x("pmag", 32768.0),
                        x("smag", 65536.0),
                        channel_names(n("flags")),
                    ])
                })
                .collect();
            let reported: Vec<Value> = scan["defects"]
                .as_array()
                .unwrap()
                .iter()
                .map(|d| {
                    json!([
                        d["row"],
                        d["col"],
                        d["flags"],
                        d["strength"],
                        d["score"],
                        d["power"],
                        d["spread"],
                        d["channels"],
                    ])
                })
                .collect();
            assert_eq!(reported, defects, "{at}: defects");
            let objects = of("O");
            let reported = scan["objects"].as_array().unwrap();
            assert_eq!(reported.len(), objects.len(), "{at}: objects");
            for (o, f) in reported.iter().zip(objects) {
                check_object(&at, o, f, units);
            }
            assert_eq!(scan["problems"], json!([]), "{at}");
            scans += 1;
        }
        if let Some(last) = got.last() {
            assert_eq!(doc["verdict"], last["verdict"], "{name}");
            assert_eq!(doc["totals"], last["totals"], "{name}");
            assert_eq!(doc["objects"], last["objects"], "{name}");
        }
    }
    assert!(scans >= 20, "{scans}");
}

/// Every vector that changes one field (`index.json`'s `changes`,
/// `TYPE.name`): `dmap listen` names that field in what it reports (a line
/// refused for the field's range, a field or cross-check problem).
#[test]
fn listen_names_the_field_a_one_field_vector_changes() {
    let mut checked = 0;
    for v in common::one_field_vectors() {
        let (name, field) = (v.name.as_str(), v.field.as_str());
        let change = format!("{}.{field}", v.kind);
        let (doc, _) = listen(name);
        let said: Vec<String> = ["line_errors", "problems"]
            .iter()
            .flat_map(|k| doc[k].as_array().cloned().unwrap_or_default())
            .filter_map(|p| p["what"].as_str().map(String::from))
            .collect();
        // An S line's field is its positions: the decoder names the position.
        let names = |w: &str| {
            if field == "chars" {
                w.contains("S line") && w.contains("position")
            } else {
                [" ", ":", "=", ","].iter().any(|end| {
                    w.contains(&format!(" {field}{end}")) || w.starts_with(&format!("{field}{end}"))
                })
            }
        };
        assert!(
            said.iter().any(|w| names(w)),
            "{name}: dmap listen does not name {change}: {said:?}"
        );
        checked += 1;
    }
    assert!(checked >= 30, "{checked}");
}
