//! The damaged streams among the conformance vectors: each a whole stream
//! of [`super::good`] with one deliberate change, for every kind of damage
//! docs/dmap.md names (a line the CRC rejects, one cut or too long,
//! a field out of its range, lines out of order, repeated or lost, and
//! lines whose valid CRC covers content that other lines contradict).

use super::Vector;
use super::edit::{Lines, sealed};
use super::good::scores_scene;
use super::scenes::{Scene, stream};
use anyhow::Result;
use cvm_core::flags;
use cvm_core::protocol::{SCORE_CHARS, encode_score, layout};

/// Where a field stands in its line, by the protocol's layout.
fn place(kind: u8, name: &str) -> usize {
    layout::place(kind, name).unwrap_or_else(|| panic!("no field {name}"))
}

/// One damaged vector: `base` changed by `edit`.
fn damaged(name: &str, about: &str, base: &Lines, edit: impl FnOnce(&mut Lines)) -> Vector {
    let mut l = base.clone();
    edit(&mut l);
    Vector {
        name: name.to_string(),
        about: about.to_string(),
        bytes: l.bytes(),
        changes: None,
    }
}

/// The whole streams the damaged vectors start from, by their vector's name.
const SCORES: &str = "good-scores";
const DEFECT_LINES: &str = "good-defect-lines";

/// A vector that changes field `field` (`TYPE.name`) of `base` (named
/// `base_name`) and nothing else: `edit` gets the field's name and sets
/// it, in one or more lines of that type.
fn one_field(
    name: &str,
    about: &str,
    (base_name, base): (&'static str, &Lines),
    field: &str,
    edit: impl FnOnce(&mut Lines, &str),
) -> Vector {
    let (_, key) = field.split_once('.').expect("TYPE.name");
    let mut v = damaged(name, about, base, |l| edit(l, key));
    v.changes = Some(super::Change {
        base: base_name,
        field: field.to_string(),
    });
    v
}

/// The damaged vectors.
pub fn all() -> Result<Vec<Vector>> {
    let g = Lines::of(&stream(&scores_scene())?);
    let d = Lines::of(&stream(&Scene {
        dcap: 30,
        ..Scene::default()
    })?);
    let default = stream(&Scene::default())?;
    let mut out = framing(&g, &default);
    out.extend(ranges(&g));
    out.extend(order(&g));
    out.extend(lost_and_repeated(&g));
    out.extend(contradictions(&g, &d));
    Ok(out)
}

/// Damage to lines as lines: CRC, trailer, length, type, syntax; cut
/// streams and lines outside a scan.
fn framing(g: &Lines, default: &[u8]) -> Vec<Vector> {
    let mut out = Vec::new();
    for (kind, name) in [
        (b'H', "header"),
        (b'R', "row"),
        (b'D', "defect"),
        (b'S', "scores"),
        (b'O', "object"),
        (b'E', "end"),
    ] {
        out.push(damaged(
            &format!("crc-{name}"),
            &format!("One byte changed in the first {} line: checksum; the line is skipped, and what it carried is missing", kind as char),
            g,
            |l| {
                let i = l.nth(kind, 0);
                l.corrupt(i);
            },
        ));
    }
    out.push(damaged(
        "crc-lower-case",
        "The end line's CRC in lower-case hex: no valid trailer",
        g,
        |l| {
            let i = l.nth(b'E', 0);
            l.0[i] = String::from_utf8_lossy(&l.0[i]).to_lowercase().into_bytes();
            l.0[i][0] = b'E';
        },
    ));
    out.push(damaged(
        "truncated",
        "A row line cut before its trailer: no checksum",
        g,
        |l| {
            let i = l.nth(b'R', 3);
            let n = l.0[i].len();
            l.0[i].truncate(n - 8);
            l.0[i].push(b'\n');
        },
    ));
    out.push(damaged(
        "crc-reply",
        "A command reply with one byte changed among the result lines: a line error; the scan is whole",
        g,
        |l| {
            l.insert(4, sealed("A,2,ok,save"));
            l.corrupt(4);
        },
    ));
    out.push(damaged(
        "unknown-type",
        "A line of type X with a valid CRC: unknown type",
        g,
        |l| {
            l.insert(3, sealed("X,1,2,3"));
        },
    ));
    out.push(damaged(
        "malformed-extra-field",
        "A row line with one field more, sealed again: malformed",
        g,
        |l| {
            let i = l.nth(b'R', 2);
            let body = format!("{},0", l.body(i));
            l.seal(i, &body);
        },
    ));
    out.push(damaged(
        "malformed-header-order",
        "A header with two keys swapped: malformed; the scan's lines are then outside a scan",
        g,
        |l| {
            let mut f: Vec<String> = l.body(0).split(',').map(String::from).collect();
            f.swap(place(b'H', "j"), place(b'H', "cols"));
            l.seal(0, &f.join(","));
        },
    ));
    out.push(damaged(
        "too-long-row",
        "A row line of 257 bytes (its max written with leading zeros): longer than the 256 of an R line",
        g,
        |l| {
            let i = l.nth(b'R', 1);
            let mut f: Vec<String> = l.body(i).split(',').map(String::from).collect();
            while f.join(",").len() + 6 < 257 {
                f[place(b'R', "max")].insert(0, '0');
            }
            l.seal(i, &f.join(","));
        },
    ));
    out.push(damaged(
        "padded-row",
        "A row line of exactly 256 bytes (its max written with leading zeros): not damage; it decodes as the line without them",
        g,
        |l| {
            let i = l.nth(b'R', 1);
            let mut f: Vec<String> = l.body(i).split(',').map(String::from).collect();
            while f.join(",").len() + 6 < 256 {
                f[place(b'R', "max")].insert(0, '0');
            }
            l.seal(i, &f.join(","));
        },
    ));
    out.push(damaged(
        "too-long-garbage",
        "400 bytes without a newline among them: longer than any line",
        g,
        |l| {
            l.insert(5, [vec![b'x'; 400], b"\n".to_vec()].concat());
        },
    ));
    out.push(damaged(
        "cut-new-scan",
        "The stream cut in the middle of a row line (a reset), a new scan right after: the cut line reported, the new header found in it",
        g,
        |l| {
            let i = l.nth(b'R', 6);
            l.0.truncate(i + 1);
            l.0[i].truncate(12);
            l.0.push(default.to_vec());
        },
    ));
    out.push(damaged(
        "cut-new-scan-long",
        "Cut in the middle of a score line, a new scan right after: the joined line is longer than any line, its end still a whole header",
        g,
        |l| {
            let i = l.nth(b'S', 8);
            l.0.truncate(i + 1);
            l.0[i].truncate(200);
            l.0.push(default.to_vec());
        },
    ));
    out.push(damaged(
        "no-end",
        "The stream ends before the end line: the scan is cut",
        g,
        |l| {
            l.0.pop();
        },
    ));
    out.push(damaged(
        "header-before-end",
        "A second scan's header before the first's end line",
        g,
        |l| {
            l.0.pop();
            l.0.push(default.to_vec());
        },
    ));
    out.push(damaged(
        "outside-scan",
        "An object line after the end line: outside any scan",
        g,
        |l| {
            let o = l.0[l.nth(b'O', 0)].clone();
            l.0.push(o);
        },
    ));
    out.push(Vector {
        name: "empty".into(),
        about: "Nothing at all: no scan".into(),
        bytes: Vec::new(),
        changes: None,
    });
    out.push(Vector {
        name: "no-scan".into(),
        about: "Lines that are no protocol: each reported, and no scan".into(),
        bytes: b"hello\nOK\n\n".to_vec(),
        changes: None,
    });
    out.push(one_field(
        "version-8",
        "A header of version 8: a problem of the scan, which is decoded as far as it goes",
        (SCORES, g),
        "H.v",
        |l, f| {
            l.set_field(0, f, "8");
        },
    ));
    out
}

/// Fields outside their ranges (the line is refused) and fields that
/// contradict one another or the header (the line is kept).
fn ranges(g: &Lines) -> Vec<Vector> {
    let mut out = Vec::new();
    for (name, key, value) in [
        ("range-j-0", "j", "0x0"),
        ("range-j-17", "j", "17x5"),
        ("range-q-99", "q", "99"),
        ("range-fs-0", "fs", "0"),
        ("range-norm-2", "norm", "2"),
    ] {
        out.push(one_field(
            name,
            &format!(
                "Header {key}={value}, a valid CRC: outside the field's range, the header refused"
            ),
            (SCORES, g),
            &format!("H.{key}"),
            |l, k| {
                l.set_field(0, k, value);
            },
        ));
    }
    let g = (SCORES, g);
    out.push(one_field(
        "range-pmax",
        "A row line's pmax 46341, above the largest power magnitude",
        g,
        "R.pmax",
        |l, f| {
            let i = l.nth(b'R', 2);
            l.set_field(i, f, "46341");
        },
    ));
    out.push(one_field(
        "range-strength",
        "A defect line's strength 65535, below a defect's least",
        g,
        "D.strength",
        |l, f| {
            let i = l.nth(b'D', 0);
            l.set_field(i, f, "65535");
        },
    ));
    out.push(one_field(
        "range-defect-flags",
        "A defect line's flags 1 (NO_DATA, no channel)",
        g,
        "D.flags",
        |l, f| {
            let i = l.nth(b'D', 0);
            l.set_field(i, f, "1");
        },
    ));
    out.push(one_field(
        "range-position",
        "A score line's first position NO_DATA with a magnitude of 1",
        g,
        "S.chars",
        |l, f| {
            let i = l.nth(b'S', 0);
            let first = position(flags::NO_DATA, 1);
            let chars = l.get(i, f);
            l.set_field(i, f, &format!("{first}{}", &chars[SCORE_CHARS..]));
        },
    ));
    out.push(one_field(
        "range-clipped",
        "A score line's first position CLIPPED (and a distance defect) below the top magnitude",
        g,
        "S.chars",
        |l, f| {
            let i = l.nth(b'S', 0);
            let first = position(flags::CLIPPED | flags::CVM_DEFECT, 5);
            let chars = l.get(i, f);
            l.set_field(i, f, &format!("{first}{}", &chars[SCORE_CHARS..]));
        },
    ));
    out.push(one_field(
        "range-object-channels",
        "An object line's channels 0",
        g,
        "O.channels",
        |l, f| {
            let i = l.nth(b'O', 0);
            l.set_field(i, f, "0");
        },
    ));
    out.push(one_field(
        "field-header-q",
        "Header q one below what a scorer of its configuration (5x5, paper kernels, uniform weights, normalised) has",
        g,
        "H.q",
        |l, f| {
            let q: i64 = l.get(0, f).parse().unwrap_or(0);
            l.set_field(0, f, &(q - 1).to_string());
        },
    ));
    out.push(one_field(
        "field-row-argmax",
        "A row line's argmax at column 30 of a 30-column scan",
        g,
        "R.argmax",
        |l, f| {
            let i = l.nth(b'R', 1);
            l.set_field(i, f, "30");
        },
    ));
    out.push(damaged(
        "field-row-listed",
        "A row line listing one defect line fewer than min(defects, dcap)",
        g.1,
        |l| {
            let i = (0..l.0.len())
                .find(|&i| l.0[i].starts_with(b"R,") && l.num_of(i, "listed") > 0)
                .unwrap_or(0);
            let listed = l.num_of(i, "listed");
            l.set_field(i, "listed", &(listed - 1).to_string());
            l.remove(i + 1);
        },
    ));
    out.push(one_field(
        "field-defect-strength",
        "A defect line's strength one above what its magnitudes and the thresholds make",
        g,
        "D.strength",
        |l, f| {
            let i = l.nth(b'D', 0);
            let s = l.num_of(i, f);
            l.set_field(i, f, &(s + 1).to_string());
        },
    ));
    for (name, about, field, delta) in [
        (
            "field-end-frames",
            "An end line's frames one short of rows x columns - missing",
            "E.frames",
            -1i64,
        ),
        (
            "field-end-rows",
            "An end line's rows one above the header's rows",
            "E.rows",
            1,
        ),
    ] {
        out.push(one_field(name, about, g, field, |l, f| {
            let i = l.nth(b'E', 0);
            let v: i64 = l.get(i, f).parse().unwrap_or(0);
            l.set_field(i, f, &(v + delta).to_string());
        }));
    }
    out.push(one_field(
        "field-object-peak-mag",
        "An object line whose peak_mag, doubled, no longer makes its own peak under the header's thresholds",
        g,
        "O.peak_mag",
        |l, f| {
            let i = l.nth(b'O', 0);
            let v = l.num_of(i, f) * 2;
            l.set_field(i, f, &v.to_string());
        },
    ));
    out.push(one_field(
        "field-object-box",
        "An object line whose peak row lies outside its box",
        g,
        "O.peak_row",
        |l, f| {
            let i = l.nth(b'O', 0);
            l.set_field(i, f, "0");
        },
    ));
    out.push(damaged(
        "verdict-good-with-objects-left-out",
        "An end line with unobj 1 and verdict good",
        g.1,
        |l| {
            let i = l.nth(b'E', 0);
            l.set_key(i, "unobj", "1").set_key(i, "verdict", "good");
        },
    ));
    out.push(one_field(
        "misplaced",
        "An end line counting one misplaced map",
        g,
        "E.misplaced",
        |l, f| {
            let i = l.nth(b'E', 0);
            l.set_field(i, f, "1");
        },
    ));
    out
}

/// Lines out of the protocol's order.
fn order(g: &Lines) -> Vec<Vector> {
    let row_with = |l: &Lines, n: u64| {
        (0..l.0.len())
            .find(|&i| l.0[i].starts_with(b"R,") && l.num_of(i, "listed") >= n)
            .unwrap_or(0)
    };
    vec![
        damaged(
            "order-rows-back",
            "Row 5's row line moved before row 4's lines",
            g,
            |l| {
                let (a, b) = (l.find("R,4,"), l.find("R,5,"));
                l.mv(b, a);
            },
        ),
        damaged(
            "order-defect-after-scores",
            "A defect line moved after its row's score lines",
            g,
            |l| {
                let r = row_with(l, 1);
                l.mv(r + 1, r + 1 + l.num_of(r, "listed") as usize + 1);
            },
        ),
        damaged(
            "order-defects-not-strongest",
            "A row's first two defect lines swapped",
            g,
            |l| {
                let r = row_with(l, 2);
                l.0.swap(r + 1, r + 2);
            },
        ),
        damaged(
            "order-scores-col0",
            "A row's two score lines swapped",
            g,
            |l| {
                let i = l.nth(b'S', 0);
                l.0.swap(i, i + 1);
            },
        ),
        damaged(
            "order-object-early",
            "An object line moved before the row that closes it",
            g,
            |l| {
                let o = l.nth(b'O', 0);
                l.mv(o, 3);
            },
        ),
        damaged(
            "order-object-late",
            "An object line moved after the lines of the row following the one that closed it",
            g,
            |l| {
                let o = l.nth(b'O', 0);
                let next = (o + 1..l.0.len())
                    .find(|&i| l.0[i].starts_with(b"R,"))
                    .unwrap_or(o);
                let after = (next + 1..l.0.len())
                    .find(|&i| l.0[i].starts_with(b"R,"))
                    .unwrap_or(next);
                l.mv(o, after - 1);
            },
        ),
    ]
}

/// Lines lost (without a CRC error: never received) or received twice.
fn lost_and_repeated(g: &Lines) -> Vec<Vector> {
    let mut out = Vec::new();
    for (kind, name, n) in [
        (b'R', "row", 3),
        (b'D', "defect", 0),
        (b'S', "scores", 4),
        (b'O', "object", 0),
    ] {
        out.push(damaged(
            &format!("lost-{name}"),
            &format!(
                "A {} line never received (no dropped count for it)",
                kind as char
            ),
            g,
            |l| {
                let i = l.nth(kind, n);
                l.remove(i);
            },
        ));
    }
    for (kind, name, n) in [(b'R', "row", 3), (b'S', "scores", 4), (b'O', "object", 0)] {
        out.push(damaged(
            &format!("repeated-{name}"),
            &format!("A {} line received twice", kind as char),
            g,
            |l| {
                let i = l.nth(kind, n);
                let line = l.0[i].clone();
                l.insert(i + 1, line);
            },
        ));
    }
    out
}

/// Lines with a valid CRC whose content other lines contradict.
fn contradictions(g: &Lines, d: &Lines) -> Vec<Vector> {
    let mut out = Vec::new();
    for (base, lines, with) in [
        ((SCORES, g), "S", "its S lines"),
        ((DEFECT_LINES, d), "D", "its D lines (no S lines)"),
    ] {
        for (field, name) in [
            ("peak", "peak"),
            ("area", "area"),
            ("col1", "box"),
            ("centroid_col_q8", "centroid"),
            ("peak_power", "peak-power"),
        ] {
            out.push(one_field(
                &format!("cross-object-{name}-{}", lines.to_lowercase()),
                &format!(
                    "The first object line's {field} one higher, sealed again: {with} contradict it"
                ),
                base,
                &format!("O.{field}"),
                |l, f| {
                    let i = l.nth(b'O', 0);
                    let v = l.num_of(i, f) + 1;
                    l.set_field(i, f, &v.to_string());
                },
            ));
        }
    }
    let g = (SCORES, g);
    out.push(one_field(
        "cross-object-channels",
        "The distance object's channels claiming the power channel too",
        g,
        "O.channels",
        |l, f| {
            let i = l.nth(b'O', 0);
            l.set_field(i, f, "48");
        },
    ));
    out.push(one_field(
        "cross-object-ids",
        "The two objects' ids swapped: each line in its place, but the ids against the order the objects open",
        g,
        "O.id",
        |l, f| {
            let (a, b) = (l.nth(b'O', 0), l.nth(b'O', 1));
            let (ia, ib) = (l.get(a, f), l.get(b, f));
            l.set_field(a, f, &ib).set_field(b, f, &ia);
        },
    ));
    out.push(one_field(
        "cross-defect-magnitude",
        "A defect line's magnitude one step up: its position's score says otherwise",
        g,
        "D.mag",
        |l, f| {
            let i = l.nth(b'D', 0);
            let m = l.num_of(i, f);
            l.set_field(i, f, &(m + 1).to_string());
        },
    ));
    out.push(one_field(
        "cross-row-max",
        "A row line's max one below the largest magnitude of its score lines",
        g,
        "R.max",
        |l, f| {
            let i = (0..l.0.len())
                .find(|&i| l.0[i].starts_with(b"R,") && l.num_of(i, f) > 0)
                .unwrap_or(0);
            let m = l.num_of(i, f);
            l.set_field(i, f, &(m - 1).to_string());
        },
    ));
    for (name, about, field, value) in [
        (
            "cross-end-defects",
            "An end line's defects one above the row lines' sum (and the objects' areas)",
            "E.defects",
            None,
        ),
        (
            "cross-end-clipped",
            "An end line counting one clipped score that no score line flags",
            "E.clipped",
            Some("1"),
        ),
    ] {
        out.push(one_field(name, about, g, field, |l, f| {
            let i = l.nth(b'E', 0);
            let v: u64 = l.get(i, f).parse().unwrap_or(0);
            l.set_field(i, f, value.unwrap_or(&(v + 1).to_string()));
        }));
    }
    out
}

/// One position of a score line with these flags and magnitude (the power
/// and spread magnitudes 0), as the encoder writes it.
fn position(flags: u8, mag: u32) -> String {
    let p = cvm_core::PositionScore {
        mag,
        flags,
        ..Default::default()
    };
    String::from_utf8_lossy(&encode_score(&p)).into_owned()
}
