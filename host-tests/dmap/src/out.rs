//! Where `dmap` writes: the one writer of standard output, warnings on
//! standard error, and output files.
//!
//! * Standard output: a closed pipe (`dmap ... | head`) is not an error of
//!   `dmap`; [`stdout`] turns `EPIPE` into [`StdoutClosed`], on which `main`
//!   exits quietly with status 141 (128 + SIGPIPE, what a shell reports for
//!   a tool killed by the signal). Any other failure (a full disk) is a
//!   one-line error.
//! * Files: written to a temporary file beside the final name, then renamed
//!   over it, so an interrupted run leaves the previous file whole; an output
//!   that names one of the command's inputs (the same file, whatever the
//!   path) is refused before anything is written.

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
    if input.as_os_str() == "-" {
        return match (
            same_file::Handle::stdin(),
            same_file::Handle::from_path(output),
        ) {
            (Ok(a), Ok(b)) => a == b,
            _ => false,
        };
    }
    same_file::is_same_file(input, output).unwrap_or(false)
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
    if same_file::is_same_file(a, b).unwrap_or(false) {
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

/// Writes a file through `write`: into a temporary file in the same
/// directory, renamed over `path` once complete. On any error the
/// temporary file is removed and `path` is left as it was.
pub fn write_file(path: &Path, write: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    let p = path.display();
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
    let mut tmp = builder
        .tempfile_in(dir)
        .map_err(|e| anyhow!("{p}: cannot create: {}", without_temp_path(&e)))?;
    {
        let mut out = BufWriter::new(tmp.as_file_mut());
        write(&mut out)?;
        out.flush().map_err(|e| anyhow!("{p}: cannot write: {e}"))?;
    }
    tmp.as_file()
        .sync_all()
        .map_err(|e| anyhow!("{p}: cannot write: {e}"))?;
    tmp.persist(path)
        .map_err(|e| anyhow!("{p}: cannot write: {}", e.error))?;
    Ok(())
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
