//! ARM semihosting calls (`bkpt 0xab`), as QEMU implements them with
//! `-semihosting-config enable=on,target=native`.

const SYS_OPEN: u32 = 0x01;
const SYS_CLOSE: u32 = 0x02;
const SYS_WRITE: u32 = 0x05;
const SYS_READ: u32 = 0x06;
const SYS_FLEN: u32 = 0x0C;
const SYS_GET_CMDLINE: u32 = 0x15;
const SYS_EXIT_EXTENDED: u32 = 0x20;
const ADP_STOPPED_APPLICATION_EXIT: u32 = 0x2_0026;

/// `fopen` modes as semihosting numbers them.
const MODE_RB: u32 = 1;
/// `":tt"` opened for append is the host's stderr.
const MODE_A: u32 = 8;

fn call(op: u32, arg: usize) -> isize {
    let r: isize;
    // SAFETY: the semihosting ABI: operation in r0, argument block in r1,
    // result in r0; the host reads and writes only the blocks we pass.
    unsafe {
        core::arch::asm!("bkpt #0xab", inout("r0") op as isize => r, in("r1") arg, options(nostack));
    }
    r
}

/// An open host file.
pub struct File(usize);

impl File {
    /// Opens `path` (NUL-terminated) for binary reading.
    pub fn open_read(path: &[u8]) -> Option<File> {
        let len = path.len().checked_sub(1)?;
        let block = [path.as_ptr() as usize, MODE_RB as usize, len];
        let h = call(SYS_OPEN, block.as_ptr() as usize);
        if h < 0 { None } else { Some(File(h as usize)) }
    }

    fn stderr() -> Option<File> {
        Self::open_read_mode(b":tt\0", MODE_A)
    }

    fn open_read_mode(path: &[u8], mode: u32) -> Option<File> {
        let block = [path.as_ptr() as usize, mode as usize, path.len() - 1];
        let h = call(SYS_OPEN, block.as_ptr() as usize);
        if h < 0 { None } else { Some(File(h as usize)) }
    }

    /// Fills `buf` as far as the file allows; returns the bytes read, or
    /// `None` on a host error.
    pub fn read(&self, buf: &mut [u8]) -> Option<usize> {
        let block = [self.0, buf.as_mut_ptr() as usize, buf.len()];
        let left = call(SYS_READ, block.as_ptr() as usize);
        if left < 0 || left as usize > buf.len() {
            None
        } else {
            Some(buf.len() - left as usize)
        }
    }

    /// The file's length in bytes.
    pub fn len(&self) -> Option<usize> {
        let block = [self.0];
        let n = call(SYS_FLEN, block.as_ptr() as usize);
        if n < 0 { None } else { Some(n as usize) }
    }

    fn write(&self, data: &[u8]) {
        let block = [self.0, data.as_ptr() as usize, data.len()];
        call(SYS_WRITE, block.as_ptr() as usize);
    }
}

impl Drop for File {
    fn drop(&mut self) {
        let block = [self.0];
        call(SYS_CLOSE, block.as_ptr() as usize);
    }
}

/// The command line QEMU was given for the program (`arg=` items of
/// `-semihosting-config`), NUL-terminated in `buf`; returns its length.
pub fn command_line(buf: &mut [u8]) -> Option<usize> {
    let mut block = [buf.as_mut_ptr() as usize, buf.len()];
    if call(SYS_GET_CMDLINE, block.as_mut_ptr() as usize) != 0 {
        return None;
    }
    Some(block[1].min(buf.len()))
}

/// A diagnostic on the host's stderr (kept off the UART, whose bytes are
/// the product's output).
pub struct Stderr(Option<File>);

impl Stderr {
    pub fn new() -> Stderr {
        Stderr(File::stderr())
    }
}

impl core::fmt::Write for Stderr {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        if let Some(f) = &self.0 {
            f.write(s.as_bytes());
        }
        Ok(())
    }
}

/// Ends the emulation; QEMU exits with `status`.
pub fn exit(status: u32) -> ! {
    let block = [ADP_STOPPED_APPLICATION_EXIT as usize, status as usize];
    call(SYS_EXIT_EXTENDED, block.as_ptr() as usize);
    // Only reached if the host ignored the request.
    loop {
        cortex_m::asm::wfi();
    }
}
