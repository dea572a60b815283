//! `dmap vectors`: the line protocol's conformance vectors
//! (docs/dmap.md, "Conformance vectors"). Each vector is a stream of
//! result lines, whole or deliberately damaged, made from synthetic scans
//! by the firmware's own pipeline (`scenes`, `good`, `damaged`), and the
//! decode `dmap listen --json` makes of it; and the command channel's
//! request and reply lines with their decodes (`commands`). `dmap vectors
//! DIR` writes them (`NAME.txt`, `NAME.json`, `index.json`,
//! `commands.json`); `dmap vectors --check DIR`
//! makes them again and compares, byte for byte, so that a change of the
//! encoder or the decoder that the vectors do not reflect fails.

mod commands;
mod damaged;
mod edit;
mod good;
mod scenes;

use crate::listen::{decode_with, summary_json};
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
}

/// Every vector, the whole streams first.
pub fn all() -> Result<Vec<Vector>> {
    let mut v = good::all()?;
    v.extend(damaged::all()?);
    Ok(v)
}

/// What `dmap listen --json` prints for `bytes` (one document) and the
/// status it exits with: 1 when the stream is damaged, else 0.
pub fn decode(bytes: &[u8]) -> Result<(serde_json::Value, i32)> {
    let dec = decode_with(bytes, 0, crate::listen::DEFAULT_MAX_SCANS as usize)?;
    let status = i32::from(!dec.damage().is_empty());
    Ok((summary_json(&dec, None), status))
}

/// The files of the vectors: name and content.
pub fn files() -> Result<Vec<(String, Vec<u8>)>> {
    let mut out = Vec::new();
    let mut index = Vec::new();
    for v in all()? {
        let (doc, status) = decode(&v.bytes)?;
        let expected = serde_json::json!({
            "about": v.about,
            "exit": status,
            "listen": doc,
        });
        index.push(serde_json::json!({"name": v.name, "about": v.about, "exit": status}));
        out.push((format!("{}.txt", v.name), v.bytes));
        out.push((format!("{}.json", v.name), pretty(&expected)?));
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
    std::fs::create_dir_all(&args.dir)
        .with_context(|| format!("cannot create {}", args.dir.display()))?;
    // Vectors no longer made go (those the old index names, nothing else):
    // the directory holds exactly the set.
    let old: Vec<String> = std::fs::read(args.dir.join("index.json"))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .and_then(|v| v.as_array().cloned())
        .unwrap_or_default()
        .iter()
        .filter_map(|e| e["name"].as_str().map(String::from))
        .filter(|n| !n.is_empty() && !n.contains(['/', '\\']) && n != "..")
        .collect();
    for name in old {
        for ext in ["txt", "json"] {
            let _ = std::fs::remove_file(args.dir.join(format!("{name}.{ext}")));
        }
    }
    let files = files()?;
    for (name, bytes) in &files {
        let path = args.dir.join(name);
        std::fs::write(&path, bytes).with_context(|| format!("cannot write {}", path.display()))?;
    }
    crate::out::stdout(
        format!("{} files written to {}\n", files.len(), args.dir.display()).as_bytes(),
    )?;
    Ok(())
}
