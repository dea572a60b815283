//! The line layout (`cvm_core::protocol::layout`) is the parser's and the
//! documentation's: changing field `k` of a real line changes, in what the
//! parser makes of it, exactly the value the layout names at `k`; the
//! key=value lines carry the layout's keys in its order; and
//! docs/protocol.md writes each line's format with the layout's names.

use cvm_core::protocol::{Line, crc16, layout, parse};

const GOOD: &str = include_str!("../../../docs/protocol/vectors/good-scores.txt");
const DOC: &str = include_str!("../../../docs/protocol.md");

fn sealed(body: &str) -> Vec<u8> {
    format!("{body}*{:04X}\n", crc16(body.as_bytes())).into_bytes()
}

fn first_line(kind: char) -> String {
    let l = GOOD
        .lines()
        .find(|l| l.starts_with(kind) && l.as_bytes().get(1) == Some(&b','))
        .unwrap_or_else(|| panic!("no {kind} line in good-scores"));
    l.rsplit_once('*').unwrap().0.to_string()
}

/// The parsed line's values by the documentation's field names: written
/// here from the parser's types, independently of the layout.
fn values(line: &Line<'_>) -> Vec<(&'static str, String)> {
    match *line {
        Line::Row { summary: s, listed } => vec![
            ("row", s.row.to_string()),
            ("max", s.max.to_string()),
            ("argmax", format!("{:?}", s.argmax)),
            ("pmax", s.pmax.to_string()),
            ("pargmax", format!("{:?}", s.pargmax)),
            ("defects", s.defects.to_string()),
            ("listed", listed.to_string()),
            ("no_data", s.no_data.to_string()),
            ("dark", s.dark.to_string()),
            ("saturated", s.saturated.to_string()),
        ],
        Line::Defect {
            row,
            col,
            mag,
            pmag,
            smag,
            strength,
            flags,
        } => vec![
            ("row", row.to_string()),
            ("col", col.to_string()),
            ("mag", mag.to_string()),
            ("pmag", pmag.to_string()),
            ("smag", smag.to_string()),
            ("strength", strength.to_string()),
            ("flags", flags.to_string()),
        ],
        Line::Scores { row, col0, chars } => vec![
            ("row", row.to_string()),
            ("col0", col0.to_string()),
            ("chars", String::from_utf8_lossy(chars).into_owned()),
        ],
        Line::Object(o) => vec![
            ("id", o.id.to_string()),
            ("row0", o.row0.to_string()),
            ("row1", o.row1.to_string()),
            ("col0", o.col0.to_string()),
            ("col1", o.col1.to_string()),
            ("area", o.area.to_string()),
            ("peak", o.peak.to_string()),
            ("peak_row", o.peak_row.to_string()),
            ("peak_col", o.peak_col.to_string()),
            ("peak_mag", o.peak_mag.to_string()),
            ("peak_power", o.peak_power.to_string()),
            ("peak_spread", o.peak_spread.to_string()),
            ("centroid_row_q8", o.centroid_row_q8.to_string()),
            ("centroid_col_q8", o.centroid_col_q8.to_string()),
            ("channels", o.channels.to_string()),
        ],
        _ => vec![],
    }
}

/// Another value for a field that keeps the line within its ranges.
fn other(name: &str, v: &str) -> String {
    match name {
        "chars" => format!("B{}", &v[1..]),
        "channels" => if v == "16" { "32" } else { "16" }.into(),
        "flags" => if v == "16" { "48" } else { "16" }.into(),
        _ => match v.parse::<u64>() {
            Ok(n) => (n + 1).to_string(),
            Err(_) => "3".into(),
        },
    }
}

#[test]
fn each_positional_field_is_the_value_its_name_says() {
    for kind in ['R', 'D', 'S', 'O'] {
        let names = layout::fields(kind as u8).unwrap();
        let body = first_line(kind);
        let fields: Vec<&str> = body.split(',').collect();
        assert_eq!(fields.len(), names.len() + 1, "{kind}: {body}");
        let good = sealed(&body);
        let before = values(&parse(&good).unwrap());
        assert_eq!(
            before.iter().map(|(n, _)| *n).collect::<Vec<_>>(),
            names.to_vec(),
            "{kind}"
        );
        for (k, name) in names.iter().enumerate() {
            assert_eq!(layout::place(kind as u8, name), Some(k + 1));
            let mut f: Vec<String> = fields.iter().map(|s| s.to_string()).collect();
            f[k + 1] = other(name, &f[k + 1]);
            let changed = sealed(&f.join(","));
            let line =
                parse(&changed).unwrap_or_else(|e| panic!("{kind} with {name} changed: {e}"));
            let after = values(&line);
            let differ: Vec<&str> = before
                .iter()
                .zip(&after)
                .filter(|(a, b)| a != b)
                .map(|(a, _)| a.0)
                .collect();
            assert_eq!(differ, vec![*name], "{kind}: field {} changed", k + 1);
        }
    }
}

#[test]
fn key_value_lines_carry_the_layout_keys_in_order() {
    for kind in ['H', 'E'] {
        let body = first_line(kind);
        let keys: Vec<&str> = body
            .split(',')
            .skip(1)
            .map(|f| f.split_once('=').unwrap().0)
            .collect();
        assert_eq!(keys, layout::fields(kind as u8).unwrap().to_vec(), "{kind}");
    }
    let end: Vec<&str> = cvm_core::protocol::END_FIELDS
        .iter()
        .map(|(k, _)| *k)
        .chain([cvm_core::protocol::DROPPED, cvm_core::protocol::VERDICT])
        .collect();
    assert_eq!(end, layout::END.to_vec());
}

#[test]
fn the_documentation_writes_each_line_with_the_layout_names() {
    for kind in ['H', 'R', 'D', 'S', 'O', 'E'] {
        let names = layout::fields(kind as u8).unwrap();
        let want = if matches!(kind, 'H' | 'E') {
            names.join(",")
        } else {
            names
                .iter()
                .map(|n| format!("<{n}>"))
                .collect::<Vec<_>>()
                .join(",")
        };
        let found = DOC.lines().any(|l| {
            l.strip_prefix(&format!("{kind},"))
                .and_then(|rest| rest.rsplit_once('*'))
                .map(|(rest, _)| rest)
                .is_some_and(|rest| {
                    if matches!(kind, 'H' | 'E') {
                        rest.split(',')
                            .map(|f| f.split_once('=').map_or(f, |(k, _)| k))
                            .collect::<Vec<_>>()
                            .join(",")
                            == want
                    } else {
                        rest == want
                    }
                })
        });
        assert!(found, "docs/protocol.md has no `{kind},{want}` line");
    }
}
