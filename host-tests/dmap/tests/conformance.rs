//! The line protocol's conformance vectors (docs/protocol/vectors,
//! described in docs/dmap.md, "Conformance vectors"): they are exactly
//! what the encoder and decoder make now (a change to either that the
//! vectors do not carry fails here: write them again with `dmap vectors`),
//! each line's decode names the fields the line carries at their places
//! in the layout, and together they cover every line type, every flag,
//! every verdict, every line error and every kind of damage the document
//! names. What `dmap listen` reports of the streams is tested in
//! `listen_vectors.rs`.

use crate::common;

use common::{dmap, s, vectors_dir as dir, vectors_index as index};
use serde_json::Value;
use std::collections::BTreeSet;

/// A vector's input, as lines without their line ends (as the decodes
/// count them: a last line without its newline is one).
fn input(name: &str) -> Vec<String> {
    let bytes = std::fs::read(dir().join(format!("{name}.txt"))).unwrap();
    bytes
        .split_inclusive(|&b| b == b'\n')
        .map(|l| {
            let l = l.strip_suffix(b"\n").unwrap_or(l);
            let l = l.strip_suffix(b"\r").unwrap_or(l);
            String::from_utf8_lossy(l).into_owned()
        })
        .collect()
}

/// A vector's decodes, one per input line, as written.
fn decode_lines(name: &str) -> Vec<String> {
    let text = std::fs::read_to_string(dir().join(format!("{name}.jsonl"))).unwrap();
    assert!(text.is_empty() || text.ends_with('\n'), "{name}.jsonl");
    text.lines().map(String::from).collect()
}

/// A vector's decodes, one per input line.
fn decodes(name: &str) -> Vec<Value> {
    decode_lines(name)
        .iter()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{name}: {l}: {e}")))
        .collect()
}

fn names() -> Vec<String> {
    index()
        .iter()
        .map(|e| e["name"].as_str().unwrap().to_string())
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

/// Each line's decode against the line's text, read by the layout's
/// names alone (`field_of`): one decode per input line; a record has
/// every field of its type's layout, in order, each the value written at
/// its place (numbers with any leading zeros, `-` for none, `1`/`0` for
/// `true`/`false`, `J1xJ2` for `j`); an `S` line one entry per 12
/// characters; an error only for a line that is no whole record.
#[test]
fn each_decode_is_what_its_line_says() {
    let mut records = 0;
    for name in names() {
        let (text, decoded, raw) = (input(&name), decodes(&name), decode_lines(&name));
        assert_eq!(text.len(), decoded.len(), "{name}: a decode per line");
        for (i, (line, d)) in text.iter().zip(&decoded).enumerate() {
            let at = format!("{name} line {}", i + 1);
            if line.is_empty() {
                assert_eq!(d, &serde_json::json!({"empty": true}), "{at}");
                continue;
            }
            let Some(fields) = d["fields"].as_object() else {
                if d["type"] == "A" {
                    assert!(line.starts_with("A,"), "{at}");
                    assert_eq!(
                        d["reply"].as_str().unwrap().split('*').next(),
                        line.split('*').next(),
                        "{at}: written again as it came"
                    );
                } else {
                    assert!(d["error"].is_string(), "{at}: {d}");
                }
                continue;
            };
            let kind = d["type"].as_str().unwrap();
            assert!(line.starts_with(&format!("{kind},")), "{at}");
            let layout = cvm_core::protocol::layout::fields(kind.as_bytes()[0]).unwrap();
            let keys: Vec<&str> = fields.keys().map(String::as_str).collect();
            let mut want: Vec<&str> = layout.to_vec();
            want.sort_unstable();
            let mut got = keys.clone();
            got.sort_unstable();
            assert_eq!(got, want, "{at}: the layout's fields");
            let places: Vec<usize> = layout
                .iter()
                .map(|f| raw[i].find(&format!("\"{f}\":")).unwrap())
                .collect();
            assert!(places.is_sorted(), "{at}: fields in the layout's order");
            for name in layout {
                let v = &fields[*name];
                let t = field_of(line, name);
                let same = match (v, t.as_deref()) {
                    (Value::Null, None | Some("-")) => true,
                    (Value::Number(n), Some(t)) => {
                        let t = t.trim_start_matches('0');
                        n.to_string() == if t.is_empty() { "0" } else { t }
                    }
                    (Value::Bool(b), Some(t)) => t == if *b { "1" } else { "0" },
                    (Value::Array(a), Some(t)) if *name == "j" => t == format!("{}x{}", a[0], a[1]),
                    (Value::Array(a), Some(t)) if *name == "chars" => {
                        a.len() * cvm_core::protocol::SCORE_CHARS == t.len()
                    }
                    // A version 6 header's 15 `src` letters: `sthr`'s `d` added.
                    (Value::String(v), Some(t)) if *name == "src" && t.len() == 15 => {
                        let mut t = t.to_string();
                        t.insert(cvm_core::protocol::SPREAD_KEY, 'd');
                        *v == t
                    }
                    (Value::String(v), Some(t)) => v == t,
                    // No `sthr` before version 7: the channel off.
                    (Value::Number(n), None) if *name == "sthr" => {
                        n.as_u64() == Some(u64::from(u32::MAX))
                    }
                    _ => false,
                };
                assert!(same, "{at}: {kind}.{name} decoded {v}, written {t:?}");
            }
            records += 1;
        }
    }
    assert!(records > 3000, "{records}");
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

/// Every line type occurs in a whole stream (one in which a receiver
/// finds no damage); every flag bit in a score line of one; every
/// verdict in an end line; every line error in a decode; every kind of
/// damage in the index but the two that only `dmap listen`'s own limits
/// raise (`--max-scans`, its memory).
#[test]
fn the_vectors_cover_the_protocol() {
    let index = index();
    let mut types = BTreeSet::new();
    let mut flags = 0u64;
    let mut errors = BTreeSet::new();
    let mut verdicts = BTreeSet::new();
    let mut damage = BTreeSet::new();
    let mut whole = 0;
    for e in &index {
        let name = e["name"].as_str().unwrap();
        let kinds = e["damage"].as_array().unwrap();
        damage.extend(kinds.iter().map(|k| k.as_str().unwrap().to_string()));
        for d in decodes(name) {
            if let Some(err) = d["error"].as_str() {
                errors.insert(err.to_string());
            }
            if d["type"] == "E" {
                verdicts.insert(d["fields"]["verdict"].as_str().unwrap().to_string());
            }
            if !kinds.is_empty() {
                continue;
            }
            if let Some(t) = d["type"].as_str() {
                types.insert(t.to_string());
            }
            match d["type"].as_str() {
                Some("S") => {
                    for p in d["fields"]["chars"].as_array().unwrap() {
                        flags |= p[3].as_u64().unwrap();
                    }
                }
                Some("D") => flags |= d["fields"]["flags"].as_u64().unwrap(),
                _ => {}
            }
        }
        whole += usize::from(kinds.is_empty());
    }
    assert!(whole >= 20, "{whole} whole streams");
    assert_eq!(
        types.into_iter().collect::<String>(),
        "ADEHORS",
        "line types of the whole streams"
    );
    // CLIPPED is never written (a score cannot reach the top of its
    // range); its rule is shown by the vector range-clipped.
    let clipped = u64::from(cvm_core::flags::CLIPPED);
    assert_eq!(flags, 0x7F & !clipped, "flags {flags:#x}");
    let set = |v: &[&str]| v.iter().map(|k| k.to_string()).collect::<BTreeSet<_>>();
    let line_errors = [
        "no-checksum",
        "checksum",
        "malformed",
        "range",
        "unknown-type",
        "too-long",
    ];
    assert_eq!(errors, set(&line_errors), "line errors in the decodes");
    let every = [
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
        damage,
        set(&[&line_errors[..], &every[..]].concat()),
        "kinds of damage in the index"
    );
    assert_eq!(
        verdicts,
        set(&[
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
/// else of its base stream; and the decodes of the lines it changed
/// differ from the base's in that field alone, or refuse the line for
/// that field's range. A vector made with another field's place, as
/// happens when the layout changes and the generator does not follow,
/// fails here. (`dmap listen` naming the field: `listen_vectors.rs`.)
#[test]
fn each_one_field_vector_changes_its_field_only_and_the_decoder_names_it() {
    let mut checked = 0;
    for v in common::one_field_vectors() {
        let (name, base) = (v.name.as_str(), v.base.as_str());
        let (kind, field) = (v.kind.as_str(), v.field.as_str());
        let change = format!("{kind}.{field}");
        let (good, bad) = (input(base), input(name));
        assert_eq!(good.len(), bad.len(), "{name}: lines added or removed");
        let differ: Vec<usize> = (0..good.len()).filter(|&i| good[i] != bad[i]).collect();
        assert!(!differ.is_empty(), "{name}: no line changed");
        let (was, now) = (decodes(base), decodes(name));
        for i in 0..good.len() {
            if !differ.contains(&i) {
                assert_eq!(was[i], now[i], "{name}: line {i} unchanged, its decode not");
                continue;
            }
            assert!(
                bad[i].starts_with(&format!("{kind},")),
                "{name}: line {i} is not {kind}"
            );
            let fields = cvm_core::protocol::layout::fields(kind.as_bytes()[0]).unwrap();
            for f in fields {
                let (a, b) = (field_of(&good[i], f), field_of(&bad[i], f));
                if *f == field {
                    assert_ne!(a, b, "{name}: {change} unchanged in line {i}");
                } else {
                    assert_eq!(a, b, "{name}: {kind}.{f} changed too, in line {i}");
                }
            }
            if now[i]["error"].is_string() {
                assert_eq!(
                    now[i],
                    serde_json::json!({"error": "range", "field": field}),
                    "{name}: line {i}"
                );
                continue;
            }
            let (a, b) = (&was[i]["fields"], &now[i]["fields"]);
            for f in fields {
                if *f == field {
                    assert_ne!(a[f], b[f], "{name}: {change} decodes unchanged in line {i}");
                } else {
                    assert_eq!(a[f], b[f], "{name}: {kind}.{f} decodes changed in line {i}");
                }
            }
        }
        checked += 1;
    }
    assert!(checked >= 30, "{checked}");
}
