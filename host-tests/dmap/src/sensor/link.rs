//! The sensor's serial link as the client sees it: requests out, and the
//! board's output read as lines, in which the replies to the request under
//! way are picked out from the result lines around them. Result lines are
//! counted (and copied to a file if asked); a reply line with a bad
//! checksum, or one that answers another id, is reported on stderr and
//! skipped.

use super::failure::Failure;
use super::words::Ask;
use cvm_core::command::{Reply, encode_request, parse_reply};
use cvm_core::protocol::{LineSink, MAX_LINE, Priority};
use std::collections::VecDeque;
use std::io::{Read, Write};
use std::time::Instant;

/// Longest line kept: a result line (`protocol::MAX_LINE` with its `\n`)
/// and a `\r`; longer ones are dropped as they come (and counted).
const LONGEST: usize = MAX_LINE + 1;

/// An `ok` reply to the request under way: the core's reply, kept past
/// its line (the status's firmware text owned).
pub type Answer = Reply<'static, String>;

struct Collect(Vec<u8>);

impl LineSink for Collect {
    fn line(&mut self, line: &[u8], _: Priority) {
        self.0.extend_from_slice(line);
    }
}

/// A line for a message: printable, without its line end.
pub fn printable(line: &[u8]) -> String {
    String::from_utf8_lossy(line)
        .trim_end_matches(['\n', '\r'])
        .escape_debug()
        .to_string()
}

pub struct Link<P> {
    port: P,
    /// The port, for messages.
    name: String,
    /// What to check when nothing comes back.
    pub hint: String,
    partial: Vec<u8>,
    overlong: bool,
    lines: VecDeque<Vec<u8>>,
    pass: Option<crate::out::OutFile>,
    /// The termination signal that arrived (0: none), set by the handlers
    /// `dmap sensor` installs; the wait for a reply ends on it.
    pub signal: std::sync::Arc<std::sync::atomic::AtomicUsize>,
    /// Lines that were not replies (result lines), ignored.
    pub result_lines: u64,
    /// Reply lines skipped: damaged, or answering another id.
    pub skipped: u64,
}

impl<P: Read + Write> Link<P> {
    /// `name` and `baud` are for messages; `pass` receives every line that
    /// is not a reply, as it came.
    pub fn new(port: P, name: &str, baud: u32, pass: Option<crate::out::OutFile>) -> Self {
        Link {
            port,
            name: name.to_string(),
            hint: format!("is the sensor connected to {name}, at {baud} baud?"),
            partial: Vec::new(),
            overlong: false,
            lines: VecDeque::new(),
            pass,
            signal: Default::default(),
            result_lines: 0,
            skipped: 0,
        }
    }

    /// Sends `ask` with this id.
    pub fn send(&mut self, id: u32, ask: &Ask) -> Result<(), Failure> {
        let mut line = Collect(Vec::new());
        encode_request(id, &ask.request, &mut line);
        self.port
            .write_all(&line.0)
            .and_then(|()| self.port.flush())
            .map_err(|e| Failure::link(format!("{}: writing to {}: {e}", ask.words, self.name)))
    }

    /// The next `ok` reply to request `id` (asked as `words`) that arrives
    /// before `deadline`, `None` if none did. An `err` reply to it (or one
    /// whose id the board could not read, which can only be this request's
    /// while it is the only one under way) is the refusal.
    pub fn reply(
        &mut self,
        id: u32,
        words: &str,
        deadline: Instant,
    ) -> Result<Option<Answer>, Failure> {
        while let Some(line) = self.next_line(words, deadline)? {
            if !line.starts_with(b"A,") {
                self.result_lines += 1;
                if let Some(w) = self.pass.as_mut() {
                    w.write_all(&line).map_err(|e| {
                        Failure::other(format!("writing the --pass-through file: {e}"))
                    })?;
                }
                continue;
            }
            let (got, reply) = match parse_reply(&line) {
                Ok(r) => r,
                Err(e) => {
                    self.skip(format!(
                        "skipped a damaged reply line ({e}): {}",
                        printable(&line)
                    ));
                    continue;
                }
            };
            match (got, reply) {
                (Some(g), _) if g != id => self.skip(format!(
                    "skipped a reply to request {g} (waiting for {id}): {}",
                    printable(&line)
                )),
                (None, Reply::Refused(why)) => {
                    return Err(Failure::refused(format!(
                        "{words} refused: {why} (the sensor could not read the request's id)"
                    )));
                }
                (_, Reply::Refused(why)) => {
                    return Err(Failure::refused(format!("{words} refused: {why}")));
                }
                // A setting of a later board: passed over.
                (_, Reply::OtherKey { .. }) => {}
                (_, r) => return Ok(answer(r)),
            }
        }
        Ok(None)
    }

    fn skip(&mut self, what: String) {
        self.skipped += 1;
        crate::out::warn(&what);
    }

    /// Puts the pass-through file in place, with every line received
    /// (however the session ended).
    pub fn finish(&mut self) -> Result<(), Failure> {
        match self.pass.take() {
            Some(f) => f
                .commit()
                .map_err(|e| Failure::other(format!("the --pass-through file: {e}"))),
            None => Ok(()),
        }
    }

    fn next_line(&mut self, words: &str, deadline: Instant) -> Result<Option<Vec<u8>>, Failure> {
        let mut buf = [0u8; 1024];
        loop {
            if let Some(l) = self.lines.pop_front() {
                return Ok(Some(l));
            }
            let signal = self.signal.load(std::sync::atomic::Ordering::Relaxed);
            if signal != 0 {
                return Err(Failure::interrupted(words, signal as i32));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            match self.port.read(&mut buf) {
                Ok(0) => {
                    return Err(Failure::link(format!(
                        "{words}: {} closed while waiting for the reply",
                        self.name
                    )));
                }
                Ok(n) => self.take(&buf[..n]),
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::Interrupted
                            | std::io::ErrorKind::WouldBlock
                    ) => {}
                Err(e) => {
                    return Err(Failure::link(format!(
                        "{words}: reading {}: {e}",
                        self.name
                    )));
                }
            }
        }
    }

    fn take(&mut self, bytes: &[u8]) {
        for &b in bytes {
            if b == b'\n' {
                if self.overlong {
                    self.result_lines += 1;
                } else if !self.partial.is_empty() {
                    let mut line = std::mem::take(&mut self.partial);
                    line.push(b'\n');
                    self.lines.push_back(line);
                }
                self.partial.clear();
                self.overlong = false;
            } else if self.partial.len() + 1 >= LONGEST {
                self.overlong = true;
                self.partial.clear();
            } else if !self.overlong {
                self.partial.push(b);
            }
        }
    }
}

/// The owned form of an `ok` reply (`None` for a refusal, and for a
/// setting of a later board).
pub fn answer(r: Reply<'_>) -> Option<Answer> {
    match r {
        Reply::Refused(_) => None,
        r => r.detach(String::from),
    }
}
