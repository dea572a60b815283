//! Who may change settings: on the loopback anyone who can reach the
//! page; on the line's network only with the token printed at start.

use super::args::ConsoleArgs;
use anyhow::{Context, Result, bail};
use std::io::Read;

/// A fresh token: 16 bytes from the kernel's random source, in hex.
fn fresh() -> Result<String> {
    let mut b = [0u8; 16];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut b))
        .context("reading /dev/urandom for a token")?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

/// The token changes of settings need, if any; refuses a --listen
/// address other than the loopback without one.
pub fn decide(args: &ConsoleArgs) -> Result<Option<String>> {
    let token = match args.token.as_deref() {
        None => None,
        Some("auto") => Some(fresh()?),
        Some(t) if t.len() < 16 || !t.bytes().all(|b| b.is_ascii_graphic()) => {
            bail!("--token: at least 16 printable characters without spaces (or `auto`)")
        }
        Some(t) => Some(t.to_string()),
    };
    if token.is_none() && !args.listen.ip().is_loopback() {
        bail!(
            "--listen {} serves the line's network: give --token TOKEN (or --token auto for a fresh one, printed at start), which changes of settings will need",
            args.listen
        );
    }
    Ok(token)
}

/// Compares in a time that does not depend on where they differ.
pub fn same(given: &str, token: &str) -> bool {
    let (a, b) = (given.as_bytes(), token.as_bytes());
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}
