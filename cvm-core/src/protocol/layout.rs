//! Every line type's fields in their order on the wire, by the names
//! docs/protocol.md gives them: the one list the decoder's messages, the
//! conformance vectors and the documentation's line formats are checked
//! against (core-tests `protocol_layout`, dmap's `vectors`).
//!
//! `H` and `E` fields are `key=value` with these keys; `R`, `D`, `S` and
//! `O` fields are values alone, at these places after the type letter.

/// `H`: the header, once when a scan starts.
pub const HEADER: &[&str] = &[
    "v", "fw", "j", "cols", "k", "b", "w", "norm", "fs", "thr", "pthr", "sthr", "q", "scores",
    "dcap", "rst", "boots", "rows", "src", "store",
];
/// `R`: a row's summary.
pub const ROW: &[&str] = &[
    "row",
    "max",
    "argmax",
    "pmax",
    "pargmax",
    "defects",
    "listed",
    "no_data",
    "dark",
    "saturated",
];
/// `D`: a defective position.
pub const DEFECT: &[&str] = &["row", "col", "mag", "pmag", "smag", "strength", "flags"];
/// `S`: a row's positions from `col0`, [`super::SCORE_CHARS`] characters each.
pub const SCORES: &[&str] = &["row", "col0", "chars"];
/// `O`: a defect object, when it closes.
pub const OBJECT: &[&str] = &[
    "id",
    "row0",
    "row1",
    "col0",
    "col1",
    "area",
    "peak",
    "peak_row",
    "peak_col",
    "peak_mag",
    "peak_power",
    "peak_spread",
    "centroid_row_q8",
    "centroid_col_q8",
    "channels",
];
/// `E`: the end of a scan.
pub const END: &[&str] = &[
    "rows",
    "frames",
    "missing",
    "dark",
    "sat",
    "defects",
    "obj",
    "unobj",
    "rejected",
    "extra",
    "bad",
    "clipped",
    "misplaced",
    "dropped",
    "verdict",
];

/// The fields of lines of type `kind` (`b'H'`, `b'R'`, ...), or `None`
/// for a type the result lines do not have.
pub fn fields(kind: u8) -> Option<&'static [&'static str]> {
    Some(match kind {
        b'H' => HEADER,
        b'R' => ROW,
        b'D' => DEFECT,
        b'S' => SCORES,
        b'O' => OBJECT,
        b'E' => END,
        _ => return None,
    })
}

/// Where field `name` of a `kind` line stands among the line's
/// comma-separated fields (0 is the type letter).
pub fn place(kind: u8, name: &str) -> Option<usize> {
    fields(kind)?.iter().position(|f| *f == name).map(|i| i + 1)
}
