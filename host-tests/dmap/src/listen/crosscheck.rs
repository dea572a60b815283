//! Cross-checks of a finished scan, line against line (docs/protocol.md,
//! "What a decoder checks"): the end line's totals against the row
//! lines, each row line against its score lines, each defect line against
//! its position's score and its row's strongest defects, and each object
//! line against the defective positions the score and defect lines show
//! (8-connected components, rebuilt here from the document's definitions).
//! Each disagreement names the line (its number) and the fields.

use super::linechecks::decide;
use super::scan::{Kind, LineError, ScanResult};
use cvm_core::flags;
use cvm_core::objects::Object;
use cvm_core::protocol::{EndInfo, ScoreValue};
use std::collections::{BTreeMap, BTreeSet};

/// A defective position: its magnitudes, decision bits and strength.
#[derive(Clone, Copy, Debug)]
struct Position {
    mag: u32,
    pmag: u16,
    smag: u32,
    bits: u8,
    strength: u32,
}

/// Every cross-check of `s`, whose end line `e` came on line `line`.
pub(super) fn cross_check(s: &ScanResult, e: &EndInfo, line: usize) -> Vec<LineError> {
    let mut out = Vec::new();
    let mut push = |line: usize, what: String| {
        out.push(LineError {
            line,
            kind: Kind::CrossCheck,
            what,
        })
    };
    for (l, what) in totals_against_rows(s, e, line) {
        push(l, what);
    }
    for (l, what) in rows_against_scores(s, e) {
        push(l, what);
    }
    for (l, what) in defects_against_scores(s) {
        push(l, what);
    }
    for (l, what) in objects_against_positions(s, e, line) {
        push(l, what);
    }
    out
}

/// The end line's `missing`, `dark`, `sat` and `defects` are the sums of
/// the row lines' counts (when every row's line arrived), its `clipped`
/// the positions flagged CLIPPED (when every score arrived).
fn totals_against_rows(s: &ScanResult, e: &EndInfo, line: usize) -> Vec<(usize, String)> {
    let t = &e.totals;
    let mut out = Vec::new();
    for (&row, &l) in s.row_lines.range(t.rows..) {
        out.push((
            l,
            format!("R line of row {row}: past the end line's {} rows", t.rows),
        ));
    }
    let rows = s.rows.range(..t.rows);
    if rows.clone().count() as u64 == u64::from(t.rows) {
        let sum = |f: fn(&cvm_core::RowSummary) -> u32| -> u64 {
            rows.clone().map(|(_, r)| u64::from(f(r))).sum()
        };
        for (key, total, rows_name, got) in [
            ("missing", t.missing, "no_data", sum(|r| r.no_data)),
            ("dark", t.dark, "dark", sum(|r| r.dark)),
            ("sat", t.saturated, "saturated", sum(|r| r.saturated)),
            ("defects", t.defects, "defects", sum(|r| r.defects)),
        ] {
            if u64::from(total) != got {
                out.push((
                    line,
                    format!(
                        "end line: {key} {total}, but the R lines' {rows_name} add up to {got}"
                    ),
                ));
            }
        }
    }
    if let Some(scores) = complete_scores(s, t.rows) {
        let clipped = scores
            .values()
            .flat_map(|r| r.values())
            .filter(|v| v.flags & flags::CLIPPED != 0)
            .count() as u64;
        if clipped != u64::from(t.clipped) {
            out.push((
                line,
                format!(
                    "end line: clipped {}, but the S lines flag {clipped} position(s) CLIPPED",
                    t.clipped
                ),
            ));
        }
    }
    out
}

/// The scan's scores when every position of its `rows` rows has one.
fn complete_scores(s: &ScanResult, rows: u32) -> Option<&BTreeMap<u32, BTreeMap<u32, ScoreValue>>> {
    // At most as many rows as arrived are looked at.
    (s.scores.len() as u64 >= u64::from(rows) && (0..rows).all(|r| row_complete(s, r)))
        .then_some(&s.scores)
}

fn row_complete(s: &ScanResult, row: u32) -> bool {
    s.scores.get(&row).is_some_and(|c| c.len() == s.cols)
}

/// Each row line whose score lines all arrived: its summary as the scores
/// make it (the largest magnitudes among the positions with data, the
/// leftmost of equals, and the counts), and its defect lines the `dcap`
/// strongest, strongest first and leftmost among equals.
fn rows_against_scores(s: &ScanResult, e: &EndInfo) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for (&row, r) in s.rows.range(..e.totals.rows) {
        let (Some(scores), Some(&l)) = (s.scores.get(&row), s.row_lines.get(&row)) else {
            continue;
        };
        if scores.len() != s.cols {
            continue;
        }
        let mut want = cvm_core::RowSummary {
            row,
            ..Default::default()
        };
        let mut defects = Vec::new();
        for (&c, v) in scores {
            if v.flags & flags::NO_DATA != 0 {
                want.no_data += 1;
                continue;
            }
            want.dark += u32::from(v.flags & flags::DARK != 0);
            want.saturated += u32::from(v.flags & flags::SATURATED != 0);
            if v.flags & flags::DEFECT != 0 {
                want.defects += 1;
                defects.push((decide(v.mag, v.pmag, v.smag, s.thresholds()).1, c));
            }
            if want.argmax.is_none() || v.mag > want.max {
                (want.max, want.argmax) = (v.mag, Some(c));
            }
            if want.pargmax.is_none() || u32::from(v.pmag) > want.pmax {
                (want.pmax, want.pargmax) = (u32::from(v.pmag), Some(c));
            }
        }
        let show = |o: Option<u32>| o.map_or("-".to_string(), |c| c.to_string());
        let fields = [
            ("max", r.max.to_string(), want.max.to_string()),
            ("argmax", show(r.argmax), show(want.argmax)),
            ("pmax", r.pmax.to_string(), want.pmax.to_string()),
            ("pargmax", show(r.pargmax), show(want.pargmax)),
            ("defects", r.defects.to_string(), want.defects.to_string()),
            ("no_data", r.no_data.to_string(), want.no_data.to_string()),
            ("dark", r.dark.to_string(), want.dark.to_string()),
            (
                "saturated",
                r.saturated.to_string(),
                want.saturated.to_string(),
            ),
        ];
        let wrong: Vec<String> = fields
            .iter()
            .filter(|(_, got, want)| got != want)
            .map(|(k, got, want)| format!("{k} {got} (the S lines make {want})"))
            .collect();
        if !wrong.is_empty() {
            out.push((l, format!("R line of row {row}: {}", wrong.join(", "))));
        }
        defects.sort_by_key(|&(strength, c)| (std::cmp::Reverse(strength), c));
        let want_cols: Vec<u32> = defects
            .iter()
            .take(usize::from(s.max_defect_lines))
            .map(|&(_, c)| c)
            .collect();
        let listed: Vec<u32> = s
            .defects
            .iter()
            .filter(|d| d.row == row)
            .map(|d| d.col)
            .collect();
        if listed != want_cols {
            out.push((
                l,
                format!(
                    "D lines of row {row} list columns {listed:?}, but its S lines make the strongest {want_cols:?} (dcap {})",
                    s.max_defect_lines
                ),
            ));
        }
    }
    out
}

/// Each defect line whose position has a score: the same magnitudes and flags.
fn defects_against_scores(s: &ScanResult) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for d in &s.defects {
        let Some(v) = s.scores.get(&d.row).and_then(|r| r.get(&d.col)) else {
            continue;
        };
        let fields = [
            ("mag", d.mag, v.mag),
            ("pmag", u32::from(d.pmag), u32::from(v.pmag)),
            ("smag", d.smag, v.smag),
            ("flags", u32::from(d.flags), u32::from(v.flags)),
        ];
        let wrong: Vec<String> = fields
            .iter()
            .filter(|(_, a, b)| a != b)
            .map(|(k, a, b)| format!("{k} {a} (its S line: {b})"))
            .collect();
        if !wrong.is_empty() {
            out.push((
                d.line,
                format!(
                    "D line of row {} column {}: {}",
                    d.row,
                    d.col,
                    wrong.join(", ")
                ),
            ));
        }
    }
    out
}

/// The defective positions the lines show, and the rows they show whole:
/// a row whose score lines all arrived, or whose defect lines list every
/// defect its row line counts.
fn known_positions(s: &ScanResult, rows: u32) -> (BTreeMap<(u32, u32), Position>, BTreeSet<u32>) {
    let mut known = BTreeMap::new();
    let mut whole = BTreeSet::new();
    // The rows lines arrived for, never `0..rows`: an end line may claim
    // billions of rows.
    let seen: BTreeSet<u32> = s.scores.keys().chain(s.rows.keys()).copied().collect();
    for row in seen.into_iter().filter(|&r| r < rows) {
        if row_complete(s, row) {
            whole.insert(row);
            for (&c, v) in &s.scores[&row] {
                if v.flags & flags::NO_DATA == 0 && v.flags & flags::DEFECT != 0 {
                    let strength = decide(v.mag, v.pmag, v.smag, s.thresholds()).1;
                    let bits = v.flags & flags::DEFECT;
                    known.insert(
                        (row, c),
                        Position {
                            mag: v.mag,
                            pmag: v.pmag,
                            smag: v.smag,
                            bits,
                            strength,
                        },
                    );
                }
            }
        } else if let Some(r) = s.rows.get(&row) {
            let listed: Vec<_> = s.defects.iter().filter(|d| d.row == row).collect();
            if listed.len() as u64 == u64::from(r.defects) {
                whole.insert(row);
                for d in listed {
                    let p = Position {
                        mag: d.mag,
                        pmag: d.pmag,
                        smag: d.smag,
                        bits: d.flags & flags::DEFECT,
                        strength: d.strength,
                    };
                    known.insert((row, d.col), p);
                }
            }
        }
    }
    (known, whole)
}

/// An object as the document defines it, from a set of positions.
fn object_of(id: u32, cells: &[((u32, u32), Position)]) -> Object {
    let mut o = Object {
        id,
        row0: u32::MAX,
        col0: u32::MAX,
        ..Object::default()
    };
    let (mut w, mut wr, mut wc) = (0u128, 0u128, 0u128);
    // Raster order: the first of equal peaks is kept.
    for &((r, c), p) in cells {
        (o.row0, o.row1) = (o.row0.min(r), o.row1.max(r));
        (o.col0, o.col1) = (o.col0.min(c), o.col1.max(c));
        o.area += 1;
        o.channels |= p.bits;
        if o.area == 1 || p.strength > o.peak {
            (o.peak, o.peak_row, o.peak_col) = (p.strength, r, c);
            (o.peak_mag, o.peak_power, o.peak_spread) = (p.mag, p.pmag, p.smag);
        }
        let weight = u128::from((p.strength >> 8).clamp(1, 1 << 24));
        w += weight;
        wr += weight * u128::from(r);
        wc += weight * u128::from(c);
    }
    o.centroid_row_q8 = (wr * 256 / w.max(1)) as u64;
    o.centroid_col_q8 = (wc * 256 / w.max(1)) as u64;
    o
}

/// 8-connected components of `known`, each in raster order.
fn components(known: &BTreeMap<(u32, u32), Position>) -> Vec<Vec<((u32, u32), Position)>> {
    let mut seen = BTreeSet::new();
    let mut out = Vec::new();
    for &start in known.keys() {
        if !seen.insert(start) {
            continue;
        }
        let mut stack = vec![start];
        let mut cells = Vec::new();
        while let Some((r, c)) = stack.pop() {
            cells.push(((r, c), known[&(r, c)]));
            for nr in r.saturating_sub(1)..=r.saturating_add(1) {
                for nc in c.saturating_sub(1)..=c.saturating_add(1) {
                    if known.contains_key(&(nr, nc)) && seen.insert((nr, nc)) {
                        stack.push((nr, nc));
                    }
                }
            }
        }
        cells.sort_by_key(|&(at, _)| at);
        out.push(cells);
    }
    out
}

/// The fields of `got` that differ from `want`'s.
fn object_diff(got: &Object, want: &Object) -> Vec<String> {
    let f = |o: &Object| {
        [
            ("row0", u64::from(o.row0)),
            ("row1", u64::from(o.row1)),
            ("col0", u64::from(o.col0)),
            ("col1", u64::from(o.col1)),
            ("area", u64::from(o.area)),
            ("peak", u64::from(o.peak)),
            ("peak_row", u64::from(o.peak_row)),
            ("peak_col", u64::from(o.peak_col)),
            ("peak_mag", u64::from(o.peak_mag)),
            ("peak_power", u64::from(o.peak_power)),
            ("peak_spread", u64::from(o.peak_spread)),
            ("centroid_row_q8", o.centroid_row_q8),
            ("centroid_col_q8", o.centroid_col_q8),
            ("channels", u64::from(o.channels)),
        ]
    };
    f(got)
        .iter()
        .zip(f(want))
        .filter(|(a, b)| a.1 != b.1)
        .map(|(a, b)| format!("{} {} (its positions make {})", a.0, a.1, b.1))
        .collect()
}

/// Each object line against the positions the score and defect lines
/// show. With every row shown whole and no position left out of the
/// objects (`unobj` 0), the objects are exactly the 8-connected
/// components: every field is checked, every component must have its line
/// and the ids must increase in the order the components open; otherwise
/// the peak alone, where its row is shown whole.
fn objects_against_positions(s: &ScanResult, e: &EndInfo, line: usize) -> Vec<(usize, String)> {
    let rows = e.totals.rows;
    let (known, whole) = known_positions(s, rows);
    let mut out = Vec::new();
    let lines = s.object_lines.iter().copied();
    if whole.len() as u64 == u64::from(rows) && e.totals.unobjected == 0 {
        let comps = components(&known);
        let mut of_cell = BTreeMap::new();
        for (k, cells) in comps.iter().enumerate() {
            for &(at, _) in cells {
                of_cell.insert(at, k);
            }
        }
        let mut claimed: BTreeMap<usize, u32> = BTreeMap::new();
        for (o, l) in s.objects.iter().zip(lines) {
            let at = format!("O line of object {}", o.id);
            let Some(&k) = of_cell.get(&(o.peak_row, o.peak_col)) else {
                out.push((l, format!("{at}: its peak at row {} column {} is no defective position of the S or D lines", o.peak_row, o.peak_col)));
                continue;
            };
            if let Some(other) = claimed.insert(k, o.id) {
                out.push((l, format!("{at}: the positions of object {other} again")));
                continue;
            }
            let wrong = object_diff(o, &object_of(o.id, &comps[k]));
            if !wrong.is_empty() {
                out.push((l, format!("{at}: {}", wrong.join(", "))));
            }
        }
        // Ids in the order the components open (their first position).
        let mut order: Vec<(usize, u32)> = claimed.iter().map(|(&k, &id)| (k, id)).collect();
        order.sort_by_key(|&(k, _)| comps[k][0].0);
        for pair in order.windows(2) {
            let ((ka, a), (kb, b)) = (pair[0], pair[1]);
            if b < a {
                let l = s
                    .objects
                    .iter()
                    .position(|o| o.id == b)
                    .map_or(line, |i| s.object_lines[i]);
                out.push((l, format!(
                    "O line of object {b}: its id is below that of object {a}, which opens earlier (at row {} column {}, before row {} column {})",
                    comps[ka][0].0.0, comps[ka][0].0.1, comps[kb][0].0.0, comps[kb][0].0.1
                )));
            }
        }
        if s.objects_arrived == u64::from(e.totals.objects) {
            for (k, cells) in comps.iter().enumerate() {
                if !claimed.contains_key(&k) {
                    let (r, c) = cells[0].0;
                    out.push((line, format!(
                        "the {} defective position(s) from row {r} column {c} (S or D lines) are in no O line",
                        cells.len()
                    )));
                }
            }
        }
        return out;
    }
    for (o, l) in s.objects.iter().zip(lines) {
        if !whole.contains(&o.peak_row) {
            continue;
        }
        let at = format!("O line of object {}", o.id);
        match known.get(&(o.peak_row, o.peak_col)) {
            None => out.push((l, format!("{at}: its peak at row {} column {} is no defective position of the S or D lines", o.peak_row, o.peak_col))),
            Some(p) => {
                let want = Object {
                    peak: p.strength,
                    peak_mag: p.mag,
                    peak_power: p.pmag,
                    peak_spread: p.smag,
                    channels: o.channels | p.bits,
                    ..*o
                };
                let wrong = object_diff(o, &want);
                if !wrong.is_empty() {
                    out.push((l, format!("{at}: {}", wrong.join(", "))));
                }
            }
        }
    }
    out
}
