//! `dmap console` against bad input: a damaged stream shows its damage in
//! the health panel and never a wrong verdict; a request with a bad
//! token, a malformed body or an out-of-range value is refused with its
//! reason; `--listen` on another address than the loopback without a
//! token is refused.

use crate::common;

use common::console::{Console, ask, http};

const TOKEN: &str = "0123456789abcdef-line-3";

/// The demo part as the firmware's pipeline scores it: objects, `obj`.
fn part(dir: &std::path::Path) -> String {
    let scan = common::demo_scan(dir);
    let out = common::dmap_ok(&["stream", common::s(&scan), "--scores"]).stdout;
    String::from_utf8(out).unwrap()
}

/// `line` with its body changed by `f` and sealed again with a valid CRC.
fn resealed(line: &str, f: impl Fn(&str) -> String) -> String {
    let body = line.rsplit_once('*').unwrap().0;
    String::from_utf8(common::framed(&f(body))).unwrap()
}

#[test]
fn a_damaged_stream_shows_its_damage_and_no_wrong_verdict() {
    let dir = common::tmp_in("console-bad", "");
    let whole = part(&dir);
    assert!(whole.contains("verdict=obj"));
    // Part 2: its end line says `good` against its own count of bad
    // frames (sealed with a valid CRC: only its fields tell; a `good` with
    // objects can be right, the objects' limits are not in the lines).
    let lied: String = whole
        .lines()
        .map(|l| {
            if l.starts_with("E,") {
                resealed(l, |b| {
                    b.replace("bad=0", "bad=1")
                        .replace("verdict=obj", "verdict=good")
                })
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    // Part 3: a score line damaged on the link (its CRC fails).
    let mut hit = false;
    let flipped: String = whole
        .lines()
        .map(|l| {
            if !hit && l.starts_with("S,10,") {
                hit = true;
                format!("{}\n", l.replacen('A', "B", 1))
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    let rec = dir.join("damaged.txt");
    std::fs::write(&rec, format!("{whole}{lied}{flipped}")).unwrap();
    let console = Console::start(&["--input", common::s(&rec), "--rate", "full"]);
    let s = console.wait(60, "the stream's end", |s| {
        s["health"]["source_end"].is_string()
    });
    let verdicts: Vec<&str> = s["history"]
        .as_array()
        .unwrap()
        .iter()
        .map(|h| h["verdict"].as_str().unwrap())
        .collect();
    assert_eq!(verdicts.len(), 3, "{verdicts:?}");
    // Newest first: the lying part and the one that lost a score line are
    // damaged, neither good nor obj.
    assert_eq!(verdicts[..2], ["damaged", "damaged"], "{verdicts:?}");
    assert_eq!(verdicts[2], "obj", "{verdicts:?}");
    assert!(!verdicts.contains(&"good"), "{verdicts:?}");
    let kinds = &s["health"]["kinds"];
    assert!(kinds["checksum"].as_u64() >= Some(1), "{kinds}");
    assert!(kinds["verdict"].as_u64() >= Some(1), "{kinds}");
    assert!(
        s["counters"]["line_errors"].as_u64() >= Some(1),
        "{}",
        s["counters"]
    );
    assert!(
        s["counters"]["damaged"].as_u64() >= Some(1),
        "{}",
        s["counters"]
    );
    assert_eq!(
        s["counters"]["rejects"].as_u64(),
        Some(verdicts.iter().filter(|v| **v == "obj").count() as u64)
    );
    let recent = s["health"]["recent"].to_string();
    assert!(recent.contains("checksum"), "{recent}");
    if verdicts[0] == "damaged" {
        assert_eq!(s["outputs"]["trusted"], false, "{}", s["outputs"]);
    }
}

#[test]
fn requests_are_refused_with_their_reasons() {
    let dir = common::tmp_in("console-bad-requests", "");
    let rec = dir.join("one.txt");
    std::fs::write(&rec, part(&dir)).unwrap();
    let console = Console::start(&[
        "--input",
        common::s(&rec),
        "--rate",
        "full",
        "--token",
        TOKEN,
    ]);
    let a = &console.addr;
    // Read-only viewers need no token.
    let (status, _) = http(a, "GET", "/api/state", &[], "");
    assert_eq!(status, 200);
    let (status, v) = ask(a, "set thr=5", None);
    assert_eq!(status, 401, "{v}");
    assert!(
        v["error"].as_str().unwrap().contains("needs the token"),
        "{v}"
    );
    let (status, v) = ask(a, "set thr=5", Some("not-the-token-at-all"));
    assert_eq!(status, 401, "{v}");
    assert!(v["error"].as_str().unwrap().contains("wrong token"), "{v}");
    let headers = [("X-Console-Token", TOKEN)];
    let (status, body) = http(a, "POST", "/api/request", &headers, "set thr=5");
    assert_eq!(status, 400, "{body}");
    assert!(body.contains("the body is not JSON"), "{body}");
    let (status, body) = http(a, "POST", "/api/request", &headers, r#"{"request": 5}"#);
    assert_eq!(status, 400, "{body}");
    assert!(body.contains("no \\\"request\\\" string"), "{body}");
    for (words, reason) in [
        ("set thr=4294967296", "value out of range 0..=4294967295"),
        ("set cols=0", "value out of range 1..=65535"),
        ("set mode=both", "mode takes part or row"),
        ("set frobs=1", "unknown setting `frobs`"),
        ("calibrate --scans 0", "--scans"),
        ("launch", "unrecognized subcommand"),
    ] {
        let (status, v) = ask(a, words, Some(TOKEN));
        assert_eq!(status, 400, "{words}: {v}");
        let said = v["error"].as_str().unwrap();
        assert!(said.contains(reason), "{words}: {said}");
    }
    // A valid request, to a recording: refused for what it is.
    let (status, v) = ask(a, "set thr=5", Some(TOKEN));
    assert_eq!(status, 409, "{v}");
    assert!(
        v["error"].as_str().unwrap().contains("takes no requests"),
        "{v}"
    );
}

#[test]
fn the_lines_network_needs_a_token() {
    let dir = common::tmp_in("console-listen", "");
    let rec = dir.join("empty.txt");
    std::fs::write(&rec, "").unwrap();
    let out = common::dmap(&[
        "console",
        "--input",
        common::s(&rec),
        "--listen",
        "0.0.0.0:0",
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("serves the line's network: give --token"),
        "{err}"
    );
    let out = common::dmap(&[
        "console",
        "--input",
        common::s(&rec),
        "--listen",
        "0.0.0.0:0",
        "--token",
        "short",
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("at least 16"),
        "{out:?}"
    );
    // A fresh token, printed in the address at start.
    let console = Console::start(&["--input", common::s(&rec), "--token", "auto"]);
    let token = console.url.split("?token=").nth(1).unwrap().to_string();
    assert_eq!(token.len(), 32, "{}", console.url);
    let (status, v) = ask(&console.addr, "set thr=5", Some(&token));
    assert_eq!(status, 409, "past the token: {v}");
}
