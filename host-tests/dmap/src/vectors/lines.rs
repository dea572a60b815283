//! What the protocol's decoder makes of each line of a vector (its
//! `NAME.jsonl`): one JSON object per input line, in the line's order, so
//! that line `n` of `NAME.jsonl` is the decode of line `n` of `NAME.txt`.
//!
//! A line is what ends in `\n` (the last one may lack it); its `\n` and a
//! `\r` before it are not part of it. Then, as docs/protocol.md frames it:
//!
//! * `{"empty":true}`: an empty line, which a receiver passes over;
//! * `{"error":"too-long"}`: longer than its type's limit (`H`, `E`:
//!   `MAX_LINE`; any other: `MAX_ROW_LINE`, the `\n` counted);
//! * `{"type":"A","reply":LINE}`: a command reply, as
//!   `cvm_core::command::parse_reply` decodes it, written again by the
//!   encoder (canonical, without its `\n`);
//! * `{"type":T,"fields":{NAME:VALUE,...}}`: a result line as
//!   `cvm_core::protocol::parse` decodes it, every field of the layout
//!   (`cvm_core::protocol::layout`) by its name, in the layout's order;
//! * `{"error":KIND}` (with `"field":NAME` for a field out of range):
//!   why `parse` (or `parse_reply`) refused it, KIND one of `no-checksum`,
//!   `checksum`, `malformed`, `range`, `unknown-type`.
//!
//! Values are the decoded ones: numbers; `null` for an `R` line's `-` and
//! for what an older header does not carry (`rows`, `src`, `store` before
//! version 6); `true`/`false` for `norm` and `scores`; `j` as `[J1, J2]`;
//! `k`, `w`, `rst`, `store`, `verdict` as their words; `src` as its
//! letters (16: a version 6 header's 15 with `sthr`'s `d`); an `S` line's
//! `chars` as one `[mag, pmag, smag, flags]` per position from `col0`.

use anyhow::{Result, bail};
use cvm_core::command::{encode_reply, parse_reply};
use cvm_core::protocol::{self, END_FIELDS, HeaderInfo, Line, ParseError, layout};
use serde_json::{Value, json};

/// The decode of every line of `bytes`, one JSON text per line.
pub fn decode(bytes: &[u8]) -> Result<Vec<String>> {
    bytes
        .split_inclusive(|&b| b == b'\n')
        .map(|raw| {
            let line = raw.strip_suffix(b"\n").unwrap_or(raw);
            let line = line.strip_suffix(b"\r").unwrap_or(line);
            one(line)
        })
        .collect()
}

/// The decode of one line, without its line end.
fn one(line: &[u8]) -> Result<String> {
    if line.is_empty() {
        return Ok(object(&[("empty", json!(true))]));
    }
    // Both limits count the newline.
    let limit = match line[0] {
        b'H' | b'E' => protocol::MAX_LINE,
        _ => protocol::MAX_ROW_LINE,
    };
    if line.len() >= limit {
        return Ok(object(&[("error", json!("too-long"))]));
    }
    if line.starts_with(b"A,") {
        return Ok(match parse_reply(line) {
            Ok((id, r)) => {
                let mut sink = crate::stream::VecSink::default();
                encode_reply(id, &r, &mut sink);
                let text = String::from_utf8_lossy(&sink.0);
                object(&[("type", json!("A")), ("reply", json!(text.trim_end()))])
            }
            Err(e) => error(e, None),
        });
    }
    Ok(match protocol::parse(line) {
        Ok(l) => {
            let (kind, values) = fields(&l);
            let names = layout::fields(kind).unwrap_or(&[]);
            if names.len() != values.len() {
                bail!(
                    "the {} line's layout has {} fields, its record here {}: follow the layout",
                    char::from(kind),
                    names.len(),
                    values.len()
                );
            }
            let record: Vec<(&str, Value)> = names.iter().copied().zip(values).collect();
            format!(
                "{{\"type\":{},\"fields\":{}}}",
                json!(char::from(kind).to_string()),
                object(&record)
            )
        }
        Err(e) => error(e, Some(line[0])),
    })
}

/// A refused line: its kind, and for a field out of range the field's
/// name when the decoder's reason starts with one of the line's fields
/// (`chars` for a position of an `S` line).
fn error(e: ParseError, kind: Option<u8>) -> String {
    let word = match e {
        ParseError::NoChecksum => "no-checksum",
        ParseError::Checksum => "checksum",
        ParseError::Format => "malformed",
        ParseError::Range(_) => "range",
        ParseError::Type => "unknown-type",
    };
    let field = match (e, kind) {
        (ParseError::Range(_), Some(b'S')) => Some("chars"),
        (ParseError::Range(why), Some(k)) => why
            .split_once(':')
            .map(|(name, _)| name)
            .filter(|name| layout::fields(k).is_some_and(|f| f.contains(name))),
        _ => None,
    };
    match field {
        Some(f) => object(&[("error", json!(word)), ("field", json!(f))]),
        None => object(&[("error", json!(word))]),
    }
}

/// A JSON object with its keys in the order given.
fn object(pairs: &[(&str, Value)]) -> String {
    let body: Vec<String> = pairs
        .iter()
        .map(|(k, v)| format!("{}:{v}", json!(k)))
        .collect();
    format!("{{{}}}", body.join(","))
}

/// The line's type letter and its fields' values, in the layout's order.
fn fields(line: &Line<'_>) -> (u8, Vec<Value>) {
    match line {
        Line::Header(h) => (b'H', header(h)),
        Line::Row { summary: r, listed } => (
            b'R',
            vec![
                json!(r.row),
                json!(r.max),
                json!(r.argmax),
                json!(r.pmax),
                json!(r.pargmax),
                json!(r.defects),
                json!(listed),
                json!(r.no_data),
                json!(r.dark),
                json!(r.saturated),
            ],
        ),
        Line::Defect {
            row,
            col,
            mag,
            pmag,
            smag,
            strength,
            flags,
        } => (
            b'D',
            vec![
                json!(row),
                json!(col),
                json!(mag),
                json!(pmag),
                json!(smag),
                json!(strength),
                json!(flags),
            ],
        ),
        Line::Scores { row, col0, chars } => {
            let positions: Vec<Value> = chars
                .chunks(protocol::SCORE_CHARS)
                .filter_map(protocol::decode_score)
                .map(|s| json!([s.mag, s.pmag, s.smag, s.flags]))
                .collect();
            (b'S', vec![json!(row), json!(col0), Value::Array(positions)])
        }
        Line::Object(o) => (
            b'O',
            vec![
                json!(o.id),
                json!(o.row0),
                json!(o.row1),
                json!(o.col0),
                json!(o.col1),
                json!(o.area),
                json!(o.peak),
                json!(o.peak_row),
                json!(o.peak_col),
                json!(o.peak_mag),
                json!(o.peak_power),
                json!(o.peak_spread),
                json!(o.centroid_row_q8),
                json!(o.centroid_col_q8),
                json!(o.channels),
            ],
        ),
        Line::End(e) => {
            let mut totals = e.totals;
            let mut v: Vec<Value> = END_FIELDS
                .iter()
                .map(|(_, field)| json!(*field(&mut totals)))
                .collect();
            v.push(json!(e.dropped));
            v.push(json!(e.verdict.as_str()));
            (b'E', v)
        }
    }
}

/// A header's values, in the layout's order.
fn header(h: &HeaderInfo<'_>) -> Vec<Value> {
    let origin = h.origin.as_ref();
    vec![
        json!(h.version),
        json!(h.firmware),
        json!([h.j1, h.j2]),
        json!(h.cols),
        json!(char::from(h.kernels).to_string()),
        json!(h.kernel_size),
        json!(h.weights),
        json!(h.normalise),
        json!(h.full_scale),
        json!(h.threshold),
        json!(h.power_threshold),
        json!(h.spread_threshold),
        json!(h.q),
        json!(h.scores),
        json!(h.max_defect_lines),
        json!(h.reset_cause.as_str()),
        json!(h.boots),
        json!(origin.map(|o| o.rows)),
        json!(origin.map(|o| {
            o.sources
                .iter()
                .map(|s| char::from(s.as_char()))
                .collect::<String>()
        })),
        json!(origin.map(|o| o.store.word())),
    ]
}
