//! `dmap score` run as a user runs it: the built binary on small generated
//! scans, its output checked against the brute-force f64 references, and
//! bad input checked for a one-line error and a non-zero exit.

use cvm_reference::{
    CvmConfig, Geometry, Ground, PaperWeights, cvm_brute, emd_independent, gradient_image_fn,
    mean_dir,
};
use std::path::{Path, PathBuf};

use crate::common;
use common::raw_npy;
use std::process::Command;

fn workdir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("score_cli")
        .join(name);
    std::fs::create_dir_all(&dir).expect("create test directory");
    dir
}

fn u16_scan_bytes(shape: [usize; 4], data: &[u16]) -> Vec<u8> {
    let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
    raw_npy("<u2", false, &shape, &bytes)
}

/// Deterministic pseudo-random counts: sparse beams, some dense maps and a
/// few dark maps, like a scan across a part.
fn synthetic_scan(rows: usize, cols: usize, g: Geometry, seed: u64) -> Vec<u16> {
    let mut s = seed | 1;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let mut data = Vec::with_capacity(rows * cols * g.cells());
    for p in 0..rows * cols {
        let kind = next() % 5;
        for _ in 0..g.cells() {
            let x = match kind {
                _ if p % 7 == 3 => 0,                               // dark map
                0 => (next() % 65536) as u16,                       // dense, full range
                1 | 2 if next() % 4 == 0 => (next() % 4000) as u16, // sparse beam
                1 | 2 => 0,
                _ => (next() % 5) as u16, // faint
            };
            data.push(x);
        }
    }
    data
}

struct Run {
    code: Option<i32>,
    stderr: String,
}

fn dmap(args: &[&str]) -> Run {
    let out = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(args)
        .output()
        .expect("run dmap");
    Run {
        code: out.status.code(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

fn close(a: f64, b: f64, rel: f64, abs: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()) + abs
}

/// A scan of `rows x cols` maps of geometry `g`.
struct ScanCase<'a> {
    rows: usize,
    cols: usize,
    g: Geometry,
    scan: &'a [u16],
}

/// Score the scan with `flags` and compare every value with `reference`
/// (to 1e-9 relative, `abs` absolute for values that are 0 in exact
/// arithmetic).
fn check_against(
    name: &str,
    case: ScanCase,
    flags: &[&str],
    abs: f64,
    reference: impl Fn(&[f64], &[f64]) -> f64,
) {
    let ScanCase {
        rows,
        cols,
        g,
        scan,
    } = case;
    let dir = workdir(name);
    let input = dir.join("scan.npy");
    let output = dir.join("grad.npy");
    std::fs::write(&input, u16_scan_bytes([rows, cols, g.j1(), g.j2()], scan)).unwrap();
    let mut args = vec![
        "score",
        input.to_str().unwrap(),
        "-o",
        output.to_str().unwrap(),
    ];
    args.extend(flags);
    let run = dmap(&args);
    assert_eq!(run.code, Some(0), "{name}: dmap failed: {}", run.stderr);
    let image = dmap::npy::read_gradient(&output).expect("read output");
    assert_eq!(
        (image.rows, image.cols),
        (rows, cols),
        "{name}: output shape"
    );
    let scan_f: Vec<f64> = scan.iter().map(|&x| f64::from(x)).collect();
    let want = gradient_image_fn(&scan_f, rows, cols, g, reference);
    assert_eq!(image.data.len(), want.len());
    for (i, (got, want)) in image.data.iter().zip(&want).enumerate() {
        assert!(
            close(*got, *want, 1e-9, abs),
            "{name}: value {i} (position {}, component {}): dmap {got} vs reference {want}",
            i / 3,
            i % 3
        );
    }
}

#[test]
fn cvm_matches_brute_force() {
    type Case<'a> = ((usize, usize), (usize, usize), &'a [&'a str]);
    let cases: &[Case] = &[
        ((3, 3), (4, 5), &[]),
        ((9, 9), (3, 4), &[]),
        ((2, 5), (3, 3), &["--weights", "unit"]),
        ((5, 2), (2, 4), &["--bmax", "1"]),
        ((1, 1), (3, 2), &[]),
        ((9, 15), (2, 3), &["--weights", "unit", "--bmax", "4"]),
        ((16, 16), (2, 2), &[]),
        ((4, 6), (3, 3), &["--kernels", "square"]),
        ((3, 3), (3, 4), &["--kernels", "square", "--bmax", "1"]),
        (
            (2, 2),
            (3, 3),
            &["--kernels", "square", "--weights", "unit"],
        ),
    ];
    for (n, &((j1, j2), (rows, cols), flags)) in cases.iter().enumerate() {
        let g = Geometry::new(j1, j2).unwrap();
        let scan = synthetic_scan(rows, cols, g, 17 + n as u64);
        let bmax = flags
            .iter()
            .position(|f| *f == "--bmax")
            .map(|i| flags[i + 1].parse::<usize>().unwrap());
        let config = if flags.contains(&"square") {
            CvmConfig::square(g, bmax)
        } else if flags.contains(&"unit") {
            CvmConfig::paper(g, PaperWeights::Unit, bmax)
        } else {
            CvmConfig::paper(g, PaperWeights::Uniform, bmax)
        }
        .unwrap();
        let name = format!("cvm{n}_{j1}x{j2}");
        check_against(
            &name,
            ScanCase {
                rows,
                cols,
                g,
                scan: &scan,
            },
            flags,
            1e-12,
            |a, b| cvm_brute(&config, a, b),
        );
    }
}

#[test]
fn raw_cvm_matches_brute_force() {
    for (n, (j1, j2, kernels)) in [(3, 4, "square"), (2, 3, "paper"), (7, 7, "square")]
        .into_iter()
        .enumerate()
    {
        let g = Geometry::new(j1, j2).unwrap();
        let (rows, cols) = (3, 4);
        let scan = synthetic_scan(rows, cols, g, 99 + n as u64);
        let config = match kernels {
            "square" => CvmConfig::square(g, None),
            _ => CvmConfig::paper(g, PaperWeights::Uniform, None),
        }
        .unwrap()
        .with_normalise(false);
        // Raw distances scale with counts squared; the floor follows.
        let total = (g.cells() * 65535) as f64;
        check_against(
            &format!("raw{n}"),
            ScanCase {
                rows,
                cols,
                g,
                scan: &scan,
            },
            &["--kernels", kernels, "--raw"],
            1e-13 * total * total,
            |a, b| cvm_brute(&config, a, b),
        );
    }
}

#[test]
fn emd_matches_independent_solver() {
    for (n, (j1, j2, ground)) in [
        (3, 3, "euclid"),
        (5, 4, "l1"),
        (9, 9, "euclid"),
        (1, 1, "l1"),
    ]
    .into_iter()
    .enumerate()
    {
        let g = Geometry::new(j1, j2).unwrap();
        let (rows, cols) = (3, 4);
        let scan = synthetic_scan(rows, cols, g, 5 + n as u64);
        let gr = if ground == "l1" {
            Ground::L1
        } else {
            Ground::Euclid
        };
        check_against(
            &format!("emd{n}"),
            ScanCase {
                rows,
                cols,
                g,
                scan: &scan,
            },
            &["--distance", "emd", "--ground", ground],
            1e-12,
            |a, b| emd_independent(g, gr, a, b),
        );
    }
}

#[test]
fn mean_dir_matches_reference() {
    let g = Geometry::new(9, 9).unwrap();
    let scan = synthetic_scan(4, 3, g, 3);
    check_against(
        "meandir",
        ScanCase {
            rows: 4,
            cols: 3,
            g,
            scan: &scan,
        },
        &["--distance", "mean-dir"],
        1e-12,
        |a, b| mean_dir(g, a, b),
    );
}

/// float32 scans with fractional intensities are accepted for f64 scoring.
#[test]
fn float32_scan_is_scored() {
    let g = Geometry::new(3, 3).unwrap();
    let (rows, cols) = (2, 2);
    let values: Vec<f32> = (0..rows * cols * 9)
        .map(|i| ((i * 37) % 11) as f32 * 0.25)
        .collect();
    let dir = workdir("f32");
    let input = dir.join("scan.npy");
    let output = dir.join("grad.npy");
    let bytes: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
    std::fs::write(&input, raw_npy("<f4", false, &[rows, cols, 3, 3], &bytes)).unwrap();
    let run = dmap(&[
        "score",
        input.to_str().unwrap(),
        "-o",
        output.to_str().unwrap(),
    ]);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    let image = dmap::npy::read_gradient(&output).unwrap();
    let config = CvmConfig::paper(g, PaperWeights::Uniform, None).unwrap();
    let scan: Vec<f64> = values.iter().map(|&x| f64::from(x)).collect();
    let want = gradient_image_fn(&scan, rows, cols, g, |a, b| cvm_brute(&config, a, b));
    for (got, want) in image.data.iter().zip(&want) {
        assert!(close(*got, *want, 1e-9, 1e-12), "{got} vs {want}");
    }
}

/// A failed run: non-zero exit, exactly one line on stderr, in the tool's
/// error format, mentioning `needle`, and no panic.
fn assert_one_line_error(run: &Run, needle: &str) {
    assert_ne!(
        run.code,
        Some(0),
        "expected failure, stderr: {}",
        run.stderr
    );
    assert!(run.code.is_some(), "killed by a signal: {}", run.stderr);
    let lines: Vec<&str> = run.stderr.lines().collect();
    assert_eq!(lines.len(), 1, "not one line: {:?}", run.stderr);
    assert!(lines[0].starts_with("dmap: error: "), "{}", lines[0]);
    assert!(!run.stderr.contains("panicked"), "{}", run.stderr);
    // The message proper, after the file name, must say what is wrong.
    let message = lines[0].split_once(".npy: ").map_or(lines[0], |m| m.1);
    assert!(
        message.to_lowercase().contains(&needle.to_lowercase()),
        "{:?} does not mention {needle:?}",
        lines[0]
    );
}

fn score_file(name: &str, contents: &[u8], extra: &[&str]) -> (Run, PathBuf) {
    let dir = workdir("bad");
    let input = dir.join(name);
    std::fs::write(&input, contents).unwrap();
    let output = dir.join(format!("{name}.out.npy"));
    let mut args = vec![
        "score",
        input.to_str().unwrap(),
        "-o",
        output.to_str().unwrap(),
    ];
    args.extend(extra);
    (dmap(&args), input)
}

#[test]
fn bad_input_gives_one_line_error() {
    let ok = |shape: [usize; 4]| u16_scan_bytes(shape, &vec![1; shape.iter().product()]);
    let f64_bytes = |v: &[f64]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("text.npy", b"rows,cols\n1,2\n".to_vec(), "not a .npy"),
        ("short.npy", b"\x93NUMPY\x01".to_vec(), "not a valid .npy"),
        (
            "rank3.npy",
            raw_npy("<u2", false, &[2, 3, 4], &[0; 48]),
            "rank 4",
        ),
        (
            "rank5.npy",
            raw_npy("<u2", false, &[1, 1, 1, 1, 1], &[0; 2]),
            "rank 4",
        ),
        (
            "int64.npy",
            raw_npy("<i8", false, &[1, 1, 2, 2], &[0; 32]),
            "unsupported dtype",
        ),
        (
            "int16.npy",
            raw_npy("<i2", false, &[1, 1, 2, 2], &[0; 8]),
            "unsupported dtype",
        ),
        ("j17.npy", ok([1, 2, 17, 3]), "17x3"),
        ("j0.npy", raw_npy("<u2", false, &[2, 2, 0, 3], &[]), "0x3"),
        (
            "empty.npy",
            raw_npy("<u2", false, &[0, 4, 3, 3], &[]),
            "empty scan",
        ),
        (
            "fortran.npy",
            raw_npy("<u2", true, &[1, 2, 3, 3], &[0; 36]),
            "fortran",
        ),
        (
            "cut-data.npy",
            ok([2, 2, 3, 3])[..150].to_vec(),
            "truncated",
        ),
        (
            "long-data.npy",
            [ok([2, 2, 3, 3]), vec![0; 2]].concat(),
            "needs 72",
        ),
        (
            "cut-header.npy",
            ok([2, 2, 3, 3])[..100].to_vec(),
            "truncated",
        ),
        (
            "nan.npy",
            raw_npy("<f8", false, &[1, 1, 1, 2], &f64_bytes(&[1.0, f64::NAN])),
            "NaN",
        ),
        (
            "neg.npy",
            raw_npy("<f8", false, &[1, 1, 1, 2], &f64_bytes(&[1.0, -2.0])),
            "-2",
        ),
        (
            "inf.npy",
            raw_npy(
                "<f8",
                false,
                &[1, 1, 1, 2],
                &f64_bytes(&[f64::INFINITY, 1.0]),
            ),
            "inf",
        ),
    ];
    for (name, contents, needle) in cases {
        let (run, path) = score_file(name, &contents, &[]);
        assert_one_line_error(&run, needle);
        assert!(
            run.stderr.contains(path.to_str().unwrap()),
            "{name}: path missing: {}",
            run.stderr
        );
    }
    // Unreadable: missing, and a directory.
    let missing = workdir("bad").join("does-not-exist.npy");
    let run = dmap(&["score", missing.to_str().unwrap(), "-o", "/dev/null"]);
    assert_one_line_error(&run, "cannot read");
    let dir = workdir("bad");
    let run = dmap(&["score", dir.to_str().unwrap(), "-o", "/dev/null"]);
    assert_one_line_error(&run, "cannot read");
}

#[test]
fn contradictory_flags_are_refused() {
    let scan = u16_scan_bytes([2, 2, 3, 3], &[1; 36]);
    let cases: &[(&[&str], &str)] = &[
        (
            &["--kernels", "square", "--weights", "uniform"],
            "unit weights",
        ),
        (&["--ground", "l1"], "--ground"),
        (&["--distance", "emd", "--raw"], "--raw"),
        (&["--distance", "mean-dir", "--bmax", "2"], "--bmax"),
        (&["--bmax", "0"], "bmax"),
        (&["--kernels", "square", "--bmax", "3"], "too large"),
    ];
    for (flags, needle) in cases {
        let (run, _) = score_file("flags.npy", &scan, flags);
        assert_one_line_error(&run, needle);
    }
}

/// Output that cannot be written is an error too, not a silent loss.
#[test]
fn unwritable_output_is_reported() {
    let dir = workdir("unwritable");
    let input = dir.join("scan.npy");
    std::fs::write(
        &input,
        u16_scan_bytes([1, 2, 2, 2], &[1, 2, 3, 4, 4, 3, 2, 1]),
    )
    .unwrap();
    let out = dir.join("no-such-dir").join("grad.npy");
    let run = dmap(&[
        "score",
        input.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_one_line_error(&run, "cannot create");
}
