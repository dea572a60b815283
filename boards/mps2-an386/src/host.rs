//! The host side of the emulated board, over ARM semihosting as QEMU
//! implements it (`-semihosting-config enable=on,target=native`), through
//! the `semihosting` crate: the scan file named on the command line,
//! diagnostics on the host's stderr (off the UART, whose bytes are the
//! product's output), and the exit status.

use core::ffi::CStr;
use core::fmt::Arguments;

use semihosting::fs::File;
use semihosting::io::Write as _;

/// Longest command line read, and longest scan file path.
const CMDLINE: usize = 512;

/// Opens the scan file named by the last word of the command line (the
/// `arg=` items of `-semihosting-config`).
pub fn open_scan() -> Result<File, &'static str> {
    let args = semihosting::experimental::env::args::<CMDLINE>()
        .map_err(|_| "no semihosting command line (run with -semihosting-config ...,arg=SCAN)")?;
    let path = (&args)
        .filter_map(Result::ok)
        .filter(|a| !a.is_empty())
        .last()
        .ok_or("no scan file on the command line")?;
    let mut name = [0u8; CMDLINE + 1];
    let slot = name
        .get_mut(..path.len())
        .ok_or("scan file path too long")?;
    slot.copy_from_slice(path.as_bytes());
    let name = CStr::from_bytes_until_nul(&name).map_err(|_| "scan file path too long")?;
    File::open(name).map_err(|_| "cannot open the scan file")
}

/// Writes to the host's stderr, if it takes it.
pub fn eprint(args: Arguments<'_>) {
    if let Ok(mut err) = semihosting::io::stderr() {
        let _ = err.write_fmt(args);
    }
}

/// Ends the emulation; QEMU exits with `status`.
pub fn exit(status: u32) -> ! {
    semihosting::process::exit(status as i32)
}
