//! The stream decoder's handler of each line type: every line checked
//! against the scan it belongs to and the order of docs/protocol.md, and
//! filed with its scan.

use super::checks::{check_complete, header_fault, object_fault};
use super::decoder::{Decoder, MAX_DEFECTS, OLDEST_VERSION};
use super::linechecks::{decide, defect_fault, end_fault, row_fault, scores_fault};
use super::scan::{Defect, Kind, LineError, MAX_IMAGE_POSITIONS, Order, ScanResult};
use cvm_core::RowSummary;
use cvm_core::objects::Object;
use cvm_core::protocol::{self, EndInfo, HeaderInfo};

impl Decoder {
    /// An `H` line: a new scan, unless the run holds as many as it may.
    pub(super) fn header(&mut self, h: &HeaderInfo<'_>) {
        self.skipping = false;
        if let Some(prev) = self.current.take() {
            self.error(
                Kind::ScanCut,
                "new scan header before the previous scan's end line",
            );
            self.scans.push(prev);
        }
        if self.scans.len() >= self.max_scans {
            self.scans_skipped += 1;
            self.skipping = true;
            if self.scans_skipped == 1 {
                self.error(
                    Kind::MaxScans,
                    format!(
                        "more than {} scans in one run: this scan and later ones are skipped (--max-scans)",
                        self.max_scans
                    ),
                );
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
            origin: h.origin,
            kernels: h.kernels as char,
            kernel_size: h.kernel_size,
            weights: h.weights.to_string(),
            normalise: h.normalise,
            power_threshold: (h.power_threshold <= cvm_core::power::POWER_MAX)
                .then(|| cvm_core::power::to_units(h.power_threshold)),
            spread_threshold: (h.spread_threshold <= cvm_core::spread::SPREAD_MAX)
                .then(|| cvm_core::spread::to_units(h.spread_threshold)),
            ..ScanResult::default()
        };
        s.threshold = s.units(h.threshold);
        s.thr = h.threshold;
        s.pthr = h.power_threshold;
        s.sthr = h.spread_threshold;
        s.header_rows = h.origin.map(|o| o.rows);
        if let Some(what) = header_fault(h) {
            s.problems.push(LineError {
                line: self.line_no,
                kind: Kind::Field,
                what,
            });
        }
        // Version 7 changed the D, S and O lines: older scans do not parse.
        if !(OLDEST_VERSION..=protocol::VERSION).contains(&h.version) {
            s.problems.push(LineError {
                line: self.line_no,
                kind: Kind::Version,
                what: format!(
                    "header v={}: a protocol version this decoder does not read (it reads {} to {})",
                    h.version,
                    OLDEST_VERSION,
                    protocol::VERSION
                ),
            });
        }
        self.current = Some(s);
    }

    /// An `R` line: the row's summary, the end of the previous row's lines.
    pub(super) fn row(&mut self, summary: RowSummary, listed: u32) {
        let Some(s) = self.current.as_mut() else {
            return self.error(Kind::OutsideScan, "row line outside a scan (header lost?)");
        };
        if s.rows.contains_key(&summary.row) {
            return self.problem(
                Kind::Duplicate,
                format!("row {} reported twice", summary.row),
            );
        }
        let order = s.order;
        s.order = Order {
            row: Some((summary.row, listed, 0)),
            ..Order::default()
        };
        if let Some((prev, ..)) = order.row
            && summary.row < prev
        {
            self.problem(
                Kind::Order,
                format!(
                    "row line of row {} after row {prev} (rows out of order)",
                    summary.row
                ),
            );
        }
        if let (Some((prev, ..)), Some((id, true))) = (order.row, order.last_object) {
            self.problem(Kind::Order, format!(
                "object {id} ends in row {prev} but row {}'s line follows it: only the scan's end closes an object in the last row reported (out of order)",
                summary.row
            ));
        }
        self.check_defects_arrived(order);
        let Some(s) = self.current.as_mut() else {
            return;
        };
        if s.rows.len() >= MAX_IMAGE_POSITIONS || self.kept >= self.max_kept {
            return self.problem(
                Kind::Capacity,
                "more row lines than an image can hold; the rest ignored",
            );
        }
        s.unlisted_defects += (summary.defects - listed.min(summary.defects)) as u64;
        let faults = row_fault(s, &summary, listed);
        s.rows.insert(summary.row, summary);
        s.row_lines.insert(summary.row, self.line_no);
        self.kept += 1;
        for what in faults {
            self.problem(Kind::Field, what);
        }
    }

    /// A `D` line: one of the row's strongest defects, checked against its
    /// row line and the previous `D` line.
    pub(super) fn defect(
        &mut self,
        row: u32,
        col: u32,
        (mag, pmag, smag): (u32, u16, u32),
        strength: u32,
        flags: u8,
    ) {
        let Some(s) = self.current.as_mut() else {
            return self.error(
                Kind::OutsideScan,
                "defect line outside a scan (header lost?)",
            );
        };
        if s.defects.len() >= MAX_DEFECTS || self.kept >= self.max_kept {
            return self.problem(
                Kind::Capacity,
                "more defect lines than an image can hold; the rest ignored",
            );
        }
        self.kept += 1;
        let score = s.units(mag);
        s.defects.push(Defect {
            row,
            col,
            score,
            power: cvm_core::power::to_units(pmag as u32),
            spread: cvm_core::spread::to_units(smag),
            strength,
            flags,
            mag,
            pmag,
            smag,
            line: self.line_no,
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
        let faults = s
            .defects
            .last()
            .map(|d| defect_fault(s, d))
            .unwrap_or_default();
        if let Some(what) = what {
            self.problem(Kind::Order, what);
        }
        for what in faults {
            self.problem(Kind::Field, what);
        }
    }

    /// An `S` line: scores of part of the row, each position once.
    pub(super) fn scores(&mut self, row: u32, col0: u32, chars: &[u8]) {
        let Some(s) = self.current.as_mut() else {
            return self.error(
                Kind::OutsideScan,
                "score line outside a scan (header lost?)",
            );
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
            self.problem(Kind::Order, what);
        }
        let Some(s) = self.current.as_mut() else {
            return;
        };
        let cols = s.cols;
        let n = chars.len() / protocol::SCORE_CHARS;
        if col0 as usize + n > cols {
            return self.problem(
                Kind::Field,
                format!("score line for row {row} runs past column {cols}"),
            );
        }
        if s.n_scores + n > MAX_IMAGE_POSITIONS || self.kept + n > self.max_kept {
            return self.problem(
                Kind::Capacity,
                "more scores than an image can hold; the rest ignored",
            );
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
        s.score_lines += u64::from(added == n);
        self.kept += added;
        let faults = scores_fault(s, row, col0, chars);
        for what in faults {
            self.problem(Kind::Field, what);
        }
        if dup {
            self.problem(
                Kind::Duplicate,
                format!("scores of row {row} from column {col0} received twice"),
            );
        }
    }

    /// An `E` line: the scan's totals, and the scan cross-checked and filed.
    pub(super) fn end(&mut self, e: EndInfo) {
        let Some(mut s) = self.current.take() else {
            return self.error(Kind::OutsideScan, "end line outside a scan (header lost?)");
        };
        s.end = Some(e);
        let faults = end_fault(&s, &e);
        let order = s.order;
        self.current = Some(s);
        for what in faults {
            self.problem(Kind::Field, what);
        }
        self.check_defects_arrived(order);
        let Some(mut s) = self.current.take() else {
            return;
        };
        check_complete(&mut s, self.line_no);
        self.scans.push(s);
    }

    /// An `O` line: filed with its scan, its place in the line order and
    /// its fields checked.
    pub(super) fn object(&mut self, o: Object) {
        let Some(s) = self.current.as_mut() else {
            return self.error(
                Kind::OutsideScan,
                "object line outside a scan (header lost?)",
            );
        };
        s.objects_arrived += 1;
        let id = o.id;
        let mut what = Vec::new();
        let order = &mut s.order;
        let ends_here = match order.row {
            None => {
                what.push((
                    Kind::Order,
                    format!("object {id} before any row line (out of order)"),
                ));
                false
            }
            Some((r, ..)) if o.row1 > r => {
                what.push((Kind::Order, format!(
                    "object {id} ends in row {}, after the last row reported ({r}): an object line follows the lines of the row that closes it (out of order)",
                    o.row1
                )));
                false
            }
            Some((r, ..)) if o.row1.saturating_add(1) < r => {
                what.push((Kind::Order, format!(
                    "object {id} ends in row {} but comes after the lines of row {r}: row {} closed it, and its line follows that row's (out of order)",
                    o.row1,
                    o.row1 + 1
                )));
                false
            }
            Some((r, ..)) => {
                let ends_here = o.row1 == r;
                match order.last_object {
                    Some((prev, true)) if !ends_here => what.push((Kind::Order, format!(
                        "object {id}, closed by row {r}, after object {prev}, which only the scan's end closes (out of order)"
                    ))),
                    Some((prev, prev_ends)) if prev_ends == ends_here && id <= prev => {
                        what.push((Kind::Order, format!(
                            "object lines after row {r} not in increasing id ({id} after {prev})"
                        )))
                    }
                    _ => {}
                }
                ends_here
            }
        };
        order.last_object = Some((id, ends_here));
        if !s.object_ids.insert(id) {
            what.push((
                Kind::Duplicate,
                format!("object {id} reported twice in the scan"),
            ));
        }
        if let Some(bad) = object_fault(&o, s.cols) {
            what.push((Kind::Field, format!("object {id}: {bad}")));
        }
        // The line against itself: its peak is the strength its own
        // magnitudes make under the header's thresholds, and the channels
        // that fired there are among its channels.
        let (bits, strength) = decide(o.peak_mag, o.peak_power, o.peak_spread, s.thresholds());
        if strength != o.peak || bits & !o.channels != 0 {
            what.push((
                Kind::Field,
                format!(
                    "object {id}: peak {} and channels {}, but its peak_mag, peak_power and peak_spread make strength {strength} of channels {bits}",
                    o.peak, o.channels
                ),
            ));
        }
        for (kind, w) in what {
            self.problem(kind, w);
        }
        let Some(s) = self.current.as_mut() else {
            return;
        };
        if s.objects.len() >= MAX_DEFECTS || self.kept >= self.max_kept {
            return self.problem(
                Kind::Capacity,
                "more object lines than an image can hold; the rest ignored",
            );
        }
        self.kept += 1;
        s.objects.push(o);
        s.object_lines.push(self.line_no);
    }

    /// After the last line of a row: as many `D` lines as its `R` line listed.
    pub(super) fn check_defects_arrived(&mut self, order: Order) {
        if let Some((row, listed, arrived)) = order.row
            && arrived < listed
        {
            self.problem(
                Kind::Missing,
                format!("row {row} lists {listed} defect line(s), {arrived} arrived"),
            );
        }
    }
}
