//! Cutting received bytes into request lines in a fixed buffer, with the
//! receiver's errors attached to the line they damaged.

use super::refusal::Refusal;
use super::wire::MAX_LINE;

/// An error the serial receiver reported while a line was arriving.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LinkError {
    /// Bytes were lost: the receiver was full (ORE).
    Overrun,
    /// A byte's stop bit was missing (FE).
    Framing,
    /// A byte was sampled with noise (NE).
    Noise,
}

impl LinkError {
    /// The refusal a line damaged by this error gets.
    pub const fn refusal(self) -> Refusal {
        match self {
            LinkError::Overrun => Refusal::Overrun,
            LinkError::Framing => Refusal::Framing,
            LinkError::Noise => Refusal::Noise,
        }
    }
}

/// What a received byte completed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Event<'a> {
    /// A line, without its `\n` (a `\r` before it is kept: the request
    /// parser strips it); never empty.
    Line(&'a [u8]),
    /// A line with more than `MAX_LINE - 1` bytes before its `\n`: its
    /// bytes were dropped as they came.
    TooLong,
    /// A line during which the receiver reported an error (the first).
    Damaged(LinkError),
}

/// Bytes in, lines out; at most `MAX_LINE` bytes of memory, whatever the input.
pub struct LineReader {
    buf: [u8; MAX_LINE],
    len: usize,
    overflow: bool,
    damage: Option<LinkError>,
}

impl Default for LineReader {
    fn default() -> Self {
        Self::new()
    }
}

impl LineReader {
    pub const fn new() -> Self {
        LineReader {
            buf: [0; MAX_LINE],
            len: 0,
            overflow: false,
            damage: None,
        }
    }

    /// The receiver reported `e` for a byte of the line now arriving.
    pub fn error(&mut self, e: LinkError) {
        if self.damage.is_none() {
            self.damage = Some(e);
        }
    }

    /// Takes one received byte; returns what it completed, if anything.
    /// Empty lines complete nothing.
    pub fn push(&mut self, b: u8) -> Option<Event<'_>> {
        if b != b'\n' {
            // One byte stays free for the `\n`: a line is at most MAX_LINE
            // bytes with it, as a result line is.
            match self.buf.get_mut(self.len) {
                Some(slot) if self.len + 1 < MAX_LINE => {
                    *slot = b;
                    self.len += 1;
                }
                _ => self.overflow = true,
            }
            return None;
        }
        let (len, overflow, damage) = (self.len, self.overflow, self.damage);
        self.len = 0;
        self.overflow = false;
        self.damage = None;
        if let Some(e) = damage {
            return Some(Event::Damaged(e));
        }
        if overflow {
            return Some(Event::TooLong);
        }
        match self.buf.get(..len) {
            // `\r\n` alone is an empty line too.
            Some(line) if !line.is_empty() && line != b"\r" => Some(Event::Line(line)),
            _ => None,
        }
    }

    /// A line damaged by the receiver is partly here (its `\n` not yet).
    pub fn damaged_pending(&self) -> bool {
        self.damage.is_some()
    }

    /// The link has been idle for [`IDLE_GAP_MS`]: a damaged line ends
    /// here, as if its `\n` had come (the `\n` may have been among the
    /// bytes lost), so the next request is read on its own. An undamaged
    /// partial line waits on: a host may type slowly.
    pub fn idle(&mut self) -> Option<Event<'static>> {
        let e = self.damage.take()?;
        self.len = 0;
        self.overflow = false;
        Some(Event::Damaged(e))
    }
}

/// The idle gap that ends a damaged line, in milliseconds: 20 ms is
/// about 1 800 characters' time at 921 600 baud, far more than any gap
/// inside a line a program sends.
pub const IDLE_GAP_MS: u32 = 20;
