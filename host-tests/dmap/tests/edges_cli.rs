//! `dmap` at its edges, as a careless or hostile user meets it: sizes near
//! the integer limits, standard output closed or full, outputs that name
//! inputs, hostile result streams, degenerate configurations and the
//! messages that explain them. Every test runs the real binary on real
//! files and checks the exit status, the files left behind and the words.

use crate::common;

use cvm_reference::Geometry;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn dmap_cmd() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dmap"))
}

fn dmap(args: &[&str]) -> Output {
    dmap_cmd().args(args).output().expect("run dmap")
}

/// A fresh directory for one test.
fn workdir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("edges_cli")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Failed with status 1 and exactly one line on stderr, containing `needle`.
fn assert_one_line_error(out: &Output, needle: &str) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(1), "stderr: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
    assert!(err.starts_with("dmap: error: "), "{err}");
    assert!(err.contains(needle), "{err:?} lacks {needle:?}");
}

/// A usage error (clap): status 2, one line.
fn assert_usage_error(out: &Output, needle: &str) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(2), "stderr: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
    assert!(err.contains(needle), "{err:?} lacks {needle:?}");
}

fn assert_ok(out: &Output) {
    assert!(out.status.success(), "stderr: {}", stderr(out));
}

/// Files in `dir` whose name starts with `prefix`.
fn files_starting(dir: &Path, prefix: &str) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(prefix))
        .collect();
    v.sort();
    v
}

/// A deterministic scan of counts (a moving spot plus noise).
fn scan_data(rows: usize, cols: usize, j1: usize, j2: usize, seed: u64) -> Vec<u16> {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut out = Vec::with_capacity(rows * cols * j1 * j2);
    for r in 0..rows {
        for c in 0..cols {
            let cy = (j1 as f64 - 1.0) * (0.5 + 0.3 * ((r + 2 * c) as f64 * 0.3).sin());
            let cx = (j2 as f64 - 1.0) * (0.5 + 0.3 * ((3 * r + c) as f64 * 0.2).cos());
            for i in 0..j1 * j2 {
                let (y, x) = ((i / j2) as f64, (i % j2) as f64);
                let d2 = (y - cy).powi(2) + (x - cx).powi(2);
                let v = 3000.0 * (-d2 / 2.0).exp() + (rnd() % 40) as f64;
                out.push(v as u16);
            }
        }
    }
    out
}

fn write_scan(path: &Path, rows: usize, cols: usize, j1: usize, j2: usize, seed: u64) {
    let data = scan_data(rows, cols, j1, j2, seed);
    dmap::npy::write_scan_u16(path, rows, cols, Geometry::new(j1, j2).unwrap(), &data).unwrap();
}

/// A gradient image whose magnitude channel is `mag` (rows x cols).
fn write_gradient(path: &Path, rows: usize, cols: usize, mag: &[f64]) {
    let data: Vec<f64> = mag.iter().flat_map(|&m| [m, m, m]).collect();
    dmap::npy::write_gradient(path, rows, cols, &data).unwrap();
}

fn write_mask(path: &Path, rows: usize, cols: usize, on: &[(usize, usize)]) {
    let mut data = vec![false; rows * cols];
    for &(r, c) in on {
        data[r * cols + c] = true;
    }
    dmap::npy::write_mask(path, &dmap::npy::Mask { rows, cols, data }).unwrap();
}

/// `body*XXXX\n` with its CRC-16/CCITT-FALSE.
fn line_with_crc(body: &str) -> String {
    format!(
        "{body}*{:04X}\n",
        cvm_core::protocol::crc16(body.as_bytes())
    )
}

/// The result lines of `dmap stream` over a small scan.
fn stream_lines(dir: &Path, scores: bool) -> Vec<u8> {
    let scan = dir.join("stream-scan.npy");
    write_scan(&scan, 5, 9, 5, 5, 11);
    let mut args = vec!["stream", s(&scan), "--threshold", "0.05"];
    if scores {
        args.push("--scores");
    }
    let out = dmap(&args);
    assert_ok(&out);
    out.stdout
}

// ---------------------------------------------------------------- item 1

/// `--crop` fields near `usize::MAX`: `r0 + h` must not wrap into a panic.
#[test]
fn crop_near_the_integer_limit_is_refused_in_one_line() {
    let dir = workdir("crop");
    let g = dir.join("g.npy");
    write_gradient(&g, 3, 4, &(0..12).map(f64::from).collect::<Vec<_>>());
    for crop in [
        "18446744073709551615,0,2,2",
        "0,18446744073709551615,2,2",
        "1,0,18446744073709551615,2",
        "0,1,2,18446744073709551615",
    ] {
        let out = dmap(&["render", s(&g), "-o", s(&dir.join("x.png")), "--crop", crop]);
        assert_one_line_error(&out, "exceeds the 3x4 image");
        assert!(!dir.join("x.png").exists());
    }
    // A crop that fits is still drawn.
    assert_ok(&dmap(&[
        "render",
        s(&g),
        "-o",
        s(&dir.join("x.png")),
        "--crop",
        "1,1,2,3",
    ]));
}

/// `--dilate` beyond the image covers the whole image: with the wrapping
/// bug the search window was empty and the estimate 0 x 0.
#[test]
fn dilate_beyond_the_image_searches_the_whole_image() {
    let dir = workdir("dilate");
    let (rows, cols) = (6, 8);
    let mut mag = vec![1.0; rows * cols];
    mag[0] = 9.0; // (0, 0)
    mag[rows * cols - 1] = 9.0; // (5, 7)
    let (g, m) = (dir.join("g.npy"), dir.join("m.npy"));
    write_gradient(&g, rows, cols, &mag);
    write_mask(&m, rows, cols, &[(2, 3)]);
    let pitch = 0.5; // mm per position with --pitch-um 500
    for dilate in ["18446744073709551615", "100"] {
        let out = dmap(&[
            "eval",
            s(&g),
            "--truth",
            s(&m),
            "--threshold",
            "5",
            "--dilate",
            dilate,
            "--pitch-um",
            "500",
            "--json",
        ]);
        assert_ok(&out);
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        // Positions above 5 at (0, 0) and (5, 7): 8 columns x 6 rows.
        assert_eq!(
            v["defects"][0]["estimated_mm"],
            serde_json::json!([8.0 * pitch, 6.0 * pitch]),
            "--dilate {dilate}"
        );
    }
}

// ---------------------------------------------------------------- item 2

/// Runs dmap with its standard output a pipe whose reader is already gone.
fn with_closed_stdout(args: &[&str]) -> Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    dmap_cmd().args(args).stdout(writer).output().unwrap()
}

/// Runs dmap with its standard output on /dev/full (every write: ENOSPC).
fn with_full_stdout(args: &[&str]) -> Output {
    let full = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .expect("/dev/full");
    dmap_cmd().args(args).stdout(full).output().unwrap()
}

fn stdout_commands(dir: &Path) -> Vec<Vec<String>> {
    let lines = dir.join("lines.txt");
    std::fs::write(&lines, stream_lines(dir, true)).unwrap();
    let scan = dir.join("scan.npy");
    write_scan(&scan, 4, 6, 3, 3, 2);
    let (g, m) = (dir.join("g.npy"), dir.join("m.npy"));
    write_gradient(&g, 3, 3, &[1.0, 1.0, 1.0, 1.0, 9.0, 1.0, 1.0, 1.0, 2.0]);
    write_mask(&m, 3, 3, &[(1, 1)]);
    let v = |a: &[&str]| a.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    vec![
        v(&["listen", "--input", s(&lines), "--json"]),
        v(&["listen", "--input", s(&lines)]),
        v(&["eval", s(&g), "--truth", s(&m)]),
        v(&["eval", s(&g), "--truth", s(&m), "--json"]),
        v(&["stream", s(&scan)]),
        v(&["score", s(&scan), "-o", "-"]),
        v(&["render", s(&g), "-o", "-"]),
    ]
}

/// A closed pipe ends the run quietly with 128 + SIGPIPE; no panic.
#[test]
fn closed_stdout_is_a_quiet_exit_141() {
    let dir = workdir("epipe");
    for args in stdout_commands(&dir) {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = with_closed_stdout(&args);
        assert_eq!(out.status.code(), Some(141), "{args:?}: {}", stderr(&out));
        assert_eq!(stderr(&out), "", "{args:?}");
    }
}

/// A full disk under standard output is a one-line error, status 1.
#[test]
fn full_stdout_is_a_one_line_error() {
    let dir = workdir("enospc");
    for args in stdout_commands(&dir) {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = with_full_stdout(&args);
        assert_one_line_error(&out, "writing to standard output: No space left on device");
    }
}

/// `bench --json` through the same writer (a short budget: the check of
/// the implementations, one run each).
#[test]
fn bench_to_closed_or_full_stdout() {
    let args = ["bench", "--json", "--seconds", "0.2", "--geometry", "5x5"];
    let out = with_closed_stdout(&args);
    assert_eq!(out.status.code(), Some(141), "{}", stderr(&out));
    let out = with_full_stdout(&args);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("No space left on device"));
    assert!(!stderr(&out).contains("panicked"));
}

/// `bench --seconds` either holds (within its fixed floor of half a
/// second) or the run says how long it took instead.
#[test]
fn bench_keeps_its_budget_or_says_so() {
    let start = std::time::Instant::now();
    let out = dmap(&["bench", "--json", "--seconds", "0.2", "--geometry", "5x5"]);
    let took = start.elapsed().as_secs_f64();
    assert_ok(&out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for (key, sample) in v["samples"].as_object().unwrap() {
        let runs = sample["runs"].as_u64().unwrap();
        assert!((1..=5).contains(&runs), "{key}: {runs} runs");
    }
    let err = stderr(&out);
    assert!(
        took < 1.5 * 0.2 + 0.8 || err.contains("more than --seconds 0.2"),
        "took {took:.1} s without a word: {err}"
    );
}

// ---------------------------------------------------------------- item 4

/// An output naming an input is refused, through any path to the same
/// file, and the input is left as it was.
#[test]
fn an_output_that_is_an_input_is_refused() {
    let dir = workdir("victim");
    let scan = dir.join("victim.npy");
    write_scan(&scan, 3, 4, 3, 3, 5);
    let before = std::fs::read(&scan).unwrap();
    std::fs::create_dir_all(dir.join("sub")).unwrap();
    std::fs::hard_link(&scan, dir.join("hard.npy")).unwrap();
    std::os::unix::fs::symlink(&scan, dir.join("soft.npy")).unwrap();
    let other_paths = [
        scan.clone(),
        dir.join("sub/../victim.npy"),
        dir.join("hard.npy"),
        dir.join("soft.npy"),
    ];
    for out_path in &other_paths {
        let out = dmap(&["score", s(&scan), "-o", s(out_path)]);
        assert_one_line_error(&out, "refusing to overwrite an input");
        assert_eq!(std::fs::read(&scan).unwrap(), before);
    }
    // render: a .npy input and the PNG output.
    let g = dir.join("g.npy");
    write_gradient(&g, 2, 2, &[1.0, 2.0, 3.0, 4.0]);
    let g_before = std::fs::read(&g).unwrap();
    let out = dmap(&["render", s(&g), "-o", s(&dir.join("sub/../g.npy"))]);
    assert_one_line_error(&out, "refusing to overwrite an input");
    assert_eq!(std::fs::read(&g).unwrap(), g_before);
    // listen: the log, directly or as the image of a later scan (OUT_2.npy).
    let log = dir.join("s.txt");
    let lines = stream_lines(&dir, false);
    std::fs::write(&log, &lines).unwrap();
    let out = dmap(&["listen", "--input", s(&log), "-o", s(&log)]);
    assert_one_line_error(&out, "refusing to overwrite an input");
    assert_eq!(std::fs::read(&log).unwrap(), lines);
    let log2 = dir.join("img_2.npy");
    std::fs::write(&log2, &lines).unwrap();
    let out = dmap(&["listen", "--input", s(&log2), "-o", s(&dir.join("img.npy"))]);
    assert_one_line_error(&out, "refusing to overwrite an input");
    // listen from standard input redirected from the output file.
    let out = dmap_cmd()
        .args(["listen", "--input", "-", "-o", s(&log)])
        .stdin(std::fs::File::open(&log).unwrap())
        .output()
        .unwrap();
    assert_one_line_error(&out, "refusing to overwrite an input");
    assert_eq!(std::fs::read(&log).unwrap(), lines);
}

/// Outputs are written beside their name and renamed: a failed run leaves
/// the previous output whole and no temporary file behind; a successful
/// one replaces it and keeps its permissions.
#[test]
fn outputs_are_replaced_whole_or_not_at_all() {
    use std::os::unix::fs::PermissionsExt;
    let dir = workdir("atomic");
    let scan = dir.join("scan.npy");
    write_scan(&scan, 3, 4, 3, 3, 5);
    let out_path = dir.join("grad.npy");
    std::fs::write(&out_path, b"previous result").unwrap();
    std::fs::set_permissions(&out_path, std::fs::Permissions::from_mode(0o640)).unwrap();
    // A scan with a NaN in its last sample fails the run.
    let mut data = Vec::new();
    for v in scan_data(3, 4, 3, 3, 5) {
        data.extend(f64::from(v).to_le_bytes());
    }
    let n = data.len();
    data[n - 8..].copy_from_slice(&f64::NAN.to_le_bytes());
    let bad = dir.join("bad.npy");
    std::fs::write(&bad, common::raw_npy("<f8", false, &[3, 4, 3, 3], &data)).unwrap();
    let out = dmap(&["score", s(&bad), "-o", s(&out_path)]);
    assert_one_line_error(&out, "is not a finite non-negative intensity");
    assert_eq!(std::fs::read(&out_path).unwrap(), b"previous result");
    // An output in a directory that cannot take a file.
    let out = dmap(&["score", s(&scan), "-o", s(&dir.join("missing/grad.npy"))]);
    assert_one_line_error(&out, "cannot create: No such file or directory");
    // Success replaces the file, mode kept, nothing else left.
    assert_ok(&dmap(&["score", s(&scan), "-o", s(&out_path)]));
    let g = dmap::npy::read_gradient(&out_path).unwrap();
    assert_eq!((g.rows, g.cols), (3, 4));
    let mode = std::fs::metadata(&out_path).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o640);
    let mut names = files_starting(&dir, "");
    names.retain(|n| n != "missing");
    assert_eq!(names, ["bad.npy", "grad.npy", "scan.npy"]);
}

/// `-o -` writes to standard output (score, render), never a file named `-`;
/// listen and simulate, whose standard output has another use or who write
/// two files, refuse it.
#[test]
fn dash_output_is_standard_output() {
    let dir = workdir("dash");
    let scan = dir.join("scan.npy");
    write_scan(&scan, 3, 4, 3, 3, 5);
    let file = dir.join("grad.npy");
    assert_ok(&dmap(&["score", s(&scan), "-o", s(&file)]));
    let out = dmap_cmd()
        .args(["score", s(&scan), "-o", "-"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert_ok(&out);
    assert_eq!(out.stdout, std::fs::read(&file).unwrap());
    let out = dmap_cmd()
        .args(["render", s(&file), "-o", "-"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert_ok(&out);
    assert!(out.stdout.starts_with(b"\x89PNG\r\n\x1a\n"));
    let log = dir.join("s.txt");
    std::fs::write(&log, stream_lines(&dir, false)).unwrap();
    let out = dmap_cmd()
        .args(["listen", "--input", s(&log), "-o", "-"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert_one_line_error(&out, "standard output carries the summary");
    let out = dmap_cmd()
        .args([
            "simulate",
            "--preset",
            "prototype",
            "--rows",
            "2",
            "--cols",
            "2",
            "-o",
            "-",
        ])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert_one_line_error(&out, "give both file names");
    assert!(!dir.join("-").exists());
}

/// `simulate -o a.npy --truth ./a.npy` names one file twice.
#[test]
fn simulate_refuses_the_same_file_for_scan_and_truth() {
    let dir = workdir("simsame");
    let a = dir.join("a.npy");
    std::fs::create_dir_all(dir.join("sub")).unwrap();
    let out = dmap(&[
        "simulate",
        "--preset",
        "prototype",
        "--rows",
        "2",
        "--cols",
        "2",
        "-o",
        s(&a),
        "--truth",
        s(&dir.join("sub/../a.npy")),
    ]);
    assert_one_line_error(&out, "name the same file");
    assert!(!a.exists());
}

// ---------------------------------------------------------------- item 5

/// 64 MiB without a newline on standard input: listen keeps a line buffer
/// of the protocol's size, reports the line, and decodes what follows.
#[test]
fn endless_line_is_dropped_not_buffered() {
    let dir = workdir("longline");
    let lines = stream_lines(&dir, false);
    let mut child = dmap_cmd()
        .args(["listen", "--input", "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    let mut stdin = child.stdin.take().unwrap();
    let chunk = vec![b'x'; 1 << 20];
    for _ in 0..64 {
        stdin.write_all(&chunk).unwrap();
    }
    stdin.write_all(b"\n").unwrap();
    stdin.write_all(&lines).unwrap();
    stdin.flush().unwrap();
    // Still running (standard input open): its peak so far.
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let hwm_kb: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap();
    drop(stdin);
    let out = child.wait_with_output().unwrap();
    assert!(
        hwm_kb < 32 * 1024,
        "listen held {hwm_kb} kB after a 64 MiB line"
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(&format!(
            "line 1: line of {} bytes is longer than the protocol's 280",
            (64 << 20) + 1
        )),
        "{text}"
    );
    // The scan after the garbage is decoded whole.
    assert!(text.contains("scan 1: firmware"), "{text}");
    assert!(text.contains("rows 5 frames 45"), "{text}");
    // The garbage is damage: non-zero status.
    assert_eq!(out.status.code(), Some(1));
}

/// A stream of many scans writes at most `--max-scans` images (64 by
/// default) and says so.
#[test]
fn scans_written_per_run_are_capped() {
    let dir = workdir("manyscans");
    let one = stream_lines(&dir, false);
    let log = dir.join("many.txt");
    std::fs::write(&log, one.repeat(70)).unwrap();
    let out = dmap(&["listen", "--input", s(&log), "-o", s(&dir.join("img.npy"))]);
    assert_one_line_error(&out, "6 scan(s) beyond --max-scans 64 skipped");
    assert_eq!(files_starting(&dir, "img").len(), 64);
    let dir2 = workdir("manyscans3");
    let out = dmap(&[
        "listen",
        "--input",
        s(&log),
        "-o",
        s(&dir2.join("img.npy")),
        "--max-scans",
        "3",
    ]);
    assert_one_line_error(&out, "67 scan(s) beyond --max-scans 3 skipped");
    assert_eq!(
        files_starting(&dir2, "img"),
        ["img.npy", "img_2.npy", "img_3.npy"]
    );
    assert_usage_error(
        &dmap(&["listen", "--input", s(&log), "--max-scans", "0"]),
        "0",
    );
}

/// Lines with valid CRCs claiming row 1 677 720 of a 9-column scan: the
/// 362 MB image the claim implies is not written.
#[test]
fn claimed_size_is_checked_against_what_arrived() {
    let dir = workdir("forged");
    // A real scan's lines (header of the current protocol), with a row
    // line moved to row 1 677 720 and an end line claiming the rows up to
    // it, every CRC valid.
    let real = String::from_utf8(stream_lines(&dir, false)).unwrap();
    let recrc = |line: &str| line_with_crc(line.split('*').next().unwrap());
    let mut stream = String::new();
    for line in real.lines() {
        if let Some(rest) = line.strip_prefix("R,4,") {
            stream += &recrc(&format!("R,1677720,{rest}"));
        } else if line.starts_with("E,") {
            stream += &recrc(&line.replacen("rows=5,", "rows=1677721,", 1));
        } else {
            stream += &format!("{line}\n");
        }
    }
    assert!(stream.contains("R,1677720,") && stream.contains("rows=1677721,"));
    let log = dir.join("forged.txt");
    std::fs::write(&log, &stream).unwrap();
    let img = dir.join("img.npy");
    let out = dmap(&["listen", "--input", s(&log), "-o", s(&img)]);
    assert_one_line_error(&out, "claims 1677721 rows but only 5 arrived");
    assert!(!img.exists());
    assert_eq!(files_starting(&dir, "img"), Vec::<String>::new());
}

// ---------------------------------------------------------------- item 7

#[test]
fn simulate_threads_are_bounded() {
    let dir = workdir("threads");
    let start = std::time::Instant::now();
    let out = dmap(&[
        "simulate",
        "--preset",
        "prototype",
        "--rows",
        "2",
        "--cols",
        "2",
        "--threads",
        "100000",
        "-o",
        s(&dir.join("a.npy")),
    ]);
    assert_usage_error(&out, "1..=256");
    assert!(start.elapsed().as_secs() < 10);
    assert_usage_error(
        &dmap(&["simulate", "--threads", "0", "-o", s(&dir.join("a.npy"))]),
        "1..=256",
    );
}

// ---------------------------------------------------------------- item 8

/// Damage of every kind makes listen fail, after printing its summary.
#[test]
fn listen_fails_on_damage_and_json_carries_it() {
    let dir = workdir("damage");
    let clean = stream_lines(&dir, true);
    let text = String::from_utf8(clean.clone()).unwrap();
    let lines: Vec<&str> = text.split_inclusive('\n').collect();
    let truncated: String = lines[..lines.len() - 1].concat();
    let mut crc = lines.clone();
    let bad = lines[2].replacen(',', ";", 1);
    crc[2] = &bad;
    let crc = crc.concat();
    let mut dup = lines.clone();
    dup.insert(2, lines[1]);
    let duplicated = dup.concat();
    let log = dir.join("clean.txt");
    std::fs::write(&log, &clean).unwrap();
    let out = dmap(&["listen", "--input", s(&log), "--json"]);
    assert_ok(&out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["damaged"], false);
    for (name, body, needle) in [
        (
            "truncated",
            truncated.as_str(),
            "stream ended before the scan's end line",
        ),
        ("crc", crc.as_str(), "checksum mismatch"),
        ("duplicated", duplicated.as_str(), "reported twice"),
        ("garbage", "hello\nworld\n", "no checksum"),
    ] {
        let log = dir.join(format!("{name}.txt"));
        std::fs::write(&log, body).unwrap();
        let out = dmap(&["listen", "--input", s(&log)]);
        assert_one_line_error(&out, "the stream was damaged");
        assert!(
            String::from_utf8_lossy(&out.stdout).contains(needle),
            "{name}"
        );
        let out = dmap(&["listen", "--input", s(&log), "--json"]);
        assert_one_line_error(&out, "the stream was damaged");
        let first = out.stdout.split(|&b| b == b'\n').next().unwrap();
        let v: serde_json::Value = serde_json::from_slice(first).unwrap();
        assert_eq!(v["damaged"], true, "{name}");
        assert!(v.to_string().contains(needle), "{name}: {v}");
        let img = dir.join(format!("{name}.npy"));
        let out = dmap(&["listen", "--input", s(&log), "-o", s(&img)]);
        assert_one_line_error(&out, "the stream was damaged");
        assert!(
            String::from_utf8_lossy(&out.stdout).contains(needle),
            "{name}"
        );
    }
    // No header at all: the JSON object is still there.
    let out = dmap(&["listen", "--input", s(&dir.join("garbage.txt")), "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["firmware"], serde_json::Value::Null);
    // Two damaged lines, and no scan at all.
    assert_eq!(v["line_error_count"], 3);
    assert_eq!(v["line_errors"][2]["kind"], "no-scan");
    let out = dmap(&[
        "listen",
        "--input",
        s(&dir.join("garbage.txt")),
        "-o",
        s(&dir.join("x.npy")),
    ]);
    assert_one_line_error(&out, "no scan in the stream");
    assert!(stderr(&out).contains("3 line error(s)"));
}

// ---------------------------------------------------------------- item 9

/// `--raw` distances are in counts: no default threshold for them.
#[test]
fn raw_needs_a_threshold_and_odd_thresholds_are_explained() {
    let dir = workdir("raw");
    let scan = dir.join("scan.npy");
    write_scan(&scan, 3, 4, 15, 15, 7);
    assert_one_line_error(&dmap(&["stream", s(&scan), "--raw"]), "give --threshold");
    // A threshold in counts is taken as given.
    let out = dmap(&["stream", s(&scan), "--raw", "--threshold", "1e9"]);
    assert_ok(&out);
    assert_eq!(stderr(&out), "");
    // 0.5 under raw's score format rounds to one step of 2^25 units.
    let out = dmap(&["stream", s(&scan), "--raw", "--threshold", "0.5"]);
    assert_ok(&out);
    let err = stderr(&out);
    assert!(err.contains("--threshold 0.5 becomes 33554432"), "{err}");
    assert!(String::from_utf8_lossy(&out.stdout).contains("thr=1,pthr=3277,sthr=4294967295,q=-25"));
    // Above every score: said, in a short number.
    let out = dmap(&["stream", s(&scan), "--threshold", "1e300"]);
    assert_ok(&out);
    let err = stderr(&out);
    assert!(
        err.contains("--threshold 1e300 is above the largest score"),
        "{err}"
    );
    // The end line may still count power-channel defects: the warning
    // says which channel it is about.
    assert!(err.contains("defect on the CVM channel"), "{err}");
    assert!(!err.contains("0000000000"), "{err}");
    for t in ["inf", "NaN", "-1"] {
        let out = dmap(&["stream", s(&scan), &format!("--threshold={t}")]);
        assert_eq!(out.status.code(), Some(1), "{t}");
        assert!(stderr(&out).contains("--threshold must be"), "{t}");
    }
}

/// Detector geometries the distance is blind to get a warning exactly when
/// the gradient they produce is zero.
#[test]
fn blind_geometries_are_warned_about() {
    let dir = workdir("blind");
    for (j1, j2, axes) in [(1, 1, None), (2, 2, None), (2, 5, Some(1)), (3, 3, Some(0))] {
        let scan = dir.join(format!("s{j1}x{j2}.npy"));
        write_scan(&scan, 4, 5, j1, j2, 3);
        let g = dir.join(format!("g{j1}x{j2}.npy"));
        let out = dmap(&["score", s(&scan), "-o", s(&g)]);
        assert_ok(&out);
        let err = stderr(&out);
        let img = dmap::npy::read_gradient(&g).unwrap();
        let max = |k: usize| img.data.chunks(3).map(|p| p[k].abs()).fold(0.0, f64::max);
        match axes {
            None => {
                assert!(max(2) < 1e-12, "{j1}x{j2}: {}", max(2));
                assert!(
                    err.contains("the whole gradient is zero"),
                    "{j1}x{j2}: {err}"
                );
            }
            Some(0) => {
                assert!(max(2) > 1e-3);
                assert_eq!(err, "", "{j1}x{j2}");
            }
            Some(n) => {
                assert!(max(2) > 1e-3);
                assert_eq!(err.lines().count(), 1, "{err}");
                assert!(
                    err.contains(&format!("detector axis {n} (2 cells)")),
                    "{err}"
                );
            }
        }
    }
}

/// NaN colour limits are refused; a gradient spanning -1e308..1e308 gets
/// a colour bar with numbers, and both ends of the colour map.
#[test]
fn render_limits_and_extreme_ranges() {
    let dir = workdir("extremes");
    let g = dir.join("g.npy");
    write_gradient(&g, 1, 3, &[-1e308, 0.0, 1e308]);
    let png = dir.join("g.png");
    for (flag, v) in [("--vmin", "NaN"), ("--vmax", "inf")] {
        let out = dmap(&["render", s(&g), "-o", s(&png), flag, v]);
        assert_one_line_error(&out, "must be a finite number");
    }
    assert_ok(&dmap(&["render", s(&g), "-o", s(&png), "--scale", "4"]));
    let ticks = dmap::render::ticks(-1e308, 1e308, false);
    let labels: Vec<&str> = ticks.iter().map(|(_, l)| l.as_str()).collect();
    assert_eq!(
        labels,
        ["-1.00E308", "-5.00E307", "0", "5.00E307", "1.00E308"]
    );
    // The two extremes take the two ends of viridis (with the overflow,
    // every value took the bottom colour).
    let (lo, hi) = (-1e308, 1e308);
    assert_eq!(dmap::render::colour(lo, lo, hi, false), [68, 1, 84]);
    assert_eq!(dmap::render::colour(hi, lo, hi, false), [253, 231, 37]);
    assert_eq!(
        dmap::render::colour(0.0, lo, hi, false),
        dmap::render::colour(0.5, 0.0, 1.0, false)
    );
}

// ---------------------------------------------------------------- item 10

#[test]
fn messages_name_the_file_and_the_real_problem() {
    let dir = workdir("messages");
    // cvm-fixed on a sample that is not a count: the file is named.
    let data: Vec<u8> = (0..4 * 9)
        .flat_map(|i| (i as f32 * 0.5).to_le_bytes())
        .collect();
    let f = dir.join("halves.npy");
    std::fs::write(&f, common::raw_npy("<f4", false, &[2, 2, 3, 3], &data)).unwrap();
    let out = dmap(&[
        "score",
        s(&f),
        "--distance",
        "cvm-fixed",
        "-o",
        s(&dir.join("g.npy")),
    ]);
    assert_one_line_error(&out, &format!("{}: float32 scan value 0.5", f.display()));
    // A .npy of format version 9.
    let mut v9 = common::raw_npy("<u2", false, &[1, 1, 2, 2], &[0; 8]);
    v9[6] = 9;
    let f9 = dir.join("v9.npy");
    std::fs::write(&f9, &v9).unwrap();
    let out = dmap(&["score", s(&f9), "-o", s(&dir.join("g.npy"))]);
    assert_one_line_error(&out, ".npy format version 9.0 is not supported");
    // One limit for the detector, the scorers' own.
    for det in ["20x20", "0x5", "17x3"] {
        let out = dmap(&["simulate", "--detector", det, "-o", s(&dir.join("a.npy"))]);
        assert_usage_error(&out, "each axis in 1..=16");
        assert!(
            stderr(&out).contains("'--detector <J1xJ2>'"),
            "{}",
            stderr(&out)
        );
        assert!(!stderr(&out).contains("64"), "{}", stderr(&out));
    }
    // bench refuses a geometry it cannot time, at once.
    for geometry in ["1x1", "2x2"] {
        let start = std::time::Instant::now();
        let out = dmap(&["bench", "--geometry", geometry, "--seconds", "1"]);
        assert_one_line_error(&out, "the whole gradient is zero");
        assert!(start.elapsed().as_secs_f64() < 5.0);
    }
    // Huge numbers stay short.
    let (g, m) = (dir.join("g3.npy"), dir.join("m3.npy"));
    write_gradient(&g, 2, 2, &[1.0, 2.0, 3.0, 4.0]);
    write_mask(&m, 2, 2, &[(0, 0)]);
    let out = dmap(&["eval", s(&g), "--truth", s(&m), "--threshold", "1e300"]);
    assert_ok(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("threshold 1e300 (given)"), "{text}");
    let out = dmap(&[
        "render",
        s(&g),
        "-o",
        s(&dir.join("x.png")),
        "--vmin",
        "1e300",
        "--vmax",
        "1",
    ]);
    assert_one_line_error(&out, "--vmin 1e300 must be below --vmax 1");
}

/// `render --scale 64` of a large image is refused from the header alone,
/// before its values are read.
#[test]
fn render_refuses_an_oversized_image_before_reading_it() {
    let dir = workdir("bigrender");
    let (rows, cols) = (3000usize, 4000usize);
    // A sparse file: a header and 288 MB of zeros that take no disk.
    let head = common::raw_npy("<f8", false, &[rows, cols, 3], &[]);
    let big = dir.join("big.npy");
    let f = std::fs::File::create(&big).unwrap();
    (&f).write_all(&head).unwrap();
    f.set_len((head.len() + rows * cols * 3 * 8) as u64)
        .unwrap();
    let start = std::time::Instant::now();
    let out = dmap(&[
        "render",
        s(&big),
        "-o",
        s(&dir.join("x.png")),
        "--scale",
        "10",
    ]);
    assert_one_line_error(&out, "too large: lower --scale");
    assert!(start.elapsed().as_secs_f64() < 5.0);
    assert_usage_error(
        &dmap(&[
            "render",
            s(&big),
            "-o",
            s(&dir.join("x.png")),
            "--scale",
            "65",
        ]),
        "65",
    );
}

// ---------------------------------------------------------------- item 6

/// `score` and `stream` work a band of rows at a time from a mapped file:
/// on a scan of several bands their output is the whole-scan computation's,
/// bit for bit.
#[test]
fn banded_scoring_equals_whole_scan_scoring() {
    let dir = workdir("banded");
    let (rows, cols, j1, j2) = (120, 100, 15, 15);
    // More than one band (and the stream's 64 KiB pieces).
    assert!(dmap::npy::band_rows(cols, j1 * j2) < rows / 2);
    let data = scan_data(rows, cols, j1, j2, 17);
    let scan = dir.join("scan.npy");
    let geometry = Geometry::new(j1, j2).unwrap();
    dmap::npy::write_scan_u16(&scan, rows, cols, geometry, &data).unwrap();
    let scoring = dmap::options::ScoringArgs::default();
    // f64 CVM against the reference crate's whole-scan gradient.
    let g = dir.join("cvm.npy");
    assert_ok(&dmap(&["score", s(&scan), "-o", s(&g)]));
    let values: Vec<f64> = data.iter().map(|&v| f64::from(v)).collect();
    let embedding = cvm_reference::CvmEmbedding::new(&scoring.reference_config(j1, j2).unwrap());
    let want = cvm_reference::gradient_image(&values, rows, cols, geometry, &embedding);
    let got = dmap::npy::read_gradient(&g).unwrap().data;
    assert_eq!(got.len(), want.len());
    for (i, (a, b)) in got.chunks(3).zip(want.chunks(3)).enumerate() {
        // The same distances bit for bit; the magnitude is sqrt(g0² + g1²)
        // here and hypot there, which may differ in the last bit.
        assert_eq!(a[..2], b[..2], "position {i}");
        assert!((a[2] - b[2]).abs() <= 1e-15 * b[2], "position {i}");
    }
    // Fixed point against the batch scorer.
    let scorer = scoring.scorer(j1, j2).unwrap();
    let g = dir.join("fixed.npy");
    assert_ok(&dmap(&[
        "score",
        s(&scan),
        "-o",
        s(&g),
        "--distance",
        "cvm-fixed",
    ]));
    let want = dmap::fixed::to_image(
        &scorer,
        &dmap::fixed::score_scan(&scorer, rows, cols, &data),
    );
    assert_eq!(dmap::npy::read_gradient(&g).unwrap().data, want);
    // The pipeline against the in-memory stream.
    let out = dmap(&["stream", s(&scan), "--scores", "--threshold", "0.05"]);
    assert_ok(&out);
    let output = dmap::stream::OutputArgs {
        threshold: Some(0.05),
        scores: true,
        ..Default::default()
    };
    let want = dmap::stream::stream_scan(
        &scorer,
        output.settings(&scorer, (rows, cols)).unwrap(),
        rows,
        &data,
    )
    .unwrap();
    assert!(want.len() > 1 << 16);
    assert!(out.stdout == want, "stream output differs");
}
