//! The decoding thread: every line of the source through `dmap listen`'s
//! decoder, and what it rebuilt into the state as it comes (the part's
//! header, each row's scores and defects, each object as it closes, the
//! verdict); command replies to the requests that wait for them.

use super::hub::{Hub, Routed};
use crate::listen::{Decoder, LINE_BUFFER, NextLine, next_line};
use crate::sensor::answer;
use cvm_core::command::{Reply, parse_reply};
use std::io::{BufReader, Read};
use std::sync::Arc;
use std::time::Instant;

/// The `k`-th field of a line (from 0, the type): the row a score (`S`)
/// or row (`R`) line names is field 1, a score line's first column field 2.
fn field(line: &[u8], k: usize) -> Option<u32> {
    let f = line.split(|&b| b == b',').nth(k)?;
    std::str::from_utf8(f).ok()?.parse().ok()
}

/// Decodes `reader` to its end into `hub`; `rt` runs the `status`
/// requests the console makes by itself.
pub fn decode(hub: Arc<Hub>, reader: Box<dyn Read + Send>, rt: tokio::runtime::Handle) {
    let mut dec = Decoder::new();
    let mut r = BufReader::with_capacity(1 << 16, reader);
    let mut buf = Vec::with_capacity(LINE_BUFFER);
    let mut first: Option<Instant> = None;
    let end = loop {
        let next = match next_line(&mut r, &mut buf, LINE_BUFFER) {
            Ok(n) => n,
            Err(e) => break format!("reading the source failed: {e}"),
        };
        first.get_or_insert_with(Instant::now);
        match next {
            NextLine::End => break "the source ended".to_string(),
            NextLine::Line => line(&hub, &mut dec, &buf, &rt),
            NextLine::TooLong(n) => {
                dec.feed_too_long(n, &buf);
                after(&hub, &mut dec, b"", &rt);
            }
        }
    };
    dec.finish();
    after(&hub, &mut dec, b"", &rt);
    let seconds = first.map(|t| t.elapsed().as_secs_f64());
    hub.change(|s| {
        // A source that failed said why (`note`); that stays.
        s.source_end.get_or_insert(end);
        s.decode_seconds = seconds;
    });
}

fn line(hub: &Arc<Hub>, dec: &mut Decoder, raw: &[u8], rt: &tokio::runtime::Handle) {
    let trimmed = raw.strip_suffix(b"\n").unwrap_or(raw);
    let trimmed = trimmed.strip_suffix(b"\r").unwrap_or(trimmed);
    if trimmed.starts_with(b"A,")
        && let Ok((id, reply)) = parse_reply(trimmed)
    {
        let routed = match reply {
            Reply::Refused(why) => Routed::Refused(why.to_string()),
            r => match answer(r) {
                Some(a) => Routed::Ok(a),
                None => return dec.feed(raw),
            },
        };
        hub.route(id, routed);
    }
    dec.feed(raw);
    after(hub, dec, trimmed, rt);
}

/// What the line just fed changed, into the state.
fn after(hub: &Arc<Hub>, dec: &mut Decoder, line: &[u8], rt: &tokio::runtime::Handle) {
    let errors = std::mem::take(&mut dec.errors);
    let ended = dec.take_scans();
    let mut ask_status = false;
    // A verdict, an object, a new part, a reply or damage wakes the
    // viewers at once; a row waits for the next wake-up.
    let now = !errors.is_empty()
        || !ended.is_empty()
        || matches!(line.first(), Some(b'H' | b'E' | b'O' | b'A'));
    let v = hub.quietly(|s| {
        s.counters.lines = dec.line_no() as u64;
        for e in &errors {
            s.line_error(e.kind.name(), e.line, &e.what);
        }
        for scan in &ended {
            s.end(scan);
        }
        let cur = dec.current();
        match (line.first(), cur) {
            (Some(b'H'), Some(c)) => {
                s.begin(c, &String::from_utf8_lossy(line));
                ask_status = s.want_status && s.requests;
                s.want_status &= !ask_status;
            }
            (Some(b'R'), Some(_)) => {
                if let (Some(p), Some(row)) = (s.current.as_mut(), field(line, 1)) {
                    p.saw_row(row);
                }
            }
            (Some(b'S'), Some(c)) => {
                let at = (field(line, 1), field(line, 2));
                if let (Some(p), (Some(row), Some(col0))) = (s.current.as_mut(), at) {
                    p.scores(c, row, col0);
                }
            }
            (Some(b'D'), Some(c)) => {
                if let Some(p) = s.current.as_mut() {
                    p.defect(c);
                }
            }
            (Some(b'O'), Some(c)) => {
                let pitch = s.pitch_um;
                if let Some(p) = s.current.as_mut() {
                    p.object(c, pitch);
                }
            }
            _ => {}
        }
        if !line.is_empty() && !line.starts_with(b"A,") {
            let part = if line.starts_with(b"E,") {
                s.last.as_mut()
            } else {
                s.current.as_mut()
            };
            if let Some(p) = part {
                p.keep_line(line);
            }
        }
    });
    if now {
        hub.tick.send_replace(v);
    }
    if ask_status {
        let hub = Arc::clone(hub);
        rt.spawn(async move {
            let _ = hub.request("status").await;
        });
    }
}
