//! The line protocol's conformance vectors (docs/protocol/vectors,
//! described in docs/dmap.md, "Conformance vectors"): they are exactly
//! what the encoder and decoder make now (a change to either that the
//! vectors do not carry fails here: write them again with `dmap vectors`),
//! `dmap listen --json` decodes every stream into its expected document
//! and exit status, and together they cover every line type, every flag
//! and every kind of damage the document names.

mod common;

use common::{dmap, s};
use serde_json::Value;
use std::collections::BTreeSet;
use std::path::PathBuf;

fn dir() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../docs/protocol/vectors"
    ))
}

/// (name, expected document) of every vector.
fn vectors() -> Vec<(String, Value)> {
    let index: Value =
        serde_json::from_slice(&std::fs::read(dir().join("index.json")).unwrap()).unwrap();
    index
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            let name = e["name"].as_str().unwrap().to_string();
            let doc = std::fs::read(dir().join(format!("{name}.json"))).unwrap();
            (name, serde_json::from_slice(&doc).unwrap())
        })
        .collect()
}

#[test]
fn the_vectors_are_what_the_encoder_and_decoder_make() {
    let out = dmap(&["vectors", "--check", s(&dir())]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn listen_decodes_every_vector_as_expected() {
    let all = vectors();
    assert!(all.len() > 80, "{}", all.len());
    for (name, want) in all {
        let input = dir().join(format!("{name}.txt"));
        let out = dmap(&["listen", "--input", s(&input), "--json"]);
        let got: Value = serde_json::from_slice(&out.stdout)
            .unwrap_or_else(|e| panic!("{name}: no JSON document: {e}"));
        assert_eq!(got, want["listen"], "{name}");
        assert_eq!(
            Some(want["exit"].as_i64().unwrap() as i32),
            out.status.code(),
            "{name}"
        );
    }
}

/// The command channel's vectors: every request the board accepts is
/// written again as the vectors say, every refusal a line alone can cause
/// (not `busy`, `storage` or the link's errors, which depend on the board)
/// occurs, and every reply decodes as they say.
#[test]
fn the_command_vectors_decode_as_stated_and_cover_the_refusals() {
    use cvm_core::command::{parse_reply, parse_request};
    let doc: Value =
        serde_json::from_slice(&std::fs::read(dir().join("commands.json")).unwrap()).unwrap();
    let cap = dmap::vectors::COMMAND_CAPACITY;
    let mut refusals = BTreeSet::new();
    for e in doc["requests"].as_array().unwrap() {
        let line = e["line"].as_str().unwrap().as_bytes();
        let d = &e["decode"];
        match parse_request(line, &cap) {
            Ok(_) => assert!(d["accepted"].is_string(), "{e}"),
            Err((_, why)) => {
                let reply = d["refused"].as_str().unwrap();
                assert!(reply.contains(&format!(",err,{}", why.word())), "{e}");
                refusals.insert(why.word());
            }
        }
    }
    assert_eq!(
        refusals,
        BTreeSet::from([
            "checksum",
            "malformed",
            "too-long",
            "unknown-command",
            "unknown-key",
            "type",
            "range"
        ])
    );
    for e in doc["replies"].as_array().unwrap() {
        let line = e["line"].as_str().unwrap().as_bytes();
        let ok = parse_reply(line).is_ok();
        assert_eq!(ok, e["decode"]["accepted"].is_string(), "{e}");
    }
}

/// Every line type occurs in a whole stream; every flag bit in a score
/// line; every verdict; every kind of damage but the two that only
/// `dmap listen`'s own limits raise (`--max-scans`, its memory).
#[test]
fn the_vectors_cover_the_protocol() {
    let all = vectors();
    let mut types = BTreeSet::new();
    let mut flags = 0u8;
    for (name, _) in all.iter().filter(|(n, _)| n.starts_with("good-")) {
        let bytes = std::fs::read(dir().join(format!("{name}.txt"))).unwrap();
        for l in bytes.split(|&b| b == b'\n').filter(|l| l.len() > 1) {
            types.insert(l[0] as char);
            if let Ok(cvm_core::protocol::Line::Scores { chars, .. }) = cvm_core::protocol::parse(l)
            {
                for c in chars.chunks(cvm_core::protocol::SCORE_CHARS) {
                    flags |= cvm_core::protocol::decode_score(c).unwrap().flags;
                }
            }
        }
    }
    assert_eq!(
        types.into_iter().collect::<String>(),
        "ADEHORS",
        "line types of the whole streams"
    );
    // CLIPPED is never written (a score cannot reach the top of its
    // range); its rule is shown by the vector range-clipped.
    let clipped = cvm_core::flags::CLIPPED;
    assert_eq!(flags, 0x7F & !clipped, "flags {flags:#x}");
    let kinds: BTreeSet<String> = all
        .iter()
        .flat_map(|(_, v)| v["listen"]["problems"].as_array().unwrap().clone())
        .map(|p| p["kind"].as_str().unwrap().to_string())
        .collect();
    let every = [
        "no-checksum",
        "checksum",
        "malformed",
        "range",
        "unknown-type",
        "too-long",
        "cut",
        "outside-scan",
        "scan-cut",
        "no-scan",
        "version",
        "order",
        "duplicate",
        "field",
        "missing",
        "cross-check",
        "verdict",
        "misplaced",
    ];
    assert_eq!(
        kinds,
        every.iter().map(|k| k.to_string()).collect::<BTreeSet<_>>()
    );
    let verdicts: BTreeSet<&str> = all
        .iter()
        .flat_map(|(_, v)| v["listen"]["scans"].as_array().unwrap().clone())
        .filter_map(|s| s["verdict"].as_str().map(String::from))
        .map(|v| match v.as_str() {
            "good" => "good",
            "obj" => "obj",
            "fault-missing" => "fault-missing",
            "fault-frames" => "fault-frames",
            "fault-misplaced" => "fault-misplaced",
            _ => "other",
        })
        .collect();
    assert_eq!(
        verdicts,
        BTreeSet::from([
            "fault-frames",
            "fault-misplaced",
            "fault-missing",
            "good",
            "obj"
        ])
    );
}

/// The spread channel's vector carries what its maps make, worked out by
/// hand from docs/protocol.md: a clear 5x5 map (a cone, 7 400 in all, 800
/// of it outside the 3x3 core around its peak) and a haloed one (the cone
/// at 3/4 plus 115 on each of the 16 rim cells: 7 390, 2 440 outside).
/// At (1, 10) the map below is haloed and the other three neighbours
/// clear: `smag = q(haloed) - q(clear)`, a spread defect alone at
/// `sthr=3277` (thr is out of reach), strength `floor(2^16 smag / sthr)`.
#[test]
fn the_spread_vector_carries_the_hand_computed_values() {
    let q = |outside: u64, power: u64| (outside << 16) / power;
    let smag = q(2440, 7390) - q(800, 7400);
    assert_eq!(smag, 21638 - 7084);
    let bytes = std::fs::read(dir().join("good-spread.txt")).unwrap();
    let text = String::from_utf8(bytes).unwrap();
    let d = text
        .lines()
        .find(|l| l.starts_with("D,1,10,"))
        .expect("the defect above the patch");
    let f: Vec<u64> = d
        .split('*')
        .next()
        .unwrap()
        .split(',')
        .skip(1)
        .map(|v| v.parse().unwrap())
        .collect();
    // row, col, mag, pmag, smag, strength, flags
    assert_eq!(f[4], smag, "{d}");
    assert_eq!(f[5], (smag << 16) / 3277, "{d}");
    assert_eq!(f[6], u64::from(cvm_core::flags::SPREAD_DEFECT), "{d}");
    assert!(text.lines().next().unwrap().contains(",sthr=3277,"));
}

/// Field `name` of a line (`key=` for `H` and `E`, else by its place in
/// the layout), the trailer left out.
fn field_of(line: &str, name: &str) -> Option<String> {
    let body = line.trim_end().rsplit_once('*').map_or(line, |(b, _)| b);
    let kind = *body.as_bytes().first()?;
    let fields: Vec<&str> = body.split(',').collect();
    match kind {
        b'H' | b'E' => fields
            .iter()
            .find_map(|f| f.split_once('=').filter(|(k, _)| *k == name))
            .map(|(_, v)| v.to_string()),
        _ => fields
            .get(cvm_core::protocol::layout::place(kind, name)?)
            .map(|s| s.to_string()),
    }
}

/// Every vector that says it changes one field (`range-`, `field-`,
/// `cross-`, ...) changes that field, in lines of that type, and nothing
/// else of its base stream; and `dmap listen` names that field in what it
/// reports (a line refused for the field's range, a field or cross-check
/// problem). A vector made with another field's place, as happens when the
/// layout changes and the generator does not follow, fails here.
#[test]
fn each_one_field_vector_changes_its_field_only_and_the_decoder_names_it() {
    let index: Value =
        serde_json::from_slice(&std::fs::read(dir().join("index.json")).unwrap()).unwrap();
    let mut checked = 0;
    for e in index.as_array().unwrap() {
        let Some(change) = e["changes"].as_str() else {
            continue;
        };
        let name = e["name"].as_str().unwrap();
        let base = e["base"].as_str().unwrap();
        let (kind, field) = change.split_once('.').unwrap();
        let read = |n: &str| std::fs::read_to_string(dir().join(format!("{n}.txt"))).unwrap();
        let (good, bad) = (read(base), read(name));
        let (good, bad): (Vec<&str>, Vec<&str>) = (good.lines().collect(), bad.lines().collect());
        assert_eq!(good.len(), bad.len(), "{name}: lines added or removed");
        let differ: Vec<usize> = (0..good.len()).filter(|&i| good[i] != bad[i]).collect();
        assert!(!differ.is_empty(), "{name}: no line changed");
        for &i in &differ {
            assert!(
                bad[i].starts_with(&format!("{kind},")),
                "{name}: line {i} is not {kind}"
            );
            let fields = cvm_core::protocol::layout::fields(kind.as_bytes()[0]).unwrap();
            for f in fields {
                let (a, b) = (field_of(good[i], f), field_of(bad[i], f));
                if *f == field {
                    assert_ne!(a, b, "{name}: {change} unchanged in line {i}");
                } else {
                    assert_eq!(a, b, "{name}: {kind}.{f} changed too, in line {i}");
                }
            }
        }
        let doc: Value =
            serde_json::from_slice(&std::fs::read(dir().join(format!("{name}.json"))).unwrap())
                .unwrap();
        let said: Vec<String> = ["line_errors", "problems"]
            .iter()
            .flat_map(|k| doc["listen"][k].as_array().cloned().unwrap_or_default())
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
            "{name}: the decoder does not name {change}: {said:?}"
        );
        checked += 1;
    }
    assert!(checked >= 30, "{checked}");
}
