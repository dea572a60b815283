//! Where `dmap` writes: the one writer of standard output, warnings on
//! standard error, and output files.
//!
//! * Standard output: a closed pipe (`dmap ... | head`) is not an error of
//!   `dmap`; [`stdout`] turns `EPIPE` into [`StdoutClosed`], on which `main`
//!   exits quietly with status 141 (128 + SIGPIPE, what a shell reports for
//!   a tool killed by the signal). Any other failure (a full disk) is a
//!   one-line error.
//! * Files: a regular file (or a name not yet taken) is written to a
//!   temporary file beside it, then renamed over it, so an interrupted run
//!   leaves the previous file whole. A symbolic link is followed: the file
//!   it points to is the one replaced, the link stays. Anything else (a
//!   device such as `/dev/null`, a FIFO, a shell's `>(...)`) is opened and
//!   written in place, never replaced; a directory or socket is refused.
//!   An output that names one of the command's inputs (the same file,
//!   whatever the path) is refused before anything is written; the check
//!   looks at the files' identities without opening them, so a FIFO does
//!   not block it.

use anyhow::{Result, anyhow, bail};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Standard output was closed by the reader (`EPIPE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StdoutClosed;

impl std::fmt::Display for StdoutClosed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("standard output closed by its reader")
    }
}

impl std::error::Error for StdoutClosed {}

/// Exit status after [`StdoutClosed`]: 128 + SIGPIPE.
pub const EXIT_STDOUT_CLOSED: i32 = 141;

/// Whether `e` (or anything in its chain) is [`StdoutClosed`].
pub fn is_stdout_closed(e: &anyhow::Error) -> bool {
    e.chain().any(|c| c.is::<StdoutClosed>())
}

fn stdout_error(e: std::io::Error) -> anyhow::Error {
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        anyhow::Error::new(StdoutClosed)
    } else {
        anyhow!("writing to standard output: {e}")
    }
}

/// Writes `bytes` to standard output and flushes it.
pub fn stdout(bytes: &[u8]) -> Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(bytes)
        .and_then(|()| out.flush())
        .map_err(stdout_error)
}

/// A warning on standard error, one line; a closed standard error is not
/// worth failing a run for.
pub fn warn(what: &str) {
    let _ = writeln!(std::io::stderr(), "dmap: warning: {what}");
}

/// Where a command's output file goes: `-` is standard output.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Target {
    Stdout,
    File(PathBuf),
}

impl Target {
    pub fn new(path: &Path) -> Self {
        if path.as_os_str() == "-" {
            Target::Stdout
        } else {
            Target::File(path.to_path_buf())
        }
    }

    /// The name for messages.
    pub fn name(&self) -> String {
        match self {
            Target::Stdout => "standard output".into(),
            Target::File(p) => p.display().to_string(),
        }
    }
}

/// Whether `output` is the file `input` (the same device and inode, so
/// whatever the paths); an `input` of `-` is standard input.
pub fn input_is_output(input: &Path, output: &Path) -> bool {
    let Some(out) = identity(output) else {
        return false;
    };
    if input.as_os_str() == "-" {
        return same_file::Handle::stdin().is_ok_and(|h| (h.dev(), h.ino()) == out);
    }
    identity(input) == Some(out)
}

/// The device and inode of the file `path` names (through symbolic
/// links), from its metadata: opening a FIFO to compare it would block.
fn identity(path: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()))
}

/// Refuses an output file that is one of `inputs` (the same file, even
/// through another path, a hard link or a symbolic link).
pub fn refuse_inputs(output: &Path, inputs: &[&Path]) -> Result<()> {
    for input in inputs {
        if input_is_output(input, output) {
            bail!(
                "output {} is the input {}: refusing to overwrite an input (choose another output path)",
                output.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// Whether two output paths name the same file, existing or not: the same
/// existing file, or the same name in the same directory.
pub fn same_destination(a: &Path, b: &Path) -> bool {
    if identity(a).is_some_and(|i| identity(b) == Some(i)) {
        return true;
    }
    let dir = |p: &Path| {
        let parent = match p.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        parent.canonicalize().ok()
    };
    a.file_name() == b.file_name() && a.file_name().is_some() && dir(a) == dir(b)
}

/// Writes a file through `write` ([`OutFile`]): a regular file or a new
/// name is written beside it and renamed over it once complete; on any
/// error the temporary file is removed and the file is left as it was.
/// A device or FIFO: written in place, as a shell's `>` would.
pub fn write_file(path: &Path, write: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    let mut out = OutFile::create(path)?;
    write(&mut out)?;
    out.commit()
}

/// An output file being written, for outputs that grow as a run goes
/// (`sensor --pass-through`): the same rule as [`write_file`]. Nothing
/// reaches a regular file's name until [`OutFile::commit`]; dropped
/// without it, the temporary file is removed and the file keeps its bytes.
pub struct OutFile {
    /// The name the user gave, for messages.
    name: String,
    to: Dest,
}

enum Dest {
    /// A temporary file beside the target and the path it replaces.
    Temp(BufWriter<tempfile::NamedTempFile>, PathBuf),
    /// A device or FIFO, written through.
    InPlace(BufWriter<std::fs::File>),
}

impl OutFile {
    /// Checks `path` and opens what will be written: a directory or
    /// socket is refused; a device or FIFO is opened for writing (a FIFO
    /// waits for its reader); a regular file (through its links) or a new
    /// name gets a temporary file beside it.
    pub fn create(path: &Path) -> Result<OutFile> {
        let name = path.display().to_string();
        if let Ok(meta) = std::fs::metadata(path) {
            use std::os::unix::fs::FileTypeExt;
            let t = meta.file_type();
            if t.is_dir() {
                bail!("{name}: is a directory");
            }
            if t.is_socket() {
                bail!("{name}: is a socket, not a file dmap can write");
            }
            if !t.is_file() {
                let file = std::fs::OpenOptions::new()
                    .write(true)
                    .open(path)
                    .map_err(|e| anyhow!("{name}: cannot open for writing: {e}"))?;
                return Ok(OutFile {
                    name,
                    to: Dest::InPlace(BufWriter::new(file)),
                });
            }
        }
        let target = resolve_links(path)?;
        let tmp = temp_beside(&target, &name)?;
        Ok(OutFile {
            name,
            to: Dest::Temp(BufWriter::new(tmp), target),
        })
    }

    /// Flushes what was written and, for a regular file, renames it into
    /// place.
    pub fn commit(self) -> Result<()> {
        let name = self.name;
        let bad = |e: std::io::Error| anyhow!("{name}: cannot write: {e}");
        match self.to {
            Dest::InPlace(mut w) => w.flush().map_err(bad),
            Dest::Temp(w, target) => {
                let tmp = w.into_inner().map_err(|e| bad(e.into_error()))?;
                tmp.as_file().sync_all().map_err(bad)?;
                tmp.persist(&target).map_err(|e| bad(e.error))?;
                Ok(())
            }
        }
    }
}

impl Write for OutFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match &mut self.to {
            Dest::Temp(w, _) => w.write(buf),
            Dest::InPlace(w) => w.write(buf),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match &mut self.to {
            Dest::Temp(w, _) => w.flush(),
            Dest::InPlace(w) => w.flush(),
        }
    }
}

/// The path a chain of symbolic links ends at (which may not exist yet:
/// a dangling link names the file to create); the path itself if it is
/// not a link.
pub(crate) fn resolve_links(path: &Path) -> Result<PathBuf> {
    let mut at = path.to_path_buf();
    // The kernel's own limit on links followed in one lookup.
    for _ in 0..40 {
        match std::fs::symlink_metadata(&at) {
            Ok(m) if m.file_type().is_symlink() => {
                let to = std::fs::read_link(&at)
                    .map_err(|e| anyhow!("{}: cannot read the link: {e}", path.display()))?;
                at = match at.parent() {
                    Some(dir) if to.is_relative() => dir.join(to),
                    _ => to,
                };
            }
            _ => return Ok(at),
        }
    }
    bail!("{}: too many levels of symbolic links", path.display())
}

/// A temporary file in the directory of `path` (a regular file or a new
/// name), with the mode the file has or a new one would get (`p`: the
/// name the user gave, for messages).
fn temp_beside(path: &Path, p: &str) -> Result<tempfile::NamedTempFile> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| anyhow!("{p}: not a file name"))?
        .to_string_lossy();
    let prefix = format!(".{name}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".part");
    // The mode a new file gets from `File::create` (0666 less the umask),
    // or the existing file's.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(path)
            .ok()
            .filter(|m| m.is_file())
            .map_or(0o666, |m| m.permissions().mode() & 0o7777);
        builder.permissions(std::fs::Permissions::from_mode(mode));
    }
    builder
        .tempfile_in(dir)
        .map_err(|e| anyhow!("{p}: cannot create: {}", without_temp_path(&e)))
}

/// The system's reason, without the temporary file's name that `tempfile`
/// adds (the user named another file).
fn without_temp_path(e: &std::io::Error) -> String {
    let text = e.to_string();
    match text.split_once(" at path ") {
        Some((reason, _)) => reason.to_string(),
        None => text,
    }
}

/// Writes to a [`Target`]: a file as [`write_file`] does, or standard
/// output (through [`stdout`], once complete).
pub fn write_target(
    target: &Target,
    write: impl FnOnce(&mut dyn Write) -> Result<()>,
) -> Result<()> {
    match target {
        Target::File(p) => write_file(p, write),
        Target::Stdout => {
            let mut bytes = Vec::new();
            write(&mut bytes)?;
            stdout(&bytes)
        }
    }
}
