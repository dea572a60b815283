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
            let bytes = stream_scan(
                &scorer,
                out.settings(&scorer, (rows, cols)).unwrap(),
                rows,
                &data,
            )
            .unwrap();
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
            let batch = score_scan(&scorer, rows, cols, &data);
            // The power channel's image: every position's power magnitude.
            let want_power: Vec<f64> = batch
                .iter()
                .map(|p| {
                    if p.flags & cvm_core::flags::NO_DATA != 0 {
                        f64::NAN
                    } else {
                        p.pmag as f64 / 32768.0
                    }
                })
                .collect();
            assert!(same(&magnitudes(&s.power_image()), &want_power));
            // Defects decoded are exactly the positions where a channel
            // reaches its threshold.
            let thr = scorer.threshold_from_units(0.05);
            let pthr = cvm_core::power::threshold_from_units(0.1);
            let defective: Vec<bool> = batch
                .iter()
                .map(|p| {
                    p.flags & cvm_core::flags::NO_DATA == 0
                        && (p.mag >= thr || p.pmag as u32 >= pthr)
                })
                .collect();
            let want_def: Vec<(u32, u32)> = (0..rows * cols)
                .filter(|&i| defective[i])
                .map(|i| ((i / cols) as u32, (i % cols) as u32))
                .collect();
            let mut got_def: Vec<(u32, u32)> = s.defects.iter().map(|d| (d.row, d.col)).collect();
            // D lines come strongest first within a row.
            got_def.sort();
            assert_eq!(got_def, want_def);
            let e = s.end.unwrap();
            assert_eq!(e.totals.frames as usize, rows * cols);
            assert_eq!(e.totals.rows as usize, rows);
            // The objects are the 8-connected components of the defects
            // (unless the object table overflowed).
            if e.totals.unobjected == 0 {
                let mut got: Vec<_> = s
                    .objects
                    .iter()
                    .map(|o| ((o.row0, o.row1), (o.col0, o.col1), o.area))
                    .collect();
                got.sort();
                assert_eq!(
                    got,
                    components(rows, cols, &defective),
                    "{rows}x{cols} {j1}x{j2} {args:?}"
                );
            }
        }
    }
}

/// First and last row, first and last column, area.
type Extent = ((u32, u32), (u32, u32), u32);

/// Bounding rows, columns and area of the 8-connected components of
/// `set` (row-major), sorted: a flood fill, independent of the core's
/// streaming labeller.
fn components(rows: usize, cols: usize, set: &[bool]) -> Vec<Extent> {
    let mut seen = vec![false; rows * cols];
    let mut out = Vec::new();
    for start in 0..rows * cols {
        if !set[start] || seen[start] {
            continue;
        }
        seen[start] = true;
        let mut stack = vec![start];
        let (mut r0, mut r1, mut c0, mut c1, mut area) = (rows, 0, cols, 0, 0u32);
        while let Some(i) = stack.pop() {
            let (r, c) = (i / cols, i % cols);
            (r0, r1, c0, c1) = (r0.min(r), r1.max(r), c0.min(c), c1.max(c));
            area += 1;
            for dr in -1i64..=1 {
                for dc in -1i64..=1 {
                    let (nr, nc) = (r as i64 + dr, c as i64 + dc);
                    if (0..rows as i64).contains(&nr) && (0..cols as i64).contains(&nc) {
                        let j = nr as usize * cols + nc as usize;
                        if set[j] && !seen[j] {
                            seen[j] = true;
                            stack.push(j);
                        }
                    }
                }
            }
        }
        out.push(((r0 as u32, r1 as u32), (c0 as u32, c1 as u32), area));
    }
    out.sort();
    out
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
    let bytes = stream_scan(
        &scorer,
        out.settings(&scorer, (rows, cols)).unwrap(),
        rows,
        &data,
    )
    .unwrap();
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
                row == lr && (c0..c0 + cvm_core::protocol::SCORES_PER_LINE).contains(&(i % cols))
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
    .settings(&scorer, (rows, cols))
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

/// The lines of one row of `scores` (with `summary`), as the encoder
/// writes them with a cap of `dcap` `D` lines and no `S` lines.
fn row_lines(
    summary: cvm_core::RowSummary,
    scores: &[cvm_core::PositionScore],
    dcap: u16,
) -> Vec<Vec<u8>> {
    let mut sink = dmap::stream::VecSink::default();
    cvm_core::protocol::encode_row(
        &cvm_core::RowView {
            summary,
            scores,
            threshold: 1,
            power_threshold: 3277,
        },
        dcap,
        false,
        &mut sink,
    );
    lines(&sink.0)
}

/// The byte counts quoted in docs/performance.md ("Line protocol
/// bandwidth"): measured on a
/// 300-column scan of 15x15 maps, on lines of chosen values, and on lines
/// with the widest value the encoder can write in every field.
#[test]
fn bandwidth_figures_of_the_protocol_document() {
    use cvm_core::protocol::{self, HeaderInfo, ResetCause};
    let (rows, cols, j1, j2) = (3, 300, 15, 15);
    let mut r = ChaCha8Rng::seed_from_u64(8);
    let data = scan(&mut r, rows, cols, j1 * j2);
    let scorer = ScoringArgs::default().scorer(j1, j2).unwrap();
    // Thresholds no position reaches: no D and no O lines.
    let out = OutputArgs {
        threshold: Some(1e9),
        power_threshold: Some(f64::INFINITY),
        scores: true,
        max_defect_lines: 16,
        calibration: None,
        ..OutputArgs::default()
    };
    let bytes = stream_scan(
        &scorer,
        out.settings(&scorer, (rows, cols)).unwrap(),
        rows,
        &data,
    )
    .unwrap();
    let ls = lines(&bytes);
    let per_type = |t: u8| {
        ls.iter()
            .filter(|l| l[0] == t)
            .map(|l| l.len())
            .collect::<Vec<_>>()
    };
    assert!(per_type(b'D').is_empty() && per_type(b'O').is_empty());
    assert!(
        per_type(b'R').iter().all(|&n| n <= 47),
        "{:?}",
        per_type(b'R')
    );
    // 17 lines of 18 positions (the last 12) per row, 12 characters a
    // position, each line `S,` + row + `,` + col0 + `,` + positions +
    // `*XXXX\n`: with a three-digit row 17 x 13 bytes of frame, col0's
    // digits (0; 18 to 90; 108 to 288: 1 + 5 x 2 + 11 x 3 = 44) and
    // 3 600 characters, 3 865 bytes; 34 fewer for one-digit rows.
    assert_eq!(per_type(b'S').len(), rows * 17);
    assert_eq!(per_type(b'S').iter().sum::<usize>(), rows * (3865 - 34));
    // A full line with a one-digit row and a three-digit col0: 2 bytes
    // less than with a three-digit row.
    assert_eq!(per_type(b'S').iter().max(), Some(&(232 - 2)));

    // Row 299 with one defect at column 123: a 10-digit magnitude, a
    // 4-digit power magnitude, strength 1.5, found by the distance.
    let p = cvm_core::PositionScore {
        mag: 1_234_567_890,
        strength: 98304,
        pmag: 4567,
        flags: cvm_core::flags::CVM_DEFECT,
        ..Default::default()
    };
    let mut row = vec![cvm_core::PositionScore::default(); 125];
    row[123] = p;
    row[124].pmag = 4568;
    let summary = cvm_core::RowSummary {
        row: 299,
        max: p.mag,
        argmax: Some(123),
        pmax: 4568,
        pargmax: Some(124),
        defects: 1,
        ..Default::default()
    };
    let ls = row_lines(summary, &row, 16);
    assert_eq!((ls[0].len(), ls[1].len()), (45, 42));
    // An object of rows 120-126, columns 40-47.
    let o = cvm_core::objects::Object {
        id: 3,
        row0: 120,
        row1: 126,
        col0: 40,
        col1: 47,
        area: 38,
        peak: 213_909,
        peak_row: 123,
        peak_col: 44,
        peak_mag: 1_234_567_890,
        peak_power: 4567,
        peak_spread: 0,
        channels: cvm_core::flags::CVM_DEFECT | cvm_core::flags::POWER_DEFECT,
        centroid_row_q8: 31_565,
        centroid_col_q8: 11_335,
    };
    let mut sink = dmap::stream::VecSink::default();
    protocol::encode_object(&o, &mut sink);
    assert_eq!(sink.0.len(), 73);

    // The widest value of every field.
    let max = u32::MAX;
    let wide = cvm_core::PositionScore {
        mag: max,
        strength: max,
        pmag: cvm_core::power::POWER_MAX as u16,
        smag: cvm_core::spread::SPREAD_MAX,
        // Every flag a defect can carry (a defect always has data).
        flags: 126,
        ..Default::default()
    };
    let summary = cvm_core::RowSummary {
        row: max,
        max,
        argmax: Some(max),
        pmax: cvm_core::power::POWER_MAX,
        pargmax: Some(max),
        defects: max,
        no_data: max,
        dark: max,
        saturated: max,
    };
    // `listed` is at most the cap, 65535.
    let ls = row_lines(summary, &[wide], u16::MAX);
    assert_eq!(ls[0].len(), 107);
    // The column is at most the row's last one; a row of 2^32 columns is
    // no row this encoder sees, so its width is counted by hand: 10 digits
    // for column 0's 1.
    assert_eq!(ls[1].len() + 9, 67);
    let mut sink = dmap::stream::VecSink::default();
    protocol::encode_object(
        &cvm_core::objects::Object {
            id: max,
            row0: max,
            row1: max,
            col0: max,
            col1: max,
            area: max,
            peak: max,
            peak_row: max,
            peak_col: max,
            peak_mag: max,
            peak_power: cvm_core::power::POWER_MAX as u16,
            peak_spread: cvm_core::spread::SPREAD_MAX,
            channels: cvm_core::flags::DEFECT,
            centroid_row_q8: u64::from(max) << 8,
            centroid_col_q8: u64::from(max) << 8,
        },
        &mut sink,
    );
    assert_eq!(sink.0.len(), 161);
    let mut sink = dmap::stream::VecSink::default();
    protocol::encode_end(
        &cvm_core::Totals {
            rows: max,
            frames: max,
            missing: max,
            dark: max,
            saturated: max,
            defects: max,
            objects: max,
            unobjected: max,
            rejected: max,
            extra: max,
            bad: max,
            clipped: max,
            misplaced: max,
        },
        max,
        cvm_core::Verdict::Fault(cvm_core::Fault::Misplaced),
        &mut sink,
    );
    assert_eq!(sink.0.len(), 277);
    let mut sink = dmap::stream::VecSink::default();
    protocol::encode_header(
        &HeaderInfo {
            version: protocol::VERSION,
            firmware: "cvm-fw-0.1.0-0123456789ab",
            j1: 16,
            j2: 16,
            cols: max,
            kernels: b'P',
            kernel_size: 255,
            weights: "separable",
            normalise: true,
            full_scale: u16::MAX,
            threshold: max,
            power_threshold: max,
            spread_threshold: max,
            q: -120,
            scores: true,
            max_defect_lines: u16::MAX,
            reset_cause: ResetCause::Other,
            boots: max,
            // The longest origin: every source one letter, the longest store word.
            origin: Some(cvm_core::protocol::Origin {
                rows: max,
                sources: [cvm_core::settings::Source::Changed; cvm_core::settings::KEYS],
                store: cvm_core::settings::Store::Foreign,
            }),
        },
        &mut sink,
    );
    assert_eq!(sink.0.len(), 237 + ",sthr=4294967295".len());
    // The score line of a row numbered 2^32 - 1 from a 10-digit col0.
    let s_max = "S,".len()
        + 10
        + 1
        + 10
        + 1
        + protocol::SCORES_PER_LINE * protocol::SCORE_CHARS
        + "*XXXX\n".len();
    assert_eq!(s_max, 246);
    assert!(
        [107, 67, 161, 253, 253, 246]
            .iter()
            .all(|&n| n <= protocol::MAX_LINE)
    );
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
    let header = format!(
        "H,v=7,fw=x,j=3x3,cols=4000000000,k=P,b=0,w=uniform,norm=1,fs=65535,thr=1,pthr=3277,sthr=4294967295,q=20,scores=1,dcap=16,rst=por,boots=1,rows=4000000000,src={},store=none",
        "d".repeat(cvm_core::settings::KEYS)
    );
    for body in [
        header.as_str(),
        "R,2,0,-,0,-,0,0,1,0,0",
        "S,2,3999999999,AAAAAAAAAAAB",
        "E,rows=4000000000,frames=0,missing=0,dark=0,sat=0,defects=0,obj=0,unobj=0,rejected=0,extra=0,bad=0,clipped=0,misplaced=0,dropped=0,verdict=good",
    ] {
        dec.feed(&line_with_crc(body));
    }
    dec.finish();
    assert!(dec.errors.is_empty(), "{:?}", dec.errors);
    let s = &dec.scans[0];
    assert_eq!(s.scores[&2].len(), 1);
    assert_eq!(
        s.scores[&2][&3_999_999_999],
        cvm_core::protocol::ScoreValue {
            mag: 1,
            pmag: 0,
            smag: 0,
            flags: 0
        }
    );
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
        spread_threshold: cvm_core::spread::SPREAD_OFF,
        scores: true,
        max_defect_lines_per_row: 16,
        rows: 1,
        outputs: cvm_core::settings::Outputs::DEFAULT,
        sources: [cvm_core::settings::Source::Default; cvm_core::settings::KEYS],
    };
    let h =
        cvm_core::protocol::HeaderInfo::new(&scorer, &settings, &cvm_core::Boot::power_on("0.1.0"));
    cvm_core::protocol::encode_header(&h, &mut sink);
    let t = cvm_core::Totals {
        rows: 4_000_000,
        ..Default::default()
    };
    cvm_core::protocol::encode_end(&t, 0, cvm_core::Verdict::Good, &mut sink);
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
                && b"HRDSOE".contains(&l.as_bytes()[0])
                && !l.contains('<')
                && l.contains('*')
        })
        .collect();
    let mut kinds = String::new();
    for l in &examples {
        let line = format!("{l}\n");
        match protocol::parse(line.as_bytes()) {
            Ok(Line::Header(h)) => assert_eq!(h.version, protocol::VERSION),
            // A scan of 300 x 300 positions.
            Ok(Line::End(e)) => assert_eq!(e.totals.frames + e.totals.missing, 90_000),
            Ok(_) => {}
            Err(e) => panic!("{l}: {e}"),
        }
        kinds.push_str(&l[..1]);
    }
    assert_eq!(kinds, "HHRDDDSOE", "{examples:?}");
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
    end_keys.push(protocol::VERDICT.to_string());
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
    let s_last = idx(&|l| starts(l, &format!("S,{row_with_two},18,")));
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
        idx(&|l| starts(l, "S,1,18,")),
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
            .any(|w| w.contains("from column 0 after the one from column 18")),
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
        (7, 4095, 3, 1)
    );
    assert_eq!(s.reset_cause, Some(cvm_core::protocol::ResetCause::PowerOn));
    assert_eq!(s.end.unwrap().totals.saturated as usize, saturated);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.starts_with("H,v=7,"), "{text}");
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
            "protocol v7, full scale 4095, at most 3 defect line(s) per row, reset cause por, start 1 since power-on"
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
