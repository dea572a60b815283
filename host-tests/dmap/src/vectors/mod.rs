//! `dmap vectors`: the line protocol's conformance vectors
//! (docs/dmap.md, "Conformance vectors"). Each vector is a stream of
//! result lines, whole or deliberately damaged, made from synthetic scans
//! by the firmware's own pipeline (`scenes`, `good`, `damaged`), and what
//! the protocol's decoder makes of each of its lines (`lines`); and the
//! command channel's request and reply lines with their decodes
//! (`commands`). `dmap vectors DIR` writes them (`NAME.txt`,
//! `NAME.jsonl`, `index.json`, `commands.json`); `dmap vectors --check
//! DIR` makes them again and compares, byte for byte, so that a change of
//! the encoder or the decoder that the vectors do not reflect fails.

mod commands;
mod damaged;
mod edit;
mod good;
mod lines;
mod scenes;

use crate::listen::decode_with;
use anyhow::{Context, Result, bail};
use clap::Args;
pub use commands::CAP as COMMAND_CAPACITY;
use std::path::{Path, PathBuf};

#[derive(Args, Clone, Debug)]
pub struct VectorsArgs {
    /// Directory of the vectors (the repository's: docs/protocol/vectors)
    #[arg(value_name = "DIR")]
    pub dir: PathBuf,
    /// Compare with the vectors in DIR instead of writing them: fails, naming each file that
    /// differs, is missing or is left over
    #[arg(long)]
    pub check: bool,
}

/// One conformance vector: its name, what it shows, and its bytes.
#[derive(Clone, Debug)]
pub struct Vector {
    pub name: String,
    pub about: String,
    pub bytes: Vec<u8>,
    /// For a vector that changes one field of a whole stream (every
    /// `range-`, `field-` and `cross-` vector): the stream it changes and
    /// the field, `TYPE.name` by the protocol's layout (`D.strength`).
    pub changes: Option<Change>,
}

/// What a one-field vector changed.
#[derive(Clone, Debug)]
pub struct Change {
    /// The whole vector it starts from.
    pub base: &'static str,
    /// `TYPE.name`: the line type and the field's name in its layout.
    pub field: String,
}

/// Every vector, the whole streams first.
pub fn all() -> Result<Vec<Vector>> {
    let mut v = good::all()?;
    v.extend(damaged::all()?);
    Ok(v)
}

/// The kinds of damage (docs/dmap.md, "Kinds of damage") a receiver
/// finds in `bytes`, as `dmap listen` names them: each once, sorted; none
/// for a whole stream.
pub fn damage(bytes: &[u8]) -> Result<Vec<&'static str>> {
    let dec = decode_with(bytes, 0, crate::listen::DEFAULT_MAX_SCANS as usize)?;
    let mut kinds: Vec<&'static str> = dec
        .errors
        .iter()
        .chain(dec.scans.iter().flat_map(|s| &s.problems))
        .map(|e| e.kind.name())
        .collect();
    kinds.sort_unstable();
    kinds.dedup();
    Ok(kinds)
}

/// The files of the vectors: name and content.
pub fn files() -> Result<Vec<(String, Vec<u8>)>> {
    let mut out = Vec::new();
    let mut index = Vec::new();
    for v in all()? {
        let mut entry = serde_json::json!({
            "name": v.name,
            "about": v.about,
            "damage": damage(&v.bytes)?,
        });
        if let Some(c) = &v.changes {
            entry["base"] = c.base.into();
            entry["changes"] = c.field.clone().into();
        }
        index.push(entry);
        let decoded: String = lines::decode(&v.bytes)?
            .iter()
            .map(|l| format!("{l}\n"))
            .collect();
        out.push((format!("{}.txt", v.name), v.bytes));
        out.push((format!("{}.jsonl", v.name), decoded.into_bytes()));
    }
    out.push((
        "index.json".to_string(),
        pretty(&serde_json::Value::Array(index))?,
    ));
    out.push(("commands.json".to_string(), pretty(&commands::document())?));
    // Git must keep every byte (`\r\n`, a missing last newline).
    out.push((".gitattributes".to_string(), b"* -text\n".to_vec()));
    Ok(out)
}

fn pretty(v: &serde_json::Value) -> Result<Vec<u8>> {
    let mut s = serde_json::to_vec_pretty(v)?;
    s.push(b'\n');
    Ok(s)
}

/// Differences between the vectors made now and those in `dir`.
pub fn compare(dir: &Path) -> Result<Vec<String>> {
    let want = files()?;
    let mut diffs = Vec::new();
    for (name, bytes) in &want {
        match std::fs::read(dir.join(name)) {
            Ok(have) if have == *bytes => {}
            Ok(_) => diffs.push(format!("{name} differs")),
            Err(_) => diffs.push(format!("{name} is missing")),
        }
    }
    let names: Vec<&str> = want.iter().map(|(n, _)| n.as_str()).collect();
    let entries =
        std::fs::read_dir(dir).with_context(|| format!("cannot read {}", dir.display()))?;
    for e in entries {
        let name = e?.file_name().to_string_lossy().into_owned();
        if !names.contains(&name.as_str()) {
            diffs.push(format!("{name} is left over"));
        }
    }
    diffs.sort();
    Ok(diffs)
}

/// The vectors a previous `dmap vectors` left in `dir`, which may then be
/// written over. A folder `dmap vectors` may write: one that does not
/// exist, an empty one, or one that holds nothing but a previous output:
/// `.gitattributes` as written here, an `index.json` listing vectors
/// (`name`, `about`, `damage`; or `exit`, as earlier versions wrote),
/// `commands.json` with its `requests` and `replies`, and each listed
/// vector's `NAME.txt` and `NAME.jsonl` (or `NAME.json`, as earlier
/// versions wrote). Any other folder is refused before
/// anything in it is touched: its files are someone else's.
fn previous_vectors(dir: &Path) -> Result<Vec<String>> {
    let d = dir.display();
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => bail!("{d}: cannot read the folder: {e}"),
    };
    let mut names = Vec::new();
    for e in entries {
        let e = e.with_context(|| format!("{d}: cannot read the folder"))?;
        if !e.file_type().is_ok_and(|t| t.is_file()) {
            bail!(
                "{d}: holds {}, which dmap vectors does not write; {REFUSE}",
                e.file_name().to_string_lossy()
            );
        }
        names.push(e.file_name().to_string_lossy().into_owned());
    }
    if names.is_empty() {
        return Ok(Vec::new());
    }
    let json = |name: &str| {
        std::fs::read(dir.join(name))
            .ok()
            .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
    };
    let index = json("index.json")
        .and_then(|v| v.as_array().cloned())
        .and_then(|a| {
            a.iter()
                .map(|e| {
                    let name = e["name"].as_str()?;
                    let plain =
                        !name.is_empty() && !name.starts_with('.') && !name.contains(['/', '\\']);
                    (plain
                        && e["about"].is_string()
                        && (e["damage"].is_array() || e["exit"].is_u64()))
                    .then(|| name.to_string())
                })
                .collect::<Option<Vec<String>>>()
        });
    let commands =
        json("commands.json").is_some_and(|v| v["requests"].is_array() && v["replies"].is_array());
    let attributes = std::fs::read(dir.join(".gitattributes")).ok();
    let (Some(index), true, Some(b"* -text\n")) = (index, commands, attributes.as_deref()) else {
        bail!(
            "{d}: not empty, and not a previous output of dmap vectors (its .gitattributes, index.json and commands.json); {REFUSE}"
        );
    };
    let ours = |n: &str| {
        [".gitattributes", "index.json", "commands.json"].contains(&n)
            || VECTOR_FILES.iter().any(|ext| {
                n.strip_suffix(ext)
                    .is_some_and(|stem| index.iter().any(|v| v == stem))
            })
    };
    if let Some(other) = names.iter().find(|n| !ours(n)) {
        bail!("{d}: holds {other}, which its index.json does not list; {REFUSE}");
    }
    Ok(index)
}

/// The endings of a vector's files, those earlier versions wrote among them.
const VECTOR_FILES: [&str; 3] = [".txt", ".jsonl", ".json"];

/// The end of every refusal of a folder.
const REFUSE: &str = "dmap vectors writes only into a new or empty folder, or over its own earlier output (nothing written)";

pub fn run(args: &VectorsArgs) -> Result<()> {
    if args.check {
        let diffs = compare(&args.dir)?;
        if !diffs.is_empty() {
            bail!(
                "{} file(s) of {} differ from what the encoder and decoder make now: {} (write them again with dmap vectors {})",
                diffs.len(),
                args.dir.display(),
                diffs.join(", "),
                args.dir.display()
            );
        }
        let n = files()?.len();
        crate::out::stdout(
            format!("{n} files of {} as made now\n", args.dir.display()).as_bytes(),
        )?;
        return Ok(());
    }
    let old = previous_vectors(&args.dir)?;
    std::fs::create_dir_all(&args.dir)
        .with_context(|| format!("cannot create {}", args.dir.display()))?;
    let files = files()?;
    for (name, bytes) in &files {
        crate::out::write_file(&args.dir.join(name), |w| Ok(w.write_all(bytes)?))?;
    }
    // Vectors no longer made go (those the old index names, nothing else),
    // once the new set is in place: the directory holds exactly the set.
    for name in old {
        for file in VECTOR_FILES.map(|ext| format!("{name}{ext}")) {
            if !files.iter().any(|(n, _)| *n == file) {
                let _ = std::fs::remove_file(args.dir.join(file));
            }
        }
    }
    crate::out::stdout(
        format!("{} files written to {}\n", files.len(), args.dir.display()).as_bytes(),
    )?;
    Ok(())
}
