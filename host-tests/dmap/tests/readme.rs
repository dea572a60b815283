//! The READMEs stay current: the protocol version the top-level README
//! names is the one the encoder writes (`cvm_core::protocol::VERSION`);
//! its table of channels names the threshold keys of the command channel
//! (`cvm_core::command::Key::ALL`), in their order, with the defaults that
//! `dmap` and the firmware's build (`build.rs`, `CVM_H743_SCAN`) start
//! from; and host-tests/README.md names every crate of the host workspace
//! (host-tests/Cargo.toml) and nothing else.

use cvm_core::command::Key;
use cvm_core::protocol::VERSION;
use dmap::settings::{DEFAULT_POWER_THRESHOLD, DEFAULT_SPREAD_THRESHOLD, DEFAULT_THRESHOLD};

const ROOT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../..");

fn read(rel: &str) -> String {
    std::fs::read_to_string(format!("{ROOT}/{rel}")).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// Every version number written after the word "protocol": "protocol 7",
/// "protocol version 7", "protocol, version 7", "protocol (version 7)".
fn protocol_versions(text: &str) -> Vec<u32> {
    let lower = text.to_lowercase();
    let mut found = Vec::new();
    for (at, word) in lower.match_indices("protocol") {
        let rest = lower[at + word.len()..].trim_start_matches([' ', ',', '(', ':', '\n']);
        let rest = rest.strip_prefix("version").unwrap_or(rest).trim_start();
        let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
        if let Ok(v) = digits.parse() {
            found.push(v);
        }
    }
    found
}

#[test]
fn readme_names_the_current_protocol_version() {
    let versions = protocol_versions(&read("README.md"));
    assert!(!versions.is_empty(), "README names no protocol version");
    for v in versions {
        assert_eq!(v, VERSION, "README names protocol version {v}");
    }
}

/// A threshold as the README writes it: a number, or `off`.
fn threshold(text: &str) -> f64 {
    match text {
        "off" => f64::INFINITY,
        t => t
            .parse()
            .unwrap_or_else(|_| panic!("README: a default threshold `{t}`")),
    }
}

/// A row of the README's channel table.
struct Channel {
    name: String,
    key: String,
    default: f64,
}

/// The README's table headed `| channel | threshold |`, with its
/// `default` column.
fn channel_table(readme: &str) -> Vec<Channel> {
    let mut lines = readme
        .lines()
        .skip_while(|l| !l.starts_with("| channel | threshold |"));
    let head: Vec<&str> = lines
        .next()
        .expect("README: no channel table")
        .split('|')
        .map(str::trim)
        .collect();
    let col = head
        .iter()
        .position(|c| *c == "default")
        .expect("README's channel table has no `default` column");
    lines
        .skip(1)
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            Channel {
                name: cells[1].to_string(),
                key: cells[2].trim_matches('`').to_string(),
                default: threshold(cells[col]),
            }
        })
        .collect()
}

#[test]
fn readme_thresholds_are_the_settings_keys() {
    let table = channel_table(&read("README.md"));
    let named: Vec<&str> = table.iter().map(|c| c.key.as_str()).collect();
    // The settings that are a channel's threshold, in the settings' order.
    let keys: Vec<&str> = Key::ALL
        .iter()
        .map(|k| k.name())
        .filter(|n| n.ends_with("thr"))
        .collect();
    assert_eq!(named, keys, "README's channel table");
    for c in &table {
        assert!(
            Key::from_name(c.key.as_bytes()).is_some(),
            "{}: `{}` is no settings key",
            c.name,
            c.key
        );
    }
    let channels: Vec<&str> = table.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(channels, ["CVM gradient", "power", "spread"]);
}

/// The default H743 build's thresholds, as the integers `thr`, `pthr` and
/// `sthr` of the `.cvm_config` section that build.rs writes into the ELF:
/// what ships, not a reading of build.rs's text.
fn firmware_defaults() -> Vec<u32> {
    let elf = dmap::twin::build_elf("").expect("the default H743 build");
    let bytes = std::fs::read(&elf).unwrap();
    let section = dmap::elf::section(&bytes, dmap::elf::CONFIG_SECTION)
        .expect("the ELF's .cvm_config section");
    let text = std::str::from_utf8(section).unwrap();
    ["thr", "pthr", "sthr"]
        .iter()
        .map(|name| {
            text.split_whitespace()
                .find_map(|f| f.strip_prefix(&format!("{name}=")))
                .unwrap_or_else(|| panic!("{text}: no {name}"))
                .parse()
                .unwrap()
        })
        .collect()
}

#[test]
fn readme_gives_the_default_thresholds() {
    let readme: Vec<f64> = channel_table(&read("README.md"))
        .iter()
        .map(|c| c.default)
        .collect();
    let dmap = [
        DEFAULT_THRESHOLD,
        DEFAULT_POWER_THRESHOLD,
        DEFAULT_SPREAD_THRESHOLD,
    ];
    assert_eq!(readme, dmap, "README's default thresholds against dmap's");
    // The README's defaults as the integers the default build (15x15, paper
    // kernels, uniform weights, normalised) compares with.
    let scorer = dmap::options::ScoringArgs::default()
        .scorer(15, 15)
        .unwrap();
    let want = vec![
        scorer.threshold_from_units(readme[0]),
        cvm_core::power::threshold_from_units(readme[1]),
        cvm_core::spread::threshold_from_units(readme[2]),
    ];
    assert_eq!(
        firmware_defaults(),
        want,
        "the default firmware's thresholds against README's"
    );
}

/// `members = [...]` and `exclude = [...]` of the workspace manifest.
fn workspace_folders(manifest: &str) -> Vec<String> {
    let mut folders = Vec::new();
    for key in ["members", "exclude"] {
        let line = manifest
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{key} =")))
            .unwrap_or_else(|| panic!("host-tests/Cargo.toml: no {key}"));
        let list = &line[line.find('[').unwrap() + 1..line.rfind(']').unwrap()];
        folders.extend(
            list.split(',')
                .map(|s| s.trim().trim_matches('"').to_string())
                .filter(|s| !s.is_empty()),
        );
    }
    folders.sort();
    folders
}

/// The `name` of a crate's manifest.
fn crate_name(manifest: &str) -> String {
    let line = manifest
        .lines()
        .find(|l| l.trim_start().starts_with("name ="))
        .expect("a crate's name");
    line.split('"').nth(1).unwrap().to_string()
}

#[test]
fn host_readme_names_every_crate_of_the_workspace() {
    let readme = read("host-tests/README.md");
    // The table's rows: `folder/` and `crate` (or `(Python)`).
    let rows: Vec<(String, String)> = readme
        .lines()
        .skip_while(|l| !l.starts_with("| folder | crate |"))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            (
                cells[1].trim_matches('`').trim_end_matches('/').to_string(),
                cells[2].trim_matches('`').to_string(),
            )
        })
        .collect();
    let crates: Vec<(String, String)> = rows
        .iter()
        .filter(|(_, c)| c != "(Python)")
        .cloned()
        .collect();
    let mut folders: Vec<String> = crates.iter().map(|(f, _)| f.clone()).collect();
    folders.sort();
    assert_eq!(
        folders,
        workspace_folders(&read("host-tests/Cargo.toml")),
        "host-tests/README.md's table against host-tests/Cargo.toml"
    );
    for (folder, name) in &crates {
        let manifest = read(&format!("host-tests/{folder}/Cargo.toml"));
        assert_eq!(&crate_name(&manifest), name, "host-tests/{folder}");
    }
    // A folder without a manifest (the chip model) is there too.
    for (folder, _) in rows.iter().filter(|(_, c)| c == "(Python)") {
        assert!(
            std::path::Path::new(&format!("{ROOT}/host-tests/{folder}")).is_dir(),
            "{folder}"
        );
    }
}

/// README is a short introduction; details belong in docs/.
#[test]
fn readme_stays_under_6_kb() {
    let n = read("README.md").len();
    assert!(
        n < 6 * 1024,
        "README.md is {n} bytes; move details to docs/"
    );
}
