//! The stream decoder: one line at a time, each line type to its handler
//! (`handlers`), a line that lost its start or end resynchronised on the
//! next whole line in it. A line's CRC, fields and ranges are checked by
//! `cvm_core::protocol::parse`, beside the encoder; what needs memory (the
//! scans, their images, objects and problems) is kept here, within bounds.

use super::scan::{Kind, LineError, MAX_IMAGE_POSITIONS, ScanResult};
use cvm_core::protocol::{self, Line};

/// The oldest protocol version whose streams this decoder reads.
pub const OLDEST_VERSION: u32 = 7;

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
    pub(super) line_no: usize,
    pub(super) current: Option<ScanResult>,
    pub scans: Vec<ScanResult>,
    /// Damaged lines and lines outside any scan (the first [`MAX_ERRORS`]).
    pub errors: Vec<LineError>,
    /// Errors beyond [`MAX_ERRORS`], counted only.
    pub errors_not_listed: usize,
    /// Scans beyond `max_scans`, whose lines were skipped.
    pub scans_skipped: usize,
    /// The signal that ended the stream (`dmap listen` interrupted), if one did.
    pub interrupted: Option<&'static str>,
    /// Command replies (`A` lines) passed over.
    pub replies: usize,
    pub(super) skipping: bool,
    pub(super) max_scans: usize,
    /// Row lines, defects and scores held, over all scans, and at most.
    pub(super) kept: usize,
    pub(super) max_kept: usize,
    /// Scans taken out by [`Decoder::take_scans`].
    taken: usize,
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
            interrupted: None,
            replies: 0,
            skipping: false,
            max_scans: max_scans.max(1),
            kept: 0,
            max_kept: MAX_KEPT,
            taken: 0,
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

    /// A line too long for the protocol, of `len` bytes, of which only
    /// the last ones, `tail`, are known: when they end in a whole line
    /// (a line cut mid-way and the next one joined to it), that line is
    /// decoded.
    pub fn feed_too_long(&mut self, len: usize, tail: &[u8]) {
        self.line_no += 1;
        self.error(
            Kind::TooLong,
            format!(
                "line of {len} bytes is longer than the protocol's {} (garbage or a lost newline)",
                protocol::MAX_LINE
            ),
        );
        let tail = tail.strip_suffix(b"\n").unwrap_or(tail);
        let tail = tail.strip_suffix(b"\r").unwrap_or(tail);
        if let Some(at) = resync(tail, 1) {
            self.decode_resynced(tail, at);
        }
    }

    /// The stream's last `len` bytes, a line without its newline, cut by
    /// a signal.
    pub fn feed_cut(&mut self, len: usize) {
        self.line_no += 1;
        let by = self.interrupted.unwrap_or("the interrupt");
        self.error(
            Kind::Cut,
            format!("line cut by {by} after {len} byte(s); not decoded"),
        );
    }

    /// The stream was ended by `signal` (before [`Decoder::finish`]).
    pub fn interrupted(&mut self, signal: &'static str) {
        self.interrupted = Some(signal);
    }

    /// The scan under way (its header arrived, its end line not yet).
    pub fn current(&self) -> Option<&ScanResult> {
        self.current.as_ref()
    }

    /// Lines fed so far (the number of the last one).
    pub fn line_no(&self) -> usize {
        self.line_no
    }

    /// Takes the scans filed so far out of the decoder and gives back what
    /// they held of its budget, so that a decoder that runs for ever
    /// (`dmap console`) holds one scan at a time.
    pub fn take_scans(&mut self) -> Vec<ScanResult> {
        let scans = std::mem::take(&mut self.scans);
        self.taken += scans.len();
        for s in &scans {
            let held = s.rows.len() + s.defects.len() + s.n_scores + s.objects.len();
            self.kept = self.kept.saturating_sub(held);
        }
        scans
    }

    /// Scans that have ended (an end line arrived).
    pub fn ended(&self) -> usize {
        self.scans.iter().filter(|s| s.end.is_some()).count()
    }

    pub(super) fn error(&mut self, kind: Kind, what: impl Into<String>) {
        if self.errors.len() < MAX_ERRORS {
            self.errors.push(LineError {
                line: self.line_no,
                kind,
                what: what.into(),
            });
        } else {
            self.errors_not_listed += 1;
        }
    }

    pub(super) fn problem(&mut self, kind: Kind, what: impl Into<String>) {
        let e = LineError {
            line: self.line_no,
            kind,
            what: what.into(),
        };
        match &mut self.current {
            Some(s) => s.add_problem(e),
            None => self.error(e.kind, e.what),
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
        // Both limits count the newline, not a carriage return before it.
        let limit = match trimmed.first() {
            Some(b'H' | b'E') => protocol::MAX_LINE,
            _ => protocol::MAX_ROW_LINE,
        };
        if trimmed.len() >= limit {
            if let Some(at) = resync(trimmed, 1) {
                return self.decode_resynced(trimmed, at);
            }
            self.error(
                Kind::TooLong,
                format!(
                    "line of {} bytes is longer than the protocol's {limit} for its type (garbage or a lost newline)",
                    trimmed.len() + 1,
                ),
            );
            return;
        }
        if trimmed.starts_with(b"A,") {
            return self.reply(trimmed);
        }
        match protocol::parse(trimmed) {
            Ok(line) => self.line(line),
            Err(e) => match resync(trimmed, 1) {
                // A line cut mid-way, the next one joined to it.
                Some(at) => self.decode_resynced(trimmed, at),
                None => self.error(parse_kind(e), e.to_string()),
            },
        }
    }

    /// `line` failed, but from byte `at` on it holds a whole line: the
    /// start is reported cut, the rest decoded.
    fn decode_resynced(&mut self, line: &[u8], at: usize) {
        self.error(
            Kind::Cut,
            format!(
                "line cut after {at} byte(s): a new line starts in it without a newline before it (the stream was cut mid-line); decoding from there"
            ),
        );
        if let Some(rest) = line.get(at..) {
            if rest.starts_with(b"A,") {
                return self.reply(rest);
            }
            if let Ok(l) = protocol::parse(rest) {
                self.line(l);
            }
        }
    }

    /// An `A` line: the command channel's reply, for another reader;
    /// counted when whole.
    fn reply(&mut self, line: &[u8]) {
        match cvm_core::command::parse_reply(line) {
            Ok(_) => self.replies += 1,
            Err(e) => self.error(parse_kind(e), format!("command reply: {e}")),
        }
    }

    /// A line that parsed, to its type's handler.
    fn line(&mut self, line: Line<'_>) {
        match line {
            Line::Object(o) => self.object(o),
            Line::Header(h) => self.header(&h),
            Line::Row { summary, listed } => self.row(summary, listed),
            Line::Defect {
                row,
                col,
                mag,
                pmag,
                smag,
                strength,
                flags,
            } => self.defect(row, col, (mag, pmag, smag), strength, flags),
            Line::Scores { row, col0, chars } => self.scores(row, col0, chars),
            Line::End(e) => self.end(e),
        }
    }

    /// Ends the stream: a scan without its end line is kept and reported
    /// cut; a stream without any scan is reported too.
    pub fn finish(&mut self) {
        if let Some(s) = self.current.take() {
            let what = match self.interrupted {
                Some(sig) => {
                    format!("interrupted by {sig} before the scan's end line (the scan is cut)")
                }
                None => "stream ended before the scan's end line".to_string(),
            };
            self.error(Kind::ScanCut, what);
            self.scans.push(s);
        }
        if self.scans.is_empty() && self.taken == 0 && self.scans_skipped == 0 {
            let lines = self.line_no;
            self.error(
                Kind::NoScan,
                format!("no scan in the stream: no header line decoded in {lines} line(s)"),
            );
        }
    }
}

/// The kind of damage a line that did not parse is.
fn parse_kind(e: protocol::ParseError) -> Kind {
    use protocol::ParseError as E;
    match e {
        E::NoChecksum => Kind::NoChecksum,
        E::Checksum => Kind::Checksum,
        E::Format => Kind::Malformed,
        E::Range(_) => Kind::Range,
        E::Type => Kind::UnknownType,
    }
}

/// Where, from byte `from` on, a line that did not parse holds a whole
/// line: the first `X,` (`X` a line type) whose rest has a valid CRC and
/// parses. A stream cut mid-line (a reset of the board) joins the cut
/// line's start to the next line; the CRC makes a false find as unlikely
/// as a damaged line passing.
pub(super) fn resync(line: &[u8], from: usize) -> Option<usize> {
    (from..line.len().saturating_sub(1)).find(|&i| {
        let rest = &line[i..];
        rest.get(1) == Some(&b',')
            && match rest[0] {
                b'A' => cvm_core::command::parse_reply(rest).is_ok(),
                b'H' | b'R' | b'D' | b'S' | b'O' | b'E' => protocol::parse(rest).is_ok(),
                _ => false,
            }
    })
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
    fn a_line_of_its_limit_is_whole_one_byte_more_is_damage() {
        // A frame padded with digits in a field to the exact length: the
        // limit is the type's (newline included), whatever the fields.
        let line = |body: &str, len: usize| {
            let mut b = body.to_string();
            while b.len() + 6 < len {
                b.push('0');
            }
            format!("{b}*{:04X}\n", protocol::crc16(b.as_bytes()))
        };
        for (body, limit) in [
            ("R,0,0,-,0,0,0,0,", protocol::MAX_ROW_LINE),
            ("O,1,", protocol::MAX_ROW_LINE),
            ("E,rows=", protocol::MAX_LINE),
            ("H,v=", protocol::MAX_LINE),
        ] {
            for (len, damaged) in [(limit, false), (limit + 1, true)] {
                let mut d = Decoder::new();
                let l = line(body, len);
                assert_eq!(l.len(), len);
                d.feed(l.as_bytes());
                let too_long = d.errors.iter().any(|e| e.kind == Kind::TooLong);
                assert_eq!(too_long, damaged, "{body} {len}");
                // A carriage return before the newline does not count.
                let mut d = Decoder::new();
                d.feed(l.replace('\n', "\r\n").as_bytes());
                let too_long = d.errors.iter().any(|e| e.kind == Kind::TooLong);
                assert_eq!(too_long, damaged, "{body} {len} CRLF");
            }
        }
    }
}
