//! Reading lines from a stream: at most one protocol line held, longer
//! ones measured and only their tail kept, an idle serial port waited on,
//! a stream ended by a signal ([`super::interrupt`]) told from one that
//! ended by itself.

use super::decoder::{DEFAULT_MAX_SCANS, Decoder};
#[cfg(feature = "tools")]
use super::interrupt::Interruptible;
use anyhow::{Context, Result};
use cvm_core::protocol;
use std::io::{BufRead, BufReader, Read};

/// What [`next_line`] found.
#[derive(Debug, PartialEq, Eq)]
pub enum NextLine {
    /// A line (with its newline, unless the stream ended without one) in the buffer.
    Line,
    /// A line longer than the limit, of this many bytes, discarded as it
    /// came but for its last `max` bytes, left in the buffer: a line that
    /// lost its newline (a stream cut mid-line) may end in a whole one.
    TooLong(usize),
    /// The end of the stream.
    End,
}

/// Reads the next line into `buf`, holding at most `max` bytes of it: a
/// longer line is read to its end and only its last `max` bytes are kept
/// (memory stays flat whatever the line). A timeout (an idle serial port)
/// keeps the partial line and waits on.
pub fn next_line(r: &mut impl BufRead, buf: &mut Vec<u8>, max: usize) -> std::io::Result<NextLine> {
    buf.clear();
    let (mut total, mut too_long) = (0usize, false);
    loop {
        let avail = match r.fill_buf() {
            Ok(b) => b,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::Interrupted | std::io::ErrorKind::TimedOut
                ) =>
            {
                continue;
            }
            Err(e) => return Err(e),
        };
        if avail.is_empty() {
            return Ok(match (total, too_long) {
                (0, _) => NextLine::End,
                (_, true) => NextLine::TooLong(total),
                _ => NextLine::Line,
            });
        }
        let (len, done) = match avail.iter().position(|&b| b == b'\n') {
            Some(i) => (i + 1, true),
            None => (avail.len(), false),
        };
        total = total.saturating_add(len);
        buf.extend_from_slice(&avail[..len]);
        if buf.len() > max {
            too_long = true;
            buf.drain(..buf.len() - max);
        }
        r.consume(len);
        if done {
            return Ok(if too_long {
                NextLine::TooLong(total)
            } else {
                NextLine::Line
            });
        }
    }
}

/// Longest line held: the protocol's `MAX_LINE` (newline included), and a
/// carriage return before the newline.
pub const LINE_BUFFER: usize = protocol::MAX_LINE + 1;

/// Decodes every line of `reader`, stopping early after `stop_after` ended
/// scans (0: read to the end), keeping at most `max_scans` scans.
pub fn decode_with(reader: impl Read, stop_after: usize, max_scans: usize) -> Result<Decoder> {
    decode_source(reader, |_| None, stop_after, max_scans)
}

/// [`decode_with`] on a stream that SIGINT or SIGTERM may end: the scans
/// complete by then are kept, the one under way is reported cut.
#[cfg(feature = "tools")]
pub fn decode_interruptible<R: Read>(
    reader: Interruptible<R>,
    stop_after: usize,
    max_scans: usize,
) -> Result<Decoder> {
    decode_source(reader, Interruptible::signal, stop_after, max_scans)
}

/// The reading loop; `signal` says whether (and by which signal) the
/// source was ended rather than reaching its end.
fn decode_source<R: Read>(
    reader: R,
    signal: impl Fn(&R) -> Option<&'static str>,
    stop_after: usize,
    max_scans: usize,
) -> Result<Decoder> {
    let mut dec = Decoder::with_max_scans(max_scans);
    let mut r = BufReader::new(reader);
    let mut buf = Vec::with_capacity(LINE_BUFFER);
    loop {
        match next_line(&mut r, &mut buf, LINE_BUFFER).context("reading the result stream")? {
            NextLine::End => break,
            NextLine::Line => match signal(r.get_ref()) {
                // A line without its newline at a signal was cut by it.
                Some(name) if !buf.ends_with(b"\n") => {
                    dec.interrupted(name);
                    dec.feed_cut(buf.len())
                }
                _ => dec.feed(&buf),
            },
            NextLine::TooLong(n) => dec.feed_too_long(n, &buf),
        }
        if stop_after > 0 && dec.ended() >= stop_after {
            break;
        }
    }
    if let Some(name) = signal(r.get_ref()) {
        dec.interrupted(name);
    }
    dec.finish();
    Ok(dec)
}

/// [`decode_with`] with the default cap on scans.
pub fn decode(reader: impl Read, stop_after: usize) -> Result<Decoder> {
    decode_with(reader, stop_after, DEFAULT_MAX_SCANS as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all_lines(input: &[u8], max: usize) -> Vec<(NextLine, Vec<u8>)> {
        let mut r = BufReader::with_capacity(7, input);
        let mut buf = Vec::new();
        let mut out = Vec::new();
        loop {
            let next = next_line(&mut r, &mut buf, max).unwrap();
            if next == NextLine::End {
                return out;
            }
            out.push((next, buf.clone()));
        }
    }

    #[test]
    fn lines_longer_than_the_limit_are_measured_and_only_their_tail_kept() {
        let input = b"abc\n0123456789abcdef\nxyz\n\nlast";
        assert_eq!(
            all_lines(input, 8),
            vec![
                (NextLine::Line, b"abc\n".to_vec()),
                (NextLine::TooLong(17), b"9abcdef\n".to_vec()),
                (NextLine::Line, b"xyz\n".to_vec()),
                (NextLine::Line, b"\n".to_vec()),
                (NextLine::Line, b"last".to_vec()),
            ]
        );
        // Exactly the limit, newline included, is a line.
        assert_eq!(
            all_lines(b"1234567\n12345678\n", 8),
            vec![
                (NextLine::Line, b"1234567\n".to_vec()),
                (NextLine::TooLong(9), b"2345678\n".to_vec()),
            ]
        );
    }
}
