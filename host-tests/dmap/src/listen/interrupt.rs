//! Ctrl-C (SIGINT) and SIGTERM while `dmap listen` reads: the stream ends
//! there, as if its writer had stopped, so that the scans already complete
//! are still reported and written (`--port --scans 0` runs until
//! interrupted). A second signal ends `dmap` at once, as if neither had
//! been caught.
//!
//! The signals are turned into bytes on a socket pair (signal-hook's
//! self-pipe) and the read waits on the input and on them with `poll`:
//! every byte read before the signal is decoded, none after it, whatever
//! thread the kernel delivers the signal to.

use anyhow::{Context, Result};
use signal_hook::consts::{SIGINT, SIGTERM};
use std::io::Read;
use std::os::fd::{AsRawFd, RawFd};
use std::os::unix::net::UnixStream;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// The signals that end a read, with their names.
const SIGNALS: [(i32, &str); 2] = [(SIGINT, "SIGINT"), (SIGTERM, "SIGTERM")];

/// A reader that ends (reads 0 bytes) once SIGINT or SIGTERM has arrived.
pub struct Interruptible<R> {
    inner: R,
    fd: RawFd,
    /// The read ends of the signals' socket pairs, in the order of [`SIGNALS`].
    wake: Vec<UnixStream>,
    signal: Option<&'static str>,
}

impl<R: Read + AsRawFd> Interruptible<R> {
    /// Installs the handlers (for the rest of the process) and wraps `inner`.
    pub fn new(inner: R) -> Result<Self> {
        // Set by the first signal; the handler registered before it then
        // kills on the second one.
        let seen = Arc::new(AtomicBool::new(false));
        let mut wake = Vec::new();
        for (sig, _) in SIGNALS {
            let (read, write) = UnixStream::pair().context("creating a signal pipe")?;
            read.set_nonblocking(true)
                .context("creating a signal pipe")?;
            signal_hook::flag::register_conditional_default(sig, Arc::clone(&seen))
                .and_then(|_| signal_hook::flag::register(sig, Arc::clone(&seen)))
                .and_then(|_| signal_hook::low_level::pipe::register(sig, write))
                .context("installing signal handlers")?;
            wake.push(read);
        }
        Ok(Interruptible {
            fd: inner.as_raw_fd(),
            inner,
            wake,
            signal: None,
        })
    }
}

impl<R> Interruptible<R> {
    /// The signal that ended the stream, if one did.
    pub fn signal(&self) -> Option<&'static str> {
        self.signal
    }
}

impl<R: Read> Read for Interruptible<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.signal.is_some() {
            return Ok(0);
        }
        let poll_fd = |fd: RawFd| libc::pollfd {
            fd,
            events: libc::POLLIN,
            revents: 0,
        };
        loop {
            let mut fds: Vec<libc::pollfd> = std::iter::once(self.fd)
                .chain(self.wake.iter().map(|w| w.as_raw_fd()))
                .map(poll_fd)
                .collect();
            // SAFETY: `fds` is a live array of `fds.len()` pollfd records.
            let n = unsafe { libc::poll(fds.as_mut_ptr(), fds.len() as libc::nfds_t, -1) };
            if n < 0 {
                let e = std::io::Error::last_os_error();
                if e.kind() == std::io::ErrorKind::Interrupted {
                    continue;
                }
                return Err(e);
            }
            // A signal wins over pending input: a stream that never pauses
            // (a board sending without end) must still stop.
            for (k, (_, name)) in SIGNALS.iter().enumerate() {
                if fds.get(k + 1).is_some_and(|f| f.revents != 0) {
                    self.signal = Some(name);
                    return Ok(0);
                }
            }
            if fds.first().is_some_and(|f| f.revents != 0) {
                return self.inner.read(buf);
            }
        }
    }
}
