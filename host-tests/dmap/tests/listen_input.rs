//! `dmap listen` on inputs that are not one whole stream: nothing at all,
//! headers whose fields a scorer cannot produce (with a valid CRC), a
//! stream cut mid-line and followed by a new scan (a board reset), a cut
//! stream with `-o` over a file already there, and no input named.

use crate::common;

use common::{dmap, dmap_ok, s, spot_scan, tmp_in};
use cvm_core::protocol;
use serde_json::Value;

const TAG: &str = "listen-input";

/// The stream of a small scan of seed `seed`, with score and defect lines
/// (its scan file named for the test, `tag`: tests run in parallel).
fn stream(tag: &str, seed: u64) -> Vec<u8> {
    let scan = tmp_in(TAG, &format!("{tag}-scan{seed}.npy"));
    spot_scan(&scan, 7, 50, 5, seed);
    dmap_ok(&[
        "stream",
        s(&scan),
        "--scores",
        "--max-defect-lines",
        "2",
        "--power-threshold",
        "0.003",
    ])
    .stdout
}

/// `dmap listen --json` on `bytes`: exit status and the document.
fn listen(name: &str, bytes: &[u8], args: &[&str]) -> (Option<i32>, Value, String) {
    let input = tmp_in(TAG, &format!("{name}.txt"));
    std::fs::write(&input, bytes).unwrap();
    let out = dmap(&[&["listen", "--input", s(&input), "--json"], args].concat());
    let v = serde_json::from_slice(&out.stdout).expect("one JSON document");
    (
        out.status.code(),
        v,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn kinds(v: &Value) -> Vec<(Value, String)> {
    v["problems"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p["line"].clone(), p["kind"].as_str().unwrap().to_string()))
        .collect()
}

fn lines(bytes: &[u8]) -> Vec<Vec<u8>> {
    bytes
        .split_inclusive(|&b| b == b'\n')
        .map(<[u8]>::to_vec)
        .collect()
}

fn sealed(body: &str) -> Vec<u8> {
    format!("{body}*{:04X}\n", protocol::crc16(body.as_bytes())).into_bytes()
}

/// Empty input, blank lines, and lines that are no protocol: no scan is a
/// failure (status 1), and the JSON says so (`damaged`, a `no-scan`
/// problem), not `damaged: false`.
#[test]
fn no_scan_is_a_failure_and_the_json_says_so() {
    for (name, bytes) in [
        ("empty", &b""[..]),
        ("blank", b"\n\n\r\n"),
        ("noise", b"hello\n"),
    ] {
        let (code, v, err) = listen(name, bytes, &[]);
        assert_eq!(code, Some(1), "{name}");
        assert_eq!(v["damaged"], true, "{name}");
        assert_eq!(v["scans"], serde_json::json!([]), "{name}");
        let k = kinds(&v);
        assert_eq!(k.last().unwrap().1, "no-scan", "{name}: {k:?}");
        assert!(err.contains("the stream was damaged"), "{name}: {err}");
        let text = dmap(&["listen", "--input", s(&tmp_in(TAG, &format!("{name}.txt")))]);
        assert_eq!(text.status.code(), Some(1));
        assert!(
            String::from_utf8_lossy(&text.stdout).contains("no scan in the stream"),
            "{name}"
        );
    }
    let (_, v, _) = listen("empty-again", b"", &[]);
    assert_eq!(
        v["problems"][0]["what"],
        "no scan in the stream: no header line decoded in 0 line(s)"
    );
}

/// A header with a valid CRC but a detector size or score format no
/// scorer has: refused (a `range` line error naming the field), so the
/// scan's lines are lines outside a scan, and the run fails.
#[test]
fn headers_a_scorer_cannot_write_are_refused() {
    let bytes = stream("ranges", 1);
    let ls = lines(&bytes);
    let head = String::from_utf8(ls[0].clone()).unwrap();
    let body = head.split('*').next().unwrap();
    for (key, value, what) in [
        ("j", "0x0", "j: each axis 1 to 16"),
        ("j", "99x99", "j: each axis 1 to 16"),
        ("j", "17x5", "j: each axis 1 to 16"),
        ("q", "99", "q: -120 to 62"),
        ("q", "-121", "q: -120 to 62"),
    ] {
        let forged: Vec<String> = body
            .split(',')
            .map(|f| match f.split_once('=') {
                Some((k, _)) if k == key => format!("{k}={value}"),
                _ => f.to_string(),
            })
            .collect();
        let forged = forged.join(",");
        assert_ne!(forged, body);
        let mut v = ls.clone();
        v[0] = sealed(&forged);
        let name = format!("header-{key}{value}");
        let (code, json, _) = listen(&name, &v.concat(), &[]);
        assert_eq!(code, Some(1), "{forged}");
        let first = &json["line_errors"][0];
        assert_eq!(first["line"], 1);
        assert_eq!(first["kind"], "range");
        assert_eq!(
            first["what"],
            format!("field outside its range: {what}"),
            "{forged}"
        );
        assert_eq!(json["scans"], serde_json::json!([]));
        assert_eq!(json["line_errors"][1]["kind"], "outside-scan");
    }
}

/// A header whose `q` is in range but not the one a scorer of its own
/// configuration has (5x5 paper kernels, uniform weights, normalised: the
/// scorer built here says which): the scan is decoded and the header
/// reported.
#[test]
fn a_header_q_its_configuration_cannot_have_is_reported() {
    let bytes = stream("q", 1);
    let mut ls = lines(&bytes);
    let cfg = cvm_core::Config::paper(cvm_core::Geometry::new(5, 5).unwrap());
    let q = cvm_core::Scorer::new(&cfg).unwrap().score_frac_bits();
    let head = String::from_utf8(ls[0].clone()).unwrap();
    let body = head.split('*').next().unwrap();
    assert!(body.contains(&format!(",q={q},")), "{body}");
    for forged_q in [-99, q - 1] {
        ls[0] = sealed(&body.replace(&format!(",q={q},"), &format!(",q={forged_q},")));
        let (code, v, _) = listen(&format!("q{forged_q}"), &ls.concat(), &[]);
        assert_eq!(code, Some(1));
        let p = &v["scans"][0]["problems"][0];
        assert_eq!(p["line"], 1);
        assert_eq!(p["kind"], "field");
        assert_eq!(
            p["what"],
            format!(
                "header: q={forged_q}, but a scorer of j=5x5, k=P, b=0, w=uniform, norm=1 has q={q}"
            )
        );
    }
}

/// A stream cut mid-line (the board reset while writing) and a new scan
/// right after it: the new header is found inside the joined line, the
/// second scan decodes exactly as it does alone, the first is reported
/// cut, and no row of the second is filed with the first.
#[test]
fn a_scan_after_a_line_cut_mid_way_is_found_and_kept_apart() {
    let (first, second) = (stream("cut", 1), stream("cut", 2));
    let (_, alone, _) = listen("second-alone", &second, &[]);
    let first_ls = lines(&first);
    // Cut in a short line (the joined line stays within the limit) and in
    // a score line (the joined line is then longer than any line may be).
    let r = first_ls.iter().rposition(|l| l.starts_with(b"R,")).unwrap();
    let sl = first_ls
        .iter()
        .rposition(|l| l.starts_with(b"S,") && l.len() > 200)
        .unwrap();
    for (name, k, keep) in [("short", r, 9), ("long", sl, 200)] {
        assert!(first_ls[k].len() > keep);
        let mut bytes: Vec<u8> = first_ls[..k].concat();
        bytes.extend_from_slice(&first_ls[k][..keep]);
        bytes.extend_from_slice(&second);
        let joined_len = keep + lines(&second)[0].len();
        assert_eq!(joined_len > protocol::MAX_LINE, name == "long");
        let (code, v, _) = listen(&format!("cut-{name}"), &bytes, &[]);
        assert_eq!(code, Some(1), "{name}");
        let scans = v["scans"].as_array().unwrap();
        assert_eq!(scans.len(), 2, "{name}: {v}");
        let mut want = alone["scans"][0].clone();
        // Line numbers of the second scan's problems (none) are the same.
        want["problems"] = serde_json::json!([]);
        assert_eq!(scans[1]["objects"], want["objects"], "{name}");
        assert_eq!(scans[1]["totals"], want["totals"], "{name}");
        assert_eq!(scans[1]["defects"], want["defects"], "{name}");
        assert_eq!(scans[1]["problems"], serde_json::json!([]), "{name}");
        assert_eq!(scans[0]["totals"], Value::Null);
        // The first keeps only its own rows (row lines before the cut).
        let first_rows = first_ls[..k]
            .iter()
            .filter(|l| l.starts_with(b"R,"))
            .count();
        assert_eq!(scans[0]["rows"], first_rows, "{name}");
        let errors: Vec<&str> = v["line_errors"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| e["kind"].as_str().unwrap())
            .collect();
        let want_errors = if name == "long" {
            vec!["too-long", "cut", "scan-cut"]
        } else {
            vec!["cut", "scan-cut"]
        };
        assert_eq!(errors, want_errors, "{name}: {v}");
        assert_eq!(v["line_errors"][0]["line"], k + 1);
    }
}

/// `-o` with a stream cut before its end line: the scan's image would be
/// partial, so an existing file keeps its bytes, and the run says so; the
/// same stream whole writes it.
#[test]
fn a_cut_scan_does_not_replace_an_existing_image() {
    let bytes = stream("o", 3);
    let img = tmp_in(TAG, "kept.npy");
    std::fs::write(&img, b"a good image of an earlier run").unwrap();
    let cut = &bytes[..bytes.len() * 2 / 3];
    let (code, _, err) = listen("cut-o", cut, &["-o", s(&img)]);
    assert_eq!(code, Some(1));
    assert_eq!(
        std::fs::read(&img).unwrap(),
        b"a good image of an earlier run"
    );
    assert!(
        err.contains("scan 1 has no end line (cut)") && err.contains("not written"),
        "{err}"
    );
    let (code, _, err) = listen("whole-o", &bytes, &["-o", s(&img)]);
    assert_eq!(code, Some(0), "{err}");
    let g = dmap::npy::read_gradient(&img).unwrap();
    assert_eq!((g.rows, g.cols), (7, 50));
}

/// `dmap listen` without a source names both it can read from.
#[test]
fn no_source_names_input_and_port() {
    let out = dmap(&["listen"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--input") && err.contains("--port"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    let out = dmap(&["listen", "--input", "x", "--port", "y"]);
    assert_eq!(out.status.code(), Some(2));
}
