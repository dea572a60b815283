//! `dmap stream` | `dmap listen` against `dmap score --distance cvm-fixed`,
//! and the decoder's handling of damaged streams.

use cvm_core::{Position, Scorer};
use dmap::fixed::{score_scan, to_image};
use dmap::listen::Decoder;
use dmap::options::{KernelArg, ScoringArgs, WeightArg};
use dmap::stream::{OutputArgs, stream_scan};
use rand::rngs::ChaCha8Rng;
use rand::{Rng, RngExt, SeedableRng};

fn scan(r: &mut impl Rng, rows: usize, cols: usize, n: usize) -> Vec<u16> {
    let mut prev: Vec<u16> = (0..n).map(|_| r.random_range(0..5000)).collect();
    let mut out = Vec::new();
    for _ in 0..rows * cols {
        let m: Vec<u16> = match r.random_range(0..12) {
            0 => vec![0; n],
            1 => (0..n).map(|_| r.random()).collect(),
            _ => prev
                .iter()
                .map(|&v| (v as f64 * r.random_range(0.8..1.2)) as u16)
                .collect(),
        };
        out.extend_from_slice(&m);
        prev = m;
    }
    out
}

fn decode(bytes: &[u8]) -> Decoder {
    let mut d = Decoder::new();
    for line in bytes.split_inclusive(|&b| b == b'\n') {
        d.feed(line);
    }
    d.finish();
    d
}

fn magnitudes(img: &[f64]) -> Vec<f64> {
    img.chunks(3).map(|p| p[2]).collect()
}

fn same(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x == y || (x.is_nan() && y.is_nan()))
}

/// Every position's magnitude survives encoding and decoding exactly.
#[test]
fn stream_then_listen_reproduces_cvm_fixed() {
    let mut r = ChaCha8Rng::seed_from_u64(3);
    for &(rows, cols, j1, j2) in &[
        (1, 1, 1, 1),
        (1, 40, 9, 9),
        (40, 1, 3, 3),
        (2, 2, 2, 2),
        (7, 33, 15, 15),
        (9, 70, 9, 15),
    ] {
        for args in [
            ScoringArgs::default(),
            ScoringArgs {
                weights: Some(WeightArg::Unit),
                raw: true,
                ..ScoringArgs::default()
            },
            ScoringArgs {
                kernels: KernelArg::Square,
                ..ScoringArgs::default()
            },
        ] {
            let data = scan(&mut r, rows, cols, j1 * j2);
            let scorer = args.scorer(j1, j2).unwrap();
            let out = OutputArgs {
                threshold: Some(0.05),
                scores: true,
                max_defect_lines: 1000,
                calibration: None,
                ..OutputArgs::default()
            };
            let bytes =
                stream_scan(&scorer, out.settings(&scorer, cols).unwrap(), rows, &data).unwrap();
            let dec = decode(&bytes);
            assert!(dec.errors.is_empty(), "{:?}", dec.errors);
            assert_eq!(dec.scans.len(), 1);
            let s = &dec.scans[0];
            assert!(s.problems.is_empty(), "{:?}", s.problems);
            let want = to_image(&scorer, &score_scan(&scorer, rows, cols, &data));
            assert!(
                same(&magnitudes(&s.image()), &magnitudes(&want)),
                "{rows}x{cols} {j1}x{j2} {args:?}"
            );
            // Defects decoded are exactly the positions at or above the threshold.
            let thr = scorer.threshold_from_units(0.05);
            let batch = score_scan(&scorer, rows, cols, &data);
            let want_def: Vec<(u32, u32)> = batch
                .iter()
                .enumerate()
                .filter(|(_, p)| p.mag >= thr)
                .map(|(i, _)| ((i / cols) as u32, (i % cols) as u32))
                .collect();
            let mut got_def: Vec<(u32, u32)> = s.defects.iter().map(|d| (d.row, d.col)).collect();
            // D lines come strongest first within a row.
            got_def.sort();
            assert_eq!(got_def, want_def);
            let e = s.end.unwrap();
            assert_eq!(e.totals.frames as usize, rows * cols);
            assert_eq!(e.totals.rows as usize, rows);
        }
    }
}

fn sample_stream() -> (Scorer, Vec<u8>, usize, usize) {
    let mut r = ChaCha8Rng::seed_from_u64(9);
    let (rows, cols, j1, j2) = (12, 50, 9, 9);
    let data = scan(&mut r, rows, cols, j1 * j2);
    let scorer = ScoringArgs::default().scorer(j1, j2).unwrap();
    let out = OutputArgs {
        threshold: Some(0.05),
        scores: true,
        max_defect_lines: 1000,
        calibration: None,
        ..OutputArgs::default()
    };
    let bytes = stream_scan(&scorer, out.settings(&scorer, cols).unwrap(), rows, &data).unwrap();
    (scorer, bytes, rows, cols)
}

fn lines(bytes: &[u8]) -> Vec<Vec<u8>> {
    bytes
        .split_inclusive(|&b| b == b'\n')
        .map(|l| l.to_vec())
        .collect()
}

/// A changed byte, a truncated line, a lost row line: each is reported by
/// line number (or as a missing row) and every other line is decoded intact.
#[test]
fn damage_is_reported_and_the_rest_survives() {
    let (_, bytes, rows, cols) = sample_stream();
    let clean = decode(&bytes);
    let clean_img = magnitudes(&clean.scans[0].image());
    let ls = lines(&bytes);
    let mut r = ChaCha8Rng::seed_from_u64(1);
    for trial in 0..200 {
        let mut damaged = ls.clone();
        let k = r.random_range(1..ls.len() - 1); // header and end line stay
        let what = trial % 3;
        match what {
            0 => {
                let i = r.random_range(0..damaged[k].len() - 1);
                let old = damaged[k][i];
                damaged[k][i] = loop {
                    let b: u8 = r.random();
                    if b != old && b != b'\n' {
                        break b;
                    }
                };
            }
            1 => {
                let cut = r.random_range(1..damaged[k].len() - 1);
                damaged[k].truncate(cut);
                damaged[k].push(b'\n');
            }
            _ => {
                damaged.remove(k);
            }
        }
        let dec = decode(&damaged.concat());
        let s = &dec.scans[0];
        let kind = ls[k][0];
        if what < 2 {
            assert_eq!(dec.errors.len(), 1, "trial {trial}: {:?}", dec.errors);
            assert_eq!(dec.errors[0].line, k + 1);
        } else {
            assert!(dec.errors.is_empty());
            // A lost line is noticed by the cross-checks.
            assert!(
                !s.problems.is_empty(),
                "trial {trial}: lost {} line undetected",
                kind as char
            );
        }
        // Everything that was not on the damaged line is intact.
        let img = magnitudes(&s.image());
        for (i, (a, b)) in img.iter().zip(&clean_img).enumerate() {
            let on_line = kind == b'S' && {
                let row = i / cols;
                let text = String::from_utf8_lossy(&ls[k]);
                let mut f = text.split(',');
                f.next();
                let lr: usize = f.next().unwrap().parse().unwrap();
                let c0: usize = f.next().unwrap().parse().unwrap();
                row == lr && (c0..c0 + 32).contains(&(i % cols))
            };
            if on_line {
                assert!(a.is_nan());
            } else {
                assert!(
                    a == b || (a.is_nan() && b.is_nan()),
                    "trial {trial}: position {i} changed"
                );
            }
        }
        assert_eq!(s.n_rows(), rows);
    }
}

/// A duplicated frame and a missing frame reach the end line's totals and
/// leave every other position where it belongs.
#[test]
fn duplicated_and_missing_frames_reach_the_totals() {
    let (j1, j2, rows, cols) = (5, 5, 4, 6);
    let mut r = ChaCha8Rng::seed_from_u64(2);
    let data = scan(&mut r, rows, cols, j1 * j2);
    let scorer = ScoringArgs::default().scorer(j1, j2).unwrap();
    let settings = OutputArgs {
        threshold: Some(0.05),
        scores: true,
        max_defect_lines: 100,
        calibration: None,
        ..OutputArgs::default()
    }
    .settings(&scorer, cols)
    .unwrap();
    let words = cvm_core::stream::row_words(cols, j1 * j2, 1);
    let (mut a, mut b) = (vec![0i32; words], vec![0i32; words]);
    let mut p = cvm_core::Pipeline::<16>::new(&scorer, settings, &mut a, &mut b).unwrap();
    let mut sink = dmap::stream::VecSink::default();
    p.begin(&mut sink);
    let n = j1 * j2;
    for i in 0..rows * cols {
        let pos = Position {
            row: (i / cols) as u32,
            col: (i % cols) as u32,
        };
        let f = &data[i * n..(i + 1) * n];
        if i == 9 {
            p.mark_missing(pos, &mut sink);
            continue;
        }
        p.push(pos, f, &mut sink);
        if i == 4 {
            p.push(pos, f, &mut sink);
        }
    }
    p.finish(0, &mut sink);
    let dec = decode(&sink.0);
    let s = &dec.scans[0];
    let e = s.end.unwrap().totals;
    assert_eq!(
        (e.frames, e.missing, e.rejected),
        ((rows * cols - 1) as u32, 1, 1)
    );
    let img = magnitudes(&s.image());
    assert!(img[9].is_nan());
    assert_eq!(img.iter().filter(|v| v.is_nan()).count(), 1);
    // Far from the hole (not a neighbour of position 9), scores are the clean ones.
    let clean = magnitudes(&to_image(&scorer, &score_scan(&scorer, rows, cols, &data)));
    for i in [0, 1, 2, 12, 20, 23] {
        assert_eq!(img[i], clean[i], "position {i}");
    }
}

/// The binaries end to end: `dmap stream --scores | dmap listen` and
/// `dmap score --distance cvm-fixed` write the same magnitudes.
#[test]
fn binaries_agree() {
    let dir = std::env::temp_dir().join(format!("dmap-stream-listen-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (rows, cols, j1, j2) = (6, 11, 9, 9);
    let mut r = ChaCha8Rng::seed_from_u64(4);
    let data = scan(&mut r, rows, cols, j1 * j2);
    let scan_path = dir.join("scan.npy");
    dmap::npy::write_scan_u16(
        &scan_path,
        rows,
        cols,
        cvm_reference::Geometry::new(j1, j2).unwrap(),
        &data,
    )
    .unwrap();
    let exe = env!("CARGO_BIN_EXE_dmap");
    let lines = std::process::Command::new(exe)
        .args(["stream", "--scores"])
        .arg(&scan_path)
        .output()
        .unwrap();
    assert!(
        lines.status.success(),
        "{}",
        String::from_utf8_lossy(&lines.stderr)
    );
    let lines_path = dir.join("lines.txt");
    std::fs::write(&lines_path, &lines.stdout).unwrap();
    let img_path = dir.join("img.npy");
    let listen = std::process::Command::new(exe)
        .args(["listen", "--input"])
        .arg(&lines_path)
        .arg("-o")
        .arg(&img_path)
        .output()
        .unwrap();
    assert!(
        listen.status.success(),
        "{}",
        String::from_utf8_lossy(&listen.stderr)
    );
    let fixed_path = dir.join("fixed.npy");
    let score = std::process::Command::new(exe)
        .args(["score", "--distance", "cvm-fixed", "-o"])
        .arg(&fixed_path)
        .arg(&scan_path)
        .output()
        .unwrap();
    assert!(
        score.status.success(),
        "{}",
        String::from_utf8_lossy(&score.stderr)
    );
    let a = dmap::npy::read_gradient(&img_path).unwrap();
    let b = dmap::npy::read_gradient(&fixed_path).unwrap();
    assert_eq!((a.rows, a.cols), (rows, cols));
    assert!(same(&magnitudes(&a.data), &magnitudes(&b.data)));
    std::fs::remove_dir_all(&dir).ok();
}

/// The byte counts quoted in docs/protocol.md ("Bandwidth"), measured on a
/// 300-column scan of 15x15 maps.
#[test]
fn bandwidth_figures_of_the_protocol_document() {
    let (rows, cols, j1, j2) = (3, 300, 15, 15);
    let mut r = ChaCha8Rng::seed_from_u64(8);
    let data = scan(&mut r, rows, cols, j1 * j2);
    let scorer = ScoringArgs::default().scorer(j1, j2).unwrap();
    // A threshold no position reaches: no D lines.
    let out = OutputArgs {
        threshold: Some(1e9),
        scores: true,
        max_defect_lines: 16,
        calibration: None,
        ..OutputArgs::default()
    };
    let bytes = stream_scan(&scorer, out.settings(&scorer, cols).unwrap(), rows, &data).unwrap();
    let ls = lines(&bytes);
    let per_type = |t: u8| {
        ls.iter()
            .filter(|l| l[0] == t)
            .map(|l| l.len())
            .collect::<Vec<_>>()
    };
    assert!(
        per_type(b'R').iter().all(|&n| n <= 95),
        "{:?}",
        per_type(b'R')
    );
    // 1 955 bytes per row for three-digit row numbers, 20 fewer for one-digit ones.
    assert_eq!(per_type(b'S').iter().sum::<usize>(), rows * (1955 - 20));
    assert!(per_type(b'S').iter().all(|&n| n <= 208));
    // A defect line with a 10-digit magnitude at row 299, column 123.
    let mut sink = dmap::stream::VecSink::default();
    let p = cvm_core::PositionScore {
        g0: 0,
        g1: 0,
        mag: 1_234_567_890,
        strength: 65536,
        pmag: 123,
        flags: cvm_core::flags::CVM_DEFECT,
        ..Default::default()
    };
    let mut row = vec![cvm_core::PositionScore::default(); 124];
    row[123] = p;
    let summary = cvm_core::RowSummary {
        row: 299,
        max: p.mag,
        argmax: Some(123),
        defects: 1,
        ..Default::default()
    };
    cvm_core::protocol::encode_row(
        &cvm_core::RowView {
            summary,
            scores: &row,
            threshold: 1,
            power_threshold: 3277,
        },
        16,
        false,
        &mut sink,
    );
    let ls = lines(&sink.0);
    assert_eq!(ls[0].len(), 36);
    assert_eq!(ls[1].len(), 28);
}

/// `body*XXXX\n` with its CRC-16/CCITT-FALSE.
fn line_with_crc(body: &str) -> Vec<u8> {
    format!(
        "{body}*{:04X}\n",
        cvm_core::protocol::crc16(body.as_bytes())
    )
    .into_bytes()
}

#[test]
fn absurd_geometry_in_valid_lines_costs_no_memory() {
    // Lines with valid CRCs but a header claiming 4e9 columns and an end
    // line claiming 4e9 rows: the decoder reports the gaps as ranges and
    // keeps only the scores that arrived.
    let mut dec = Decoder::new();
    for body in [
        "H,v=3,fw=x,j=3x3,cols=4000000000,k=P,b=0,w=uniform,norm=1,fs=65535,thr=1,q=20,scores=1,dcap=16,rst=por,boots=1",
        "R,2,0,-,0,0,1,0,0",
        "S,2,3999999999,AAAAAB",
        "E,rows=4000000000,frames=0,missing=0,dark=0,sat=0,defects=0,rejected=0,extra=0,bad=0,clipped=0,misplaced=0,dropped=0",
    ] {
        dec.feed(&line_with_crc(body));
    }
    dec.finish();
    assert!(dec.errors.is_empty(), "{:?}", dec.errors);
    let s = &dec.scans[0];
    assert_eq!(s.scores[&2].len(), 1);
    assert_eq!(s.scores[&2][&3_999_999_999], (1, 0));
    let rows = s
        .problems
        .iter()
        .find(|p| p.what.starts_with("no row line"))
        .expect("missing rows reported");
    assert_eq!(
        rows.what,
        "no row line for 3999999999 row(s): 0-1, 3-3999999999"
    );
}

/// A stream that claims an absurd scan size gets a one-line refusal, not an
/// attempt to allocate it.
#[test]
fn absurd_claimed_size_is_refused() {
    let mut sink = dmap::stream::VecSink::default();
    let scorer = ScoringArgs::default().scorer(9, 9).unwrap();
    let settings = cvm_core::Settings {
        cols: 4_000_000,
        threshold: 1,
        power_threshold: 3277,
        scores: true,
        max_defect_lines_per_row: 16,
        firmware_version: "0.1.0",
        reset_cause: cvm_core::protocol::ResetCause::PowerOn,
        boots: 1,
    };
    let h = cvm_core::protocol::HeaderInfo::new(&scorer, &settings);
    cvm_core::protocol::encode_header(&h, &mut sink);
    let t = cvm_core::Totals {
        rows: 4_000_000,
        ..Default::default()
    };
    cvm_core::protocol::encode_end(&t, 0, &mut sink);
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("absurd");
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("lines.txt");
    std::fs::write(&input, &sink.0).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(["listen", "--input"])
        .arg(&input)
        .arg("-o")
        .arg(dir.join("img.npy"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("4000000 rows x 4000000 columns"), "{err}");
    assert!(!dir.join("img.npy").exists());
}

/// The example lines of docs/protocol.md are real lines of the current
/// version: each parses (CRC included), the headers carry `VERSION`, and
/// the key tables of the `H` and `E` lines list the keys in the encoder's
/// order (the `E` keys from the one list the encoder and parser share).
#[test]
fn protocol_document_examples_parse() {
    use cvm_core::protocol::{self, Line};
    let doc = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../docs/protocol.md"
    ))
    .unwrap();
    let examples: Vec<&str> = doc
        .lines()
        .filter(|l| {
            l.len() > 7
                && l.as_bytes()[1] == b','
                && b"HRDSE".contains(&l.as_bytes()[0])
                && !l.contains('<')
                && l.contains('*')
        })
        .collect();
    let mut kinds = String::new();
    for l in &examples {
        let line = format!("{l}\n");
        match protocol::parse(line.as_bytes()) {
            Ok(Line::Header(h)) => assert_eq!(h.version, protocol::VERSION),
            Ok(Line::End(e)) => assert_eq!(e.totals.frames, 90_000),
            Ok(_) => {}
            Err(e) => panic!("{l}: {e}"),
        }
        kinds.push_str(&l[..1]);
    }
    assert_eq!(kinds, "HHRDDSE", "{examples:?}");
    // Key tables: the first column of the rows after `| key | meaning |`.
    let table_after = |heading: &str| -> Vec<String> {
        let from = doc.find(heading).unwrap();
        let rest = &doc[from..];
        let start = rest.find("| key | meaning |").unwrap();
        rest[start..]
            .lines()
            .skip(2)
            .take_while(|l| l.starts_with('|'))
            .flat_map(|l| {
                let cell = l.split('|').nth(1).unwrap().trim().to_string();
                cell.split(", ")
                    .map(|k| k.trim_matches('`').to_string())
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    let header_keys: Vec<String> = examples[0]
        .split('*')
        .next()
        .unwrap()
        .split(',')
        .skip(1)
        .map(|f| f.split('=').next().unwrap().to_string())
        .collect();
    assert_eq!(table_after("### `H`"), header_keys);
    let mut end_keys: Vec<String> = protocol::END_FIELDS
        .iter()
        .map(|(k, _)| k.to_string())
        .collect();
    end_keys.push(protocol::DROPPED.to_string());
    assert_eq!(table_after("### `E`"), end_keys);
}

/// Lines out of the documented order are damage: a row going backwards, a
/// score line of one row after another row's line, defect lines not
/// strongest first or more than listed, score lines going backwards.
#[test]
fn out_of_order_lines_are_reported() {
    let (_, bytes, _, _) = sample_stream();
    let ls = lines(&bytes);
    let idx = |pred: &dyn Fn(&[u8]) -> bool| ls.iter().position(|l| pred(l)).unwrap();
    let starts = |l: &[u8], p: &str| l.starts_with(p.as_bytes());
    let feed = |v: &[Vec<u8>]| {
        let mut d = Decoder::new();
        for l in v {
            d.feed(l);
        }
        d.finish();
        d
    };
    let clean = feed(&ls);
    assert!(clean.damage().is_empty(), "{:?}", clean.damage());

    // The R line of row 3 swapped with the first S line of row 2.
    let mut v = ls.clone();
    let (a, b) = (idx(&|l| starts(l, "R,3,")), idx(&|l| starts(l, "S,2,0,")));
    v.swap(a, b);
    let d = feed(&v);
    assert!(d.errors.is_empty(), "{:?}", d.errors);
    let p: Vec<&str> = d.scans[0]
        .problems
        .iter()
        .map(|p| p.what.as_str())
        .collect();
    assert!(p.iter().any(|w| w.contains("out of order")), "{p:?}");
    assert!(!d.damage().is_empty());

    // Rows going backwards: row 5's lines moved before row 4's.
    let mut v = ls.clone();
    let (r4, r5, r6) = (
        idx(&|l| starts(l, "R,4,")),
        idx(&|l| starts(l, "R,5,")),
        idx(&|l| starts(l, "R,6,")),
    );
    let row5: Vec<Vec<u8>> = v.drain(r5..r6).collect();
    for (k, l) in row5.into_iter().enumerate() {
        v.insert(r4 + k, l);
    }
    let d = feed(&v);
    let p: Vec<&str> = d.scans[0]
        .problems
        .iter()
        .map(|p| p.what.as_str())
        .collect();
    assert!(
        p.iter()
            .any(|w| w.contains("row line of row 4 after row 5")),
        "{p:?}"
    );

    // Two D lines of a row swapped (the sample has rows with several).
    let row_with_two = (0..12)
        .find(|r| ls.iter().filter(|l| starts(l, &format!("D,{r},"))).count() >= 2)
        .expect("a row with two defect lines");
    let first = idx(&|l| starts(l, &format!("D,{row_with_two},")));
    let mut v = ls.clone();
    v.swap(first, first + 1);
    let d = feed(&v);
    let p: Vec<&str> = d.scans[0]
        .problems
        .iter()
        .map(|p| p.what.as_str())
        .collect();
    assert!(p.iter().any(|w| w.contains("not strongest first")), "{p:?}");

    // A D line moved after its row's S lines, and one dropped.
    let mut v = ls.clone();
    let dl = v.remove(first);
    let s_last = idx(&|l| starts(l, &format!("S,{row_with_two},32,")));
    v.insert(s_last, dl);
    let d = feed(&v);
    let p: Vec<&str> = d.scans[0]
        .problems
        .iter()
        .map(|p| p.what.as_str())
        .collect();
    assert!(
        p.iter().any(|w| w.contains("after its score lines")),
        "{p:?}"
    );
    let mut v = ls.clone();
    v.remove(first);
    let d = feed(&v);
    let p: Vec<&str> = d.scans[0]
        .problems
        .iter()
        .map(|p| p.what.as_str())
        .collect();
    assert!(
        p.iter()
            .any(|w| w.starts_with(&format!("row {row_with_two} lists"))),
        "{p:?}"
    );

    // Score lines of a row going backwards.
    let mut v = ls.clone();
    let (s0, s1) = (
        idx(&|l| starts(l, "S,1,0,")),
        idx(&|l| starts(l, "S,1,32,")),
    );
    v.swap(s0, s1);
    let d = feed(&v);
    let p: Vec<&str> = d.scans[0]
        .problems
        .iter()
        .map(|p| p.what.as_str())
        .collect();
    assert!(
        p.iter()
            .any(|w| w.contains("from column 0 after the one from column 32")),
        "{p:?}"
    );
}

/// `dmap stream --full-scale N`: the header declares `fs=N`, the scorer
/// flags exactly the maps with a sample at or above N, and `dmap listen`
/// reports the full scale, the cap, the reset cause and the start count.
#[test]
fn full_scale_reaches_the_header_and_the_scoring() {
    let dir = std::env::temp_dir().join(format!("dmap-full-scale-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (rows, cols, j1, j2) = (4, 9, 3, 3);
    let mut r = ChaCha8Rng::seed_from_u64(12);
    let data: Vec<u16> = (0..rows * cols * j1 * j2)
        .map(|_| r.random_range(0..4200))
        .collect();
    let saturated = data
        .chunks(j1 * j2)
        .filter(|m| m.iter().any(|&v| v >= 4095))
        .count();
    assert!(saturated > 0 && saturated < rows * cols);
    let scan_path = dir.join("scan.npy");
    dmap::npy::write_scan_u16(
        &scan_path,
        rows,
        cols,
        cvm_reference::Geometry::new(j1, j2).unwrap(),
        &data,
    )
    .unwrap();
    let exe = env!("CARGO_BIN_EXE_dmap");
    let out = std::process::Command::new(exe)
        .args(["stream", "--full-scale", "4095", "--max-defect-lines", "3"])
        .arg(&scan_path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dec = decode(&out.stdout);
    assert!(dec.damage().is_empty(), "{:?}", dec.damage());
    let s = &dec.scans[0];
    assert_eq!(
        (s.version, s.full_scale, s.max_defect_lines, s.boots),
        (3, 4095, 3, 1)
    );
    assert_eq!(s.reset_cause, Some(cvm_core::protocol::ResetCause::PowerOn));
    assert_eq!(s.end.unwrap().totals.saturated as usize, saturated);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.starts_with("H,v=3,"), "{text}");
    assert!(text.lines().next().unwrap().contains(",fs=4095,"), "{text}");
    let listen = std::process::Command::new(exe)
        .args(["listen", "--input", "-"])
        .stdin(
            std::fs::File::open({
                let p = dir.join("lines.txt");
                std::fs::write(&p, &out.stdout).unwrap();
                p
            })
            .unwrap(),
        )
        .output()
        .unwrap();
    assert!(listen.status.success());
    let summary = String::from_utf8_lossy(&listen.stdout);
    assert!(
        summary.contains(
            "protocol v3, full scale 4095, at most 3 defect line(s) per row, reset cause por, start 1 since power-on"
        ),
        "{summary}"
    );
    for bad in ["0", "65536"] {
        let out = std::process::Command::new(exe)
            .args(["stream", "--full-scale", bad])
            .arg(&scan_path)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "--full-scale {bad}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
