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

/// One damaged vector: `base` changed by `edit`.
fn damaged(name: &str, about: &str, base: &Lines, edit: impl FnOnce(&mut Lines)) -> Vector {
    let mut l = base.clone();
    edit(&mut l);
    Vector {
        name: name.to_string(),
        about: about.to_string(),
        bytes: l.bytes(),
    }
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
            f.swap(3, 4);
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
                f[2].insert(0, '0');
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
    });
    out.push(Vector {
        name: "no-scan".into(),
        about: "Lines that are no protocol: each reported, and no scan".into(),
        bytes: b"hello\nOK\n\n".to_vec(),
    });
    out.push(damaged(
        "version-8",
        "A header of version 8: a problem of the scan, which is decoded as far as it goes",
        g,
        |l| {
            l.set_key(0, "v", "8");
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
        out.push(damaged(
            name,
            &format!(
                "Header {key}={value}, a valid CRC: outside the field's range, the header refused"
            ),
            g,
            |l| {
                l.set_key(0, key, value);
            },
        ));
    }
    out.push(damaged(
        "range-pmax",
        "A row line's pmax 46341, above the largest power magnitude",
        g,
        |l| {
            let i = l.nth(b'R', 2);
            l.set(i, 4, "46341");
        },
    ));
    out.push(damaged(
        "range-strength",
        "A defect line's strength 65535, below a defect's least",
        g,
        |l| {
            let i = l.nth(b'D', 0);
            l.set(i, 5, "65535");
        },
    ));
    out.push(damaged(
        "range-defect-flags",
        "A defect line's flags 1 (NO_DATA, no channel)",
        g,
        |l| {
            let i = l.nth(b'D', 0);
            l.set(i, 6, "1");
        },
    ));
    out.push(damaged(
        "range-position",
        "A score line's first position NO_DATA with a magnitude of 1",
        g,
        |l| {
            let i = l.nth(b'S', 0);
            let chars = l.field(i, 3);
            l.set(i, 3, &format!("BAAAAAAAB{}", &chars[9..]));
        },
    ));
    out.push(damaged(
        "range-clipped",
        "A score line's first position CLIPPED below the top magnitude",
        g,
        |l| {
            let i = l.nth(b'S', 0);
            let chars = l.field(i, 3);
            // Flags 24 (CLIPPED and CVM_DEFECT), magnitude 5.
            l.set(i, 3, &format!("YAAAAAAAF{}", &chars[9..]));
        },
    ));
    out.push(damaged(
        "range-object-channels",
        "An object line's channels 0",
        g,
        |l| {
            let i = l.nth(b'O', 0);
            l.set(i, 14, "0");
        },
    ));
    out.push(damaged(
        "field-header-q",
        "Header q one below what a scorer of its configuration (5x5, paper kernels, uniform weights, normalised) has",
        g,
        |l| {
            let q: i64 = l.key(0, "q").parse().unwrap_or(0);
            l.set_key(0, "q", &(q - 1).to_string());
        },
    ));
    out.push(damaged(
        "field-row-argmax",
        "A row line's argmax at column 30 of a 30-column scan",
        g,
        |l| {
            let i = l.nth(b'R', 1);
            l.set(i, 3, "30");
        },
    ));
    out.push(damaged(
        "field-row-listed",
        "A row line listing one defect line fewer than min(defects, dcap)",
        g,
        |l| {
            let i = (0..l.0.len())
                .find(|&i| l.0[i].starts_with(b"R,") && l.num(i, 7) > 0)
                .unwrap_or(0);
            let listed = l.num(i, 7);
            l.set(i, 7, &(listed - 1).to_string());
            l.remove(i + 1);
        },
    ));
    out.push(damaged(
        "field-defect-strength",
        "A defect line's strength one above what its magnitudes and the thresholds make",
        g,
        |l| {
            let i = l.nth(b'D', 0);
            let s = l.num(i, 5);
            l.set(i, 5, &(s + 1).to_string());
        },
    ));
    out.push(damaged(
        "field-end-frames",
        "An end line's frames one short of rows x columns - missing",
        g,
        |l| {
            let i = l.nth(b'E', 0);
            let f: u64 = l.key(i, "frames").parse().unwrap_or(0);
            l.set_key(i, "frames", &(f - 1).to_string());
        },
    ));
    out.push(damaged(
        "field-end-rows",
        "An end line's rows one above the header's rows",
        g,
        |l| {
            let i = l.nth(b'E', 0);
            let r: u64 = l.key(i, "rows").parse().unwrap_or(0);
            l.set_key(i, "rows", &(r + 1).to_string());
        },
    ));
    out.push(damaged(
        "field-object-box",
        "An object line whose peak lies outside its box",
        g,
        |l| {
            let i = l.nth(b'O', 0);
            l.set(i, 8, "0");
        },
    ));
    out.push(damaged(
        "verdict-good-with-objects-left-out",
        "An end line with unobj 1 and verdict good",
        g,
        |l| {
            let i = l.nth(b'E', 0);
            l.set_key(i, "unobj", "1").set_key(i, "verdict", "good");
        },
    ));
    out.push(damaged(
        "misplaced",
        "An end line counting one misplaced map",
        g,
        |l| {
            let i = l.nth(b'E', 0);
            l.set_key(i, "misplaced", "1");
        },
    ));
    out
}

/// Lines out of the protocol's order.
fn order(g: &Lines) -> Vec<Vector> {
    let row_with = |l: &Lines, n: u64| {
        (0..l.0.len())
            .find(|&i| l.0[i].starts_with(b"R,") && l.num(i, 7) >= n)
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
                l.mv(r + 1, r + 1 + l.num(r, 7) as usize + 1);
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
    // O,id,row0,row1,col0,col1,area,peak,peak_row,peak_col,peak_mag,peak_power,centroid_row_q8,centroid_col_q8,channels
    for (base, lines, with) in [
        (g, "S", "its S lines"),
        (d, "D", "its D lines (no S lines)"),
    ] {
        for (field, name, delta) in [
            (7, "peak", 1i64),
            (6, "area", 1),
            (5, "box", 1),
            (12, "centroid", 1),
            (11, "peak-power", 1),
        ] {
            out.push(damaged(
                &format!("cross-object-{name}-{}", lines.to_lowercase()),
                &format!("The first object line's {name} changed by {delta}, sealed again: {with} contradict it"),
                base,
                |l| {
                    let i = l.nth(b'O', 0);
                    let v = l.num(i, field) as i64 + delta;
                    l.set(i, field, &v.to_string());
                },
            ));
        }
    }
    out.push(damaged(
        "cross-object-channels",
        "The distance object's channels claiming the power channel too",
        g,
        |l| {
            let i = l.nth(b'O', 0);
            l.set(i, 14, "48");
        },
    ));
    out.push(damaged(
        "cross-object-ids",
        "The two objects' ids swapped: each line in its place, but the ids against the order the objects open",
        g,
        |l| {
            let (a, b) = (l.nth(b'O', 0), l.nth(b'O', 1));
            let (ia, ib) = (l.field(a, 1), l.field(b, 1));
            l.set(a, 1, &ib).set(b, 1, &ia);
        },
    ));
    out.push(damaged(
        "cross-defect-magnitude",
        "A defect line's magnitude one step up: its position's score says otherwise",
        g,
        |l| {
            let i = l.nth(b'D', 0);
            let m = l.num(i, 3);
            l.set(i, 3, &(m + 1).to_string());
        },
    ));
    out.push(damaged(
        "cross-row-max",
        "A row line's max one below the largest magnitude of its score lines",
        g,
        |l| {
            let i = (0..l.0.len())
                .find(|&i| l.0[i].starts_with(b"R,") && l.num(i, 2) > 0)
                .unwrap_or(0);
            let m = l.num(i, 2);
            l.set(i, 2, &(m - 1).to_string());
        },
    ));
    out.push(damaged(
        "cross-end-defects",
        "An end line's defects one above the row lines' sum (and the objects' areas)",
        g,
        |l| {
            let i = l.nth(b'E', 0);
            let v: u64 = l.key(i, "defects").parse().unwrap_or(0);
            l.set_key(i, "defects", &(v + 1).to_string());
        },
    ));
    out.push(damaged(
        "cross-end-clipped",
        "An end line counting one clipped score that no score line flags",
        g,
        |l| {
            let i = l.nth(b'E', 0);
            l.set_key(i, "clipped", "1");
        },
    ));
    out
}
