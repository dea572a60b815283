//! How `dmap sensor` fails: one line and an exit status that tells a
//! script what went wrong without reading the line.

/// Exit status: any other error (an output file that cannot be written).
pub const EXIT_OTHER: i32 = 1;
/// Exit status: bad arguments, an unknown key or a bad value (nothing was
/// sent); the same as clap's usage errors.
pub const EXIT_USAGE: i32 = 2;
/// Exit status: the sensor refused a request (`err` reply).
pub const EXIT_REFUSED: i32 = 3;
/// Exit status: no reply within the timeout.
pub const EXIT_TIMEOUT: i32 = 4;
/// Exit status: the serial port could not be opened, read or written.
pub const EXIT_LINK: i32 = 5;

/// The exit statuses, for `--help`.
pub const EXIT_HELP: &str = "\
Exit status: 0 done; 1 another error (e.g. the --pass-through file); 2 bad
arguments, an unknown key or a bad value (checked before anything is sent);
3 the sensor refused a request (its reason on stderr); 4 no reply within the
timeout; 5 the serial port could not be opened, read or written; 128 + the
signal's number after SIGINT, SIGTERM or SIGHUP (the --pass-through file then
holds the lines received until then).";

/// A failure with its exit status.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Failure {
    pub code: i32,
    pub message: String,
}

impl Failure {
    pub fn other(message: String) -> Self {
        Failure {
            code: EXIT_OTHER,
            message,
        }
    }

    pub fn usage(message: String) -> Self {
        Failure {
            code: EXIT_USAGE,
            message,
        }
    }

    pub fn refused(message: String) -> Self {
        Failure {
            code: EXIT_REFUSED,
            message,
        }
    }

    pub fn timeout(message: String) -> Self {
        Failure {
            code: EXIT_TIMEOUT,
            message,
        }
    }

    /// Ended by SIGINT, SIGTERM or SIGHUP while waiting for the reply to
    /// `words`: the status a shell gives a process the signal ended.
    pub fn interrupted(words: &str, signal: i32) -> Self {
        let name = match signal {
            libc::SIGINT => "SIGINT",
            libc::SIGTERM => "SIGTERM",
            libc::SIGHUP => "SIGHUP",
            _ => "a signal",
        };
        Failure {
            code: 128 + signal,
            message: format!("{words}: interrupted by {name} while waiting for the reply"),
        }
    }

    pub fn link(message: String) -> Self {
        Failure {
            code: EXIT_LINK,
            message,
        }
    }
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Failure {}

/// The exit status `e` asks for, if it is (or wraps) a [`Failure`].
pub fn exit_code(e: &anyhow::Error) -> Option<i32> {
    e.chain()
        .find_map(|c| c.downcast_ref::<Failure>())
        .map(|f| f.code)
}
