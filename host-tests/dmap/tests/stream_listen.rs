//! `dmap stream` | `dmap listen` against `dmap score --distance cvm-fixed`,
//! and the decoder's handling of damaged streams.

use cvm_core::{Position, Scorer};
use dmap::fixed::{score_scan, to_image};
use dmap::listen::Decoder;
use dmap::options::{KernelArg, ScoringArgs, WeightArg};
use dmap::stream::{OutputArgs, stream_scan};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

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
            let got_def: Vec<(u32, u32)> = s.defects.iter().map(|d| (d.row, d.col)).collect();
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
        flags: 0,
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
        "H,v=2,fw=x,j=3x3,cols=4000000000,k=P,b=0,w=uniform,norm=1,fs=65535,thr=1,q=20,scores=1",
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
    let h = cvm_core::protocol::HeaderInfo::new(&scorer, 4_000_000, 1, true, "0.1.0");
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
/// version: each parses (CRC included) and the header carries `VERSION`.
#[test]
fn protocol_document_examples_parse() {
    let doc = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../docs/protocol.md"
    ))
    .unwrap();
    let examples: Vec<&str> = doc
        .lines()
        .filter(|l| l.contains('*') && (l.starts_with("H,v=") || l.starts_with("E,rows=")))
        .collect();
    assert_eq!(examples.len(), 2, "{examples:?}");
    for l in examples {
        let line = format!("{l}\n");
        match cvm_core::protocol::parse(line.as_bytes()) {
            Ok(cvm_core::protocol::Line::Header(h)) => {
                assert_eq!(h.version, cvm_core::protocol::VERSION)
            }
            Ok(cvm_core::protocol::Line::End(e)) => assert_eq!(e.totals.frames, 90_000),
            other => panic!("{l}: {other:?}"),
        }
    }
}
