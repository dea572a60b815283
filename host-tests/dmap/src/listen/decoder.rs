//! The stream decoder: one line at a time, each line type to its handler,
//! every line checked against the scan it belongs to and the order of
//! docs/protocol.md. A line's CRC and fields are checked by
//! `cvm_core::protocol::parse`, beside the encoder; what needs memory (the
//! scans, their images, objects and problems) is kept here, within bounds.

use super::checks::{check_complete, object_fault};
use super::scan::{Defect, LineError, MAX_IMAGE_POSITIONS, Order, ScanResult};
use cvm_core::RowSummary;
use cvm_core::objects::Object;
use cvm_core::protocol::{self, EndInfo, HeaderInfo, Line};

/// The oldest protocol version whose streams this decoder reads.
pub const OLDEST_VERSION: u32 = 5;

/// Scans one run decodes by default, and at most (`--max-scans`).
pub const DEFAULT_MAX_SCANS: u32 = 64;
pub const MAX_SCANS: u32 = 4096;

/// Row lines, defects and scores one run holds, over all its scans (the
/// largest image's worth, about 1.5 GB at most): memory does not grow with
/// the number of scans either.
pub const MAX_KEPT: usize = MAX_IMAGE_POSITIONS;

/// Line errors kept (and listed); beyond, they are only counted.
pub const MAX_ERRORS: usize = 1000;
/// Defect lines kept per scan (a scan of the largest image with a defect
/// listed at every position).
pub const MAX_DEFECTS: usize = MAX_IMAGE_POSITIONS;

/// The stream decoder: feed it lines, collect scans and errors. Memory is
/// bounded whatever the stream: at most `max_scans` scans, each with at
/// most [`MAX_IMAGE_POSITIONS`] scores and [`MAX_DEFECTS`] defects, and
/// [`MAX_ERRORS`] errors listed.
pub struct Decoder {
    line_no: usize,
    current: Option<ScanResult>,
    pub scans: Vec<ScanResult>,
    /// Damaged lines and lines outside any scan (the first [`MAX_ERRORS`]).
    pub errors: Vec<LineError>,
    /// Errors beyond [`MAX_ERRORS`], counted only.
    pub errors_not_listed: usize,
    /// Scans beyond `max_scans`, whose lines were skipped.
    pub scans_skipped: usize,
    skipping: bool,
    max_scans: usize,
    /// Row lines, defects and scores held, over all scans, and at most.
    kept: usize,
    max_kept: usize,
}

impl Default for Decoder {
    fn default() -> Self {
        Self::with_max_scans(DEFAULT_MAX_SCANS as usize)
    }
}

impl Decoder {
    pub fn new() -> Self {
        Self::default()
    }

    /// A decoder that keeps at most `max_scans` scans (at least one).
    pub fn with_max_scans(max_scans: usize) -> Self {
        Decoder {
            line_no: 0,
            current: None,
            scans: Vec::new(),
            errors: Vec::new(),
            errors_not_listed: 0,
            scans_skipped: 0,
            skipping: false,
            max_scans: max_scans.max(1),
            kept: 0,
            max_kept: MAX_KEPT,
        }
    }

    /// The same decoder holding at most `kept` row lines, defects and
    /// scores over all its scans (default [`MAX_KEPT`]).
    pub fn with_budget(mut self, kept: usize) -> Self {
        self.max_kept = kept;
        self
    }

    /// Line errors in all, listed or not.
    pub fn error_count(&self) -> usize {
        self.errors.len() + self.errors_not_listed
    }

    /// One line per kind of damage seen in the stream (none: the stream
    /// arrived whole): line errors, problems of scans, skipped scans.
    pub fn damage(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.error_count() > 0 {
            out.push(format!("{} line error(s)", self.error_count()));
        }
        for (k, s) in self.scans.iter().enumerate() {
            if s.problem_count() > 0 {
                out.push(format!("scan {}: {} problem(s)", k + 1, s.problem_count()));
            }
        }
        if self.scans_skipped > 0 {
            out.push(format!(
                "{} scan(s) beyond --max-scans {} skipped",
                self.scans_skipped, self.max_scans
            ));
        }
        out
    }

    /// A line too long for the protocol, of which only the length is known.
    pub fn feed_too_long(&mut self, len: usize) {
        self.line_no += 1;
        self.error(format!(
            "line of {len} bytes is longer than the protocol's {} (garbage or a lost newline)",
            protocol::MAX_LINE
        ));
    }

    /// Scans that have ended (an end line arrived).
    pub fn ended(&self) -> usize {
        self.scans.iter().filter(|s| s.end.is_some()).count()
    }

    fn error(&mut self, what: impl Into<String>) {
        if self.errors.len() < MAX_ERRORS {
            self.errors.push(LineError {
                line: self.line_no,
                what: what.into(),
            });
        } else {
            self.errors_not_listed += 1;
        }
    }

    fn problem(&mut self, what: impl Into<String>) {
        let e = LineError {
            line: self.line_no,
            what: what.into(),
        };
        match &mut self.current {
            Some(s) => s.add_problem(e),
            None => self.error(e.what),
        }
    }

    /// Decodes one line (with or without its newline).
    pub fn feed(&mut self, raw: &[u8]) {
        self.line_no += 1;
        let trimmed = raw.strip_suffix(b"\n").unwrap_or(raw);
        let trimmed = trimmed.strip_suffix(b"\r").unwrap_or(trimmed);
        if trimmed.is_empty() {
            return;
        }
        if self.skipping && !trimmed.starts_with(b"H,") {
            // A scan beyond --max-scans: its lines are counted, not kept.
            if trimmed.starts_with(b"E,") {
                self.skipping = false;
            }
            return;
        }
        // MAX_LINE counts the newline.
        if trimmed.len() >= protocol::MAX_LINE {
            self.error(format!(
                "line of {} bytes is longer than the protocol's {} (garbage or a lost newline)",
                trimmed.len() + 1,
                protocol::MAX_LINE
            ));
            return;
        }
        let line = match protocol::parse(trimmed) {
            Ok(l) => l,
            Err(e) => {
                self.error(e.to_string());
                return;
            }
        };
        match line {
            Line::Object(o) => self.object(o),
            Line::Header(h) => self.header(&h),
            Line::Row { summary, listed } => self.row(summary, listed),
            Line::Defect {
                row,
                col,
                mag,
                pmag,
                strength,
                flags,
            } => self.defect(row, col, mag, pmag, strength, flags),
            Line::Scores { row, col0, chars } => self.scores(row, col0, chars),
            Line::End(e) => self.end(e),
        }
    }

    /// An `H` line: a new scan, unless the run holds as many as it may.
    fn header(&mut self, h: &HeaderInfo<'_>) {
        self.skipping = false;
        if let Some(prev) = self.current.take() {
            self.error("new scan header before the previous scan's end line");
            self.scans.push(prev);
        }
        if self.scans.len() >= self.max_scans {
            self.scans_skipped += 1;
            self.skipping = true;
            if self.scans_skipped == 1 {
                self.error(format!(
                    "more than {} scans in one run: this scan and later ones are skipped (--max-scans)",
                    self.max_scans
                ));
            }
            return;
        }
        let mut s = ScanResult {
            version: h.version,
            firmware: h.firmware.to_string(),
            geometry: (h.j1, h.j2),
            cols: h.cols as usize,
            q: h.q,
            scores_enabled: h.scores,
            full_scale: h.full_scale,
            max_defect_lines: h.max_defect_lines,
            reset_cause: Some(h.reset_cause),
            boots: h.boots,
            kernels: h.kernels as char,
            kernel_size: h.kernel_size,
            weights: h.weights.to_string(),
            normalise: h.normalise,
            power_threshold: (h.power_threshold <= cvm_core::power::POWER_MAX)
                .then(|| cvm_core::power::to_units(h.power_threshold)),
            ..ScanResult::default()
        };
        s.threshold = s.units(h.threshold);
        // Version 6 only added fields to the header: 5 reads the same.
        if !(OLDEST_VERSION..=protocol::VERSION).contains(&h.version) {
            s.problems.push(LineError {
                line: self.line_no,
                what: format!(
                    "protocol version {} (this decoder reads {} to {})",
                    h.version,
                    OLDEST_VERSION,
                    protocol::VERSION
                ),
            });
        }
        self.current = Some(s);
    }

    /// An `R` line: the row's summary, the end of the previous row's lines.
    fn row(&mut self, summary: RowSummary, listed: u32) {
        let Some(s) = self.current.as_mut() else {
            return self.error("row line outside a scan (header lost?)");
        };
        if s.rows.contains_key(&summary.row) {
            return self.problem(format!("row {} reported twice", summary.row));
        }
        let order = s.order;
        s.order = Order {
            row: Some((summary.row, listed, 0)),
            ..Order::default()
        };
        if let Some((prev, ..)) = order.row
            && summary.row < prev
        {
            self.problem(format!(
                "row line of row {} after row {prev} (rows out of order)",
                summary.row
            ));
        }
        if let (Some((prev, ..)), Some((id, true))) = (order.row, order.last_object) {
            self.problem(format!(
                "object {id} ends in row {prev} but row {}'s line follows it: only the scan's end closes an object in the last row reported (out of order)",
                summary.row
            ));
        }
        self.check_defects_arrived(order);
        let Some(s) = self.current.as_mut() else {
            return;
        };
        if s.rows.len() >= MAX_IMAGE_POSITIONS || self.kept >= self.max_kept {
            return self.problem("more row lines than an image can hold; the rest ignored");
        }
        s.unlisted_defects += (summary.defects - listed.min(summary.defects)) as u64;
        s.rows.insert(summary.row, summary);
        self.kept += 1;
    }

    /// A `D` line: one of the row's strongest defects, checked against its
    /// row line and the previous `D` line.
    fn defect(&mut self, row: u32, col: u32, mag: u32, pmag: u16, strength: u32, flags: u8) {
        let Some(s) = self.current.as_mut() else {
            return self.error("defect line outside a scan (header lost?)");
        };
        if s.defects.len() >= MAX_DEFECTS || self.kept >= self.max_kept {
            return self.problem("more defect lines than an image can hold; the rest ignored");
        }
        self.kept += 1;
        let score = s.units(mag);
        s.defects.push(Defect {
            row,
            col,
            score,
            power: cvm_core::power::to_units(pmag as u32),
            strength,
            flags,
        });
        let order = &mut s.order;
        let what = match order.row {
            Some((r, ..)) if r != row => Some(format!(
                "defect line of row {row} among the lines of row {r} (out of order)"
            )),
            None => Some(format!(
                "defect line of row {row} before any row line (out of order)"
            )),
            Some(_) if order.last_scores.is_some() => Some(format!(
                "defect line of row {row} after its score lines (out of order)"
            )),
            Some(_) if order.last_object.is_some() => Some(format!(
                "defect line of row {row} after the object lines of its row (out of order)"
            )),
            Some((_, listed, arrived)) if arrived >= listed => Some(format!(
                "row {row} lists {listed} defect line(s); more arrived"
            )),
            Some(_) => match order.last_defect {
                Some((m, c)) if strength > m || (strength == m && col <= c) => Some(format!(
                    "defect lines of row {row} not strongest first (column {col} after column {c})"
                )),
                _ => None,
            },
        };
        if let Some((_, _, arrived)) = order.row.as_mut() {
            *arrived += 1;
        }
        order.last_defect = Some((strength, col));
        if let Some(what) = what {
            self.problem(what);
        }
        if flags & cvm_core::flags::DEFECT == 0 || strength < 1 << 16 {
            self.problem(format!(
                "defect line of row {row} column {col} is no defect (flags {flags}, strength {strength})"
            ));
        }
    }

    /// An `S` line: scores of part of the row, each position once.
    fn scores(&mut self, row: u32, col0: u32, chars: &[u8]) {
        let Some(s) = self.current.as_mut() else {
            return self.error("score line outside a scan (header lost?)");
        };
        let order = &mut s.order;
        let misplaced = match (order.row, order.last_scores) {
            (Some((r, ..)), _) if r != row => Some(format!(
                "score line of row {row} among the lines of row {r} (out of order)"
            )),
            (None, _) => Some(format!(
                "score line of row {row} before any row line (out of order)"
            )),
            (_, Some(c)) if col0 <= c => Some(format!(
                "score line of row {row} from column {col0} after the one from column {c} (out of order)"
            )),
            _ if order.last_object.is_some() => Some(format!(
                "score line of row {row} after the object lines of its row (out of order)"
            )),
            _ => None,
        };
        order.last_scores = Some(col0);
        if let Some(what) = misplaced {
            self.problem(what);
        }
        let Some(s) = self.current.as_mut() else {
            return;
        };
        let cols = s.cols;
        let n = chars.len() / protocol::SCORE_CHARS;
        if col0 as usize + n > cols {
            return self.problem(format!("score line for row {row} runs past column {cols}"));
        }
        if s.n_scores + n > MAX_IMAGE_POSITIONS || self.kept + n > self.max_kept {
            return self.problem("more scores than an image can hold; the rest ignored");
        }
        let mut added = 0;
        let line = s.scores.entry(row).or_default();
        let mut dup = false;
        for (k, c) in chars.chunks(protocol::SCORE_CHARS).enumerate() {
            // In range: `col0 + n <= cols` was checked above.
            if let Some(v) = protocol::decode_score(c) {
                let again = line.insert(col0 + k as u32, v).is_some();
                dup |= again;
                added += usize::from(!again);
            }
        }
        s.n_scores += added;
        self.kept += added;
        if dup {
            self.problem(format!(
                "scores of row {row} from column {col0} received twice"
            ));
        }
    }

    /// An `E` line: the scan's totals, and the scan cross-checked and filed.
    fn end(&mut self, e: EndInfo) {
        let Some(mut s) = self.current.take() else {
            return self.error("end line outside a scan (header lost?)");
        };
        s.end = Some(e);
        let order = s.order;
        self.current = Some(s);
        self.check_defects_arrived(order);
        let Some(mut s) = self.current.take() else {
            return;
        };
        check_complete(&mut s, self.line_no);
        self.scans.push(s);
    }

    /// An `O` line: filed with its scan, its place in the line order and
    /// its fields checked.
    fn object(&mut self, o: Object) {
        let Some(s) = self.current.as_mut() else {
            return self.error("object line outside a scan (header lost?)");
        };
        s.objects_arrived += 1;
        let id = o.id;
        let mut what = Vec::new();
        let order = &mut s.order;
        let ends_here = match order.row {
            None => {
                what.push(format!("object {id} before any row line (out of order)"));
                false
            }
            Some((r, ..)) if o.row1 > r => {
                what.push(format!(
                    "object {id} ends in row {}, after the last row reported ({r}): an object line follows the lines of the row that closes it (out of order)",
                    o.row1
                ));
                false
            }
            Some((r, ..)) => {
                let ends_here = o.row1 == r;
                match order.last_object {
                    Some((prev, true)) if !ends_here => what.push(format!(
                        "object {id}, closed by row {r}, after object {prev}, which only the scan's end closes (out of order)"
                    )),
                    Some((prev, prev_ends)) if prev_ends == ends_here && id <= prev => {
                        what.push(format!(
                            "object lines after row {r} not in increasing id ({id} after {prev})"
                        ))
                    }
                    _ => {}
                }
                ends_here
            }
        };
        order.last_object = Some((id, ends_here));
        if !s.object_ids.insert(id) {
            what.push(format!("object {id} reported twice in the scan"));
        }
        if let Some(bad) = object_fault(&o, s.cols) {
            what.push(format!("object {id}: {bad}"));
        }
        for w in what {
            self.problem(w);
        }
        let Some(s) = self.current.as_mut() else {
            return;
        };
        if s.objects.len() >= MAX_DEFECTS || self.kept >= self.max_kept {
            return self.problem("more object lines than an image can hold; the rest ignored");
        }
        self.kept += 1;
        s.objects.push(o);
    }

    /// After the last line of a row: as many `D` lines as its `R` line listed.
    fn check_defects_arrived(&mut self, order: Order) {
        if let Some((row, listed, arrived)) = order.row
            && arrived < listed
        {
            self.problem(format!(
                "row {row} lists {listed} defect line(s), {arrived} arrived"
            ));
        }
    }

    /// Ends the stream: a scan without its end line is kept and reported.
    pub fn finish(&mut self) {
        if let Some(s) = self.current.take() {
            self.error("stream ended before the scan's end line");
            self.scans.push(s);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_run_holds_a_bounded_number_of_scores_over_all_scans() {
        let scorer = crate::options::ScoringArgs::default().scorer(3, 3).unwrap();
        let settings = crate::stream::OutputArgs {
            threshold: Some(0.0),
            scores: true,
            max_defect_lines: 20,
            ..Default::default()
        }
        .settings(&scorer, (2, 10))
        .unwrap();
        // Two rows of ten columns: 2 row lines, 20 scores, 20 defects and
        // (every position a defect) one object a scan.
        let frames: Vec<u16> = (0..20 * 9).map(|i| (i * 37 % 1000) as u16).collect();
        let one = crate::stream::stream_scan(&scorer, settings, 2, &frames).unwrap();
        let mut dec = Decoder::new().with_budget(100);
        for line in one.repeat(3).split_inclusive(|&b| b == b'\n') {
            dec.feed(line);
        }
        dec.finish();
        assert_eq!(dec.scans.len(), 3);
        let held: Vec<usize> = dec
            .scans
            .iter()
            .map(|s| s.rows.len() + s.defects.len() + s.n_scores + s.objects.len())
            .collect();
        // 43 each, until the budget of 100 runs out in the third scan.
        assert_eq!(held[..2], [43, 43]);
        assert!(held[2] <= 16, "{held:?}");
        assert!(dec.scans[0].problems.is_empty() && dec.scans[1].problems.is_empty());
        assert!(dec.scans[2].problem_count() > 0);
        assert!(!dec.damage().is_empty());
    }

    #[test]
    fn a_line_of_max_line_bytes_is_whole_one_more_is_damage() {
        // A valid frame padded with digits in a field to the exact length.
        let line = |len: usize| {
            let body = "R,0,0,-,0,0,0,0,";
            let mut b = body.to_string();
            while b.len() + 6 < len {
                b.push('0');
            }
            format!("{b}*{:04X}\n", protocol::crc16(b.as_bytes()))
        };
        for (len, damaged) in [(protocol::MAX_LINE, false), (protocol::MAX_LINE + 1, true)] {
            let mut d = Decoder::new();
            let l = line(len);
            assert_eq!(l.len(), len);
            d.feed(l.as_bytes());
            let too_long = d.errors.iter().any(|e| e.what.contains("longer than"));
            assert_eq!(too_long, damaged, "{len}");
        }
    }
}
