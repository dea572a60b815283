//! The README stays current: the protocol version it names is the one the
//! encoder writes (`cvm_core::protocol::VERSION`), and its table of
//! channels names exactly the threshold keys of the command channel
//! (`cvm_core::command::Key::ALL`), in their order.

use cvm_core::command::Key;
use cvm_core::protocol::VERSION;

const README: &str = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/../../README.md"));

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
    let versions = protocol_versions(README);
    assert!(!versions.is_empty(), "README names no protocol version");
    for v in versions {
        assert_eq!(v, VERSION, "README names protocol version {v}");
    }
}

/// The rows of the README's table headed `| channel | threshold |`: each
/// channel's name and its threshold key.
fn channel_table(text: &str) -> Vec<(String, String)> {
    text.lines()
        .skip_while(|l| !l.starts_with("| channel | threshold"))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            (cells[1].to_string(), cells[2].trim_matches('`').to_string())
        })
        .collect()
}

#[test]
fn readme_thresholds_are_the_settings_keys() {
    let table = channel_table(README);
    let named: Vec<&str> = table.iter().map(|(_, k)| k.as_str()).collect();
    // The settings that are a channel's threshold, in the settings' order.
    let keys: Vec<&str> = Key::ALL
        .iter()
        .map(|k| k.name())
        .filter(|n| n.ends_with("thr"))
        .collect();
    assert_eq!(named, keys, "README's channel table: {table:?}");
    for (channel, key) in &table {
        assert!(
            Key::from_name(key.as_bytes()).is_some(),
            "{channel}: `{key}` is no settings key"
        );
    }
    let channels: Vec<&str> = table.iter().map(|(c, _)| c.as_str()).collect();
    assert_eq!(channels, ["CVM gradient", "power", "spread"]);
}
