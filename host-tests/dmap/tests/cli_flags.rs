//! One meaning per option name across `dmap`'s subcommands: walks clap's
//! whole command tree (every subcommand and every `sensor` action) and
//! fails if a short letter stands for two long names, if one long name
//! takes two kinds of value, or if its help says two different things; an
//! old spelling kept for scripts is a hidden alias, and parses as the new.

use clap::CommandFactory;
use clap::Parser;
use dmap::cli::{Cli, Command};
use dmap::cli_values::Component;
use std::collections::BTreeMap;

/// An option where it is defined.
struct Place {
    /// `dmap calibrate`, `dmap sensor calibrate`, ...
    path: String,
    long: String,
    short: Option<char>,
    /// Hidden spellings kept for old scripts.
    aliases: Vec<String>,
    /// `flag`, or the value's Rust type and, for a set of names, the names.
    kind: String,
    help: String,
    /// The whole `--help` text of its subcommand.
    page: String,
}

fn kind(a: &clap::Arg) -> String {
    if !a.get_num_args().is_some_and(|n| n.takes_values()) {
        return "flag".to_string();
    }
    let names: Vec<String> = a
        .get_possible_values()
        .iter()
        .map(|p| p.get_name().to_string())
        .collect();
    format!("{:?} {names:?}", a.get_value_parser().type_id())
}

fn walk(cmd: &clap::Command, path: &str, out: &mut Vec<Place>) {
    let page = cmd.clone().render_long_help().to_string();
    for a in cmd.get_arguments() {
        let Some(long) = a.get_long() else { continue };
        if ["help", "version"].contains(&long) {
            continue;
        }
        out.push(Place {
            path: path.to_string(),
            long: long.to_string(),
            short: a.get_short(),
            aliases: a
                .get_all_aliases()
                .unwrap_or_default()
                .into_iter()
                .map(str::to_string)
                .collect(),
            kind: kind(a),
            help: a.get_help().map(|h| h.to_string()).unwrap_or_default(),
            page: page.clone(),
        });
    }
    for sub in cmd.get_subcommands() {
        walk(sub, &format!("{path} {}", sub.get_name()), out);
    }
}

fn places() -> Vec<Place> {
    let mut all = Vec::new();
    walk(&Cli::command(), "dmap", &mut all);
    all
}

/// A long name whose help differs between subcommands (each says it in
/// its own context), and the words every one of those helps contains:
/// what the name means wherever it is.
const MEANS: &[(&str, &str)] = &[
    ("baud", "baud rate"),
    ("calibration", "from a calibration file"),
    ("elf", "elf"),
    ("flash", "bank 2"),
    ("full-scale", "full scale of the detector"),
    ("input", "lines"),
    ("json", "one json"),
    ("output", "output"),
    ("parts", "parts"),
    ("pitch-um", "µm"),
    ("port", "serial port"),
    ("rate", "false positions per part, per channel"),
    ("scans", "scans"),
    ("threshold", "defect"),
    ("truth", "truth mask"),
];

/// Old spellings that another subcommand spells with another meaning,
/// kept (hidden) so that no script breaks: `(subcommand, alias)`.
const OLD: &[(&str, &str)] = &[
    ("dmap calibrate", "k"),
    ("dmap eval", "k"),
    ("dmap calibrate", "scores"),
    ("dmap console", "rate"),
];

#[test]
fn a_short_letter_is_one_long_name() {
    let mut by_short: BTreeMap<char, Vec<(String, String)>> = BTreeMap::new();
    for p in places() {
        if let Some(c) = p.short {
            by_short.entry(c).or_default().push((p.path, p.long));
        }
    }
    assert!(by_short.contains_key(&'o'), "{by_short:?}");
    for (c, uses) in by_short {
        let first = &uses[0].1;
        assert!(
            uses.iter().all(|(_, l)| l == first),
            "-{c} stands for more than one option: {uses:?}"
        );
    }
}

#[test]
fn a_long_name_means_one_thing() {
    let all = places();
    let mut by_long: BTreeMap<&str, Vec<&Place>> = BTreeMap::new();
    for p in &all {
        by_long.entry(&p.long).or_default().push(p);
    }
    let mut used = Vec::new();
    for (long, uses) in &by_long {
        let first = uses[0];
        for p in uses {
            assert_eq!(
                p.kind, first.kind,
                "--{long} takes another kind of value in `{}` than in `{}`",
                p.path, first.path
            );
        }
        if uses.iter().all(|p| p.help == first.help) {
            continue;
        }
        let Some((_, words)) = MEANS.iter().find(|(n, _)| n == long) else {
            panic!(
                "--{long} is described differently in {:?}: give it one meaning in MEANS, or another name",
                uses.iter().map(|p| &p.path).collect::<Vec<_>>()
            );
        };
        used.push(*long);
        for p in uses {
            assert!(
                p.help.to_lowercase().contains(words),
                "--{long} in `{}` does not say \"{words}\": {}",
                p.path,
                p.help
            );
        }
    }
    for (n, _) in MEANS {
        assert!(used.contains(n), "MEANS lists --{n}, which needs no entry");
    }
    // The three that had two meanings each.
    for gone in ["out", "channel", "k"] {
        assert!(!by_long.contains_key(gone), "--{gone} is a long name again");
    }
}

#[test]
fn an_old_spelling_is_a_hidden_alias_that_clashes_only_where_listed() {
    let all = places();
    let mut clashes = Vec::new();
    for p in &all {
        for alias in &p.aliases {
            // Another option (another long name) spelled so too.
            let other = all
                .iter()
                .find(|q| q.long != p.long && (q.long == *alias || q.aliases.contains(alias)));
            if other.is_some() {
                clashes.push((p.path.as_str(), alias.as_str()));
            }
            // Hidden: --help names the new spelling only.
            let token = format!("--{alias}");
            let shown = p.page.match_indices(&token).any(|(at, _)| {
                !p.page[at + token.len()..]
                    .starts_with(|c: char| c.is_ascii_alphanumeric() || c == '-')
            });
            assert!(!shown, "`{} --help` shows {token}", p.path);
        }
    }
    clashes.sort();
    let mut want = OLD.to_vec();
    want.sort();
    assert_eq!(clashes, want);
}

fn parse(args: &[&str]) -> Command {
    Cli::try_parse_from(std::iter::once("dmap").chain(args.iter().copied()))
        .unwrap_or_else(|e| panic!("{args:?}: {e}"))
        .command
}

fn same(old: &[&str], new: &[&str]) {
    let (o, n) = (parse(old), parse(new));
    assert_eq!(
        format!("{o:?}"),
        format!("{n:?}"),
        "{old:?} against {new:?}"
    );
}

#[test]
fn old_spellings_parse_as_the_new() {
    same(
        &["calibrate", "r.npy", "--out", "c.json", "--k", "2.5"],
        &["calibrate", "r.npy", "-o", "c.json", "--k-mad", "2.5"],
    );
    same(
        &["calibrate", "g.npy", "--scores", "--output", "c.json"],
        &["calibrate", "g.npy", "--from-scores", "-o", "c.json"],
    );
    same(
        &["simulate", "--out", "s.npy"],
        &["simulate", "--output", "s.npy"],
    );
    same(
        &["render", "g.npy", "--out", "p.png", "--channel", "0"],
        &[
            "render",
            "g.npy",
            "-o",
            "p.png",
            "--component",
            "horizontal",
        ],
    );
    same(
        &[
            "eval",
            "g.npy",
            "--truth",
            "t.npy",
            "--k",
            "3",
            "--channel",
            "1",
        ],
        &[
            "eval",
            "g.npy",
            "--truth",
            "t.npy",
            "--k-std",
            "3",
            "--component",
            "vertical",
        ],
    );
    same(
        &["console", "--input", "l.txt", "--rate", "full"],
        &["console", "--input", "l.txt", "--pace", "full"],
    );
}

#[test]
fn component_takes_its_name_or_index() {
    let comp = |args: &[&str]| match parse(args) {
        Command::Eval(a) => a.component,
        _ => unreachable!(),
    };
    let base = ["eval", "g.npy", "--truth", "t.npy"];
    assert_eq!(comp(&base), Component::Magnitude);
    for (v, want, index) in [
        ("horizontal", Component::Horizontal, 0),
        ("0", Component::Horizontal, 0),
        ("vertical", Component::Vertical, 1),
        ("1", Component::Vertical, 1),
        ("magnitude", Component::Magnitude, 2),
        ("2", Component::Magnitude, 2),
    ] {
        let c = comp(&[&base[..], &["--component", v]].concat());
        assert_eq!((c, c.index()), (want, index), "{v}");
    }
    for bad in ["3", "power", "mag"] {
        let e = Cli::try_parse_from(["dmap", "render", "g.npy", "-o", "x.png", "--component", bad])
            .err()
            .unwrap_or_else(|| panic!("{bad} taken"));
        assert!(e.to_string().contains("--component"), "{e}");
    }
}
