//! Issue 47, "the newest surfaces under bad input, round 3": an output
//! never written over an input nor begun before it can be finished
//! (`twin --pins`, `vectors DIR`; `sensor --pass-through` is in
//! sensor_cli.rs), inputs read once and within what they announce
//! (`--requests` from a pipe, `.npy` files, `--flash`), options that
//! would have no effect refused (`--power-cut`), no build outliving
//! `dmap`, clear errors, and the repository found at run time.
//!
//! `DMAP_BIN=/path/to/dmap` runs these tests against another build (one
//! from before the fixes, to see each fail). The `twin` runs need what
//! tests/twin.rs needs (python3 with unicorn and pyelftools, the
//! thumbv7em target).

use crate::common;

use common::{s, spot_scan};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn bin() -> String {
    std::env::var("DMAP_BIN").unwrap_or_else(|_| env!("CARGO_BIN_EXE_dmap").to_string())
}

fn dmap_cmd(args: &[&str]) -> Command {
    let mut c = Command::new(bin());
    c.args(args).stdin(Stdio::null());
    c
}

fn run(args: &[&str]) -> Output {
    dmap_cmd(args).output().expect("run dmap")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Waits for `child` at most `secs`, killing it (and failing) if it
/// is still running then.
fn wait_at_most(mut child: Child, secs: u64, what: &str) -> Output {
    let until = Instant::now() + Duration::from_secs(secs);
    while Instant::now() < until {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.kill();
    let out = child.wait_with_output().unwrap();
    panic!(
        "{what}: still running after {secs} s (killed); stderr: {}",
        text(&out.stderr)
    );
}

/// Runs dmap with at most 4 GiB of address space and `secs` of time, so
/// that a reader that does not stop fails here rather than on the machine.
fn run_bounded(args: &[&str], stdin: Stdio, secs: u64) -> Output {
    use std::os::unix::process::CommandExt;
    let mut c = dmap_cmd(args);
    c.stdin(stdin).stdout(Stdio::piped()).stderr(Stdio::piped());
    // SAFETY: setrlimit is async-signal-safe.
    unsafe {
        c.pre_exec(|| {
            let lim = libc::rlimit {
                rlim_cur: 4 << 30,
                rlim_max: 4 << 30,
            };
            libc::setrlimit(libc::RLIMIT_AS, &lim);
            Ok(())
        });
    }
    wait_at_most(c.spawn().unwrap(), secs, &format!("dmap {args:?}"))
}

/// Failed with one line on stderr containing `needle` (no traceback).
fn one_line(what: &str, out: &Output, needle: &str) {
    let err = text(&out.stderr);
    assert!(!out.status.success(), "{what}: exited 0: {err}");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{what}: not one line: {err}"
    );
    assert!(err.contains(needle), "{what}: {err:?} lacks {needle:?}");
}

const ROWS: usize = 5;
const COLS: usize = 10;
const J: usize = 9;

/// A small defect-free scan: every `twin` run here has its configuration,
/// so one firmware build serves them all.
fn scan(dir: &Path) -> PathBuf {
    let p = dir.join("scan.npy");
    spot_scan(&p, ROWS, COLS, J, 7);
    p
}

/// The H743 ELF a default `dmap twin` run of `scan` uses, built (and
/// cached) as `dmap twin` builds it.
fn elf_for(scan: &Path) -> PathBuf {
    #[derive(clap::Parser)]
    struct Emulate {
        #[command(flatten)]
        args: dmap::emulate::EmulateArgs,
    }
    let parsed = <Emulate as clap::Parser>::try_parse_from(["emulate", s(scan)]).unwrap();
    let (file, _) = dmap::emulate::scan_file_and_warnings(&parsed.args).unwrap();
    let header = cvm_fw_app::emufile::ScanHeader::parse(&file).unwrap();
    dmap::twin::build_elf(&dmap::twin::h743_build_config(&header).unwrap()).unwrap()
}

fn twin(args: &[&str]) -> Output {
    let mut all = vec!["twin"];
    all.extend_from_slice(args);
    run(&all)
}

// 1. --pins over an input

#[test]
fn twin_pins_over_an_input_is_refused_and_the_input_kept() {
    let dir = tempfile::tempdir().unwrap();
    let scan = scan(dir.path());
    let other = |name: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, format!("{name}: the user's bytes\n")).unwrap();
        p
    };
    let (flash, req, cal, elf) = (
        other("bank2.bin"),
        other("req.txt"),
        other("cal.json"),
        other("fw.elf"),
    );
    let cases: [(&str, &Path, Vec<&str>); 5] = [
        ("the scan", &scan, vec![]),
        ("--flash", &flash, vec!["--flash", s(&flash)]),
        ("--requests", &req, vec!["--requests", s(&req)]),
        ("--calibration", &cal, vec!["--calibration", s(&cal)]),
        ("--elf", &elf, vec!["--elf", s(&elf)]),
    ];
    for (what, input, opts) in cases {
        let before = std::fs::read(input).unwrap();
        let mut args = vec![s(&scan), "--pins", s(input)];
        args.extend(opts);
        let out = twin(&args);
        assert_eq!(
            std::fs::read(input).unwrap(),
            before,
            "--pins over {what} changed it"
        );
        one_line(what, &out, "refusing to overwrite");
    }
}

// 2. vectors DIR over a folder it did not make

#[test]
fn vectors_refuses_a_folder_it_did_not_make_and_keeps_its_files() {
    let dir = tempfile::tempdir().unwrap();
    let theirs = dir.path().join("theirs");
    std::fs::create_dir(&theirs).unwrap();
    let files: [(&str, &[u8]); 5] = [
        ("index.json", br#"[{"name": "mine"}]"#),
        ("mine.txt", b"my stream\n"),
        ("mine.json", b"{\"mine\": true}\n"),
        (".gitattributes", b"*.txt eol=lf\n"),
        ("notes.md", b"# notes\n"),
    ];
    for (n, b) in files {
        std::fs::write(theirs.join(n), b).unwrap();
    }
    let out = run(&["vectors", s(&theirs)]);
    for (n, b) in files {
        let now = std::fs::read(theirs.join(n)).map(|b| text(&b)).ok();
        assert_eq!(now, Some(text(b)), "{n} was changed or removed");
    }
    assert_eq!(std::fs::read_dir(&theirs).unwrap().count(), files.len());
    one_line(
        "a folder of someone else's",
        &out,
        "not a previous output of dmap vectors",
    );

    // A new folder, then its own output again: written; with a stray file
    // added: refused, the stray file kept.
    let ours = dir.path().join("ours");
    let out = run(&["vectors", s(&ours)]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = run(&["vectors", s(&ours)]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(run(&["vectors", "--check", s(&ours)]).status.success());
    std::fs::write(ours.join("README.md"), b"mine\n").unwrap();
    let out = run(&["vectors", s(&ours)]);
    one_line("a stray file", &out, "README.md");
    assert_eq!(std::fs::read(ours.join("README.md")).unwrap(), b"mine\n");
    // An empty folder is taken.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    assert!(run(&["vectors", s(&empty)]).status.success());

    // An earlier version's output (each vector's report in NAME.json, its
    // exit status in the index) is taken, and its NAME.json files go.
    let old = dir.path().join("old");
    std::fs::create_dir(&old).unwrap();
    let files: [(&str, &[u8]); 5] = [
        (
            "index.json",
            br#"[{"name": "good-clear", "about": "a", "exit": 0}]"#,
        ),
        ("good-clear.txt", b"H\n"),
        ("good-clear.json", b"{}\n"),
        ("commands.json", br#"{"requests": [], "replies": []}"#),
        (".gitattributes", b"* -text\n"),
    ];
    for (n, b) in files {
        std::fs::write(old.join(n), b).unwrap();
    }
    let out = run(&["vectors", s(&old)]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(!old.join("good-clear.json").exists());
    assert!(old.join("good-clear.jsonl").exists());
    assert!(run(&["vectors", "--check", s(&old)]).status.success());
}

// 4. --requests from a pipe

/// A requests file's line: a `status` request, id 5, at beam 10.
fn status_burst() -> Vec<u8> {
    let hex: String = common::framed("C,5,status")
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    format!("10 {hex}\n").into_bytes()
}

#[test]
fn twin_requests_from_a_pipe_are_sent_and_an_empty_one_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scan = scan(dir.path());
    let burst = status_burst();
    let mut child = dmap_cmd(&["twin", s(&scan), "--requests", "/dev/stdin"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(&burst).unwrap();
    let out = wait_at_most(child, 600, "twin --requests /dev/stdin");
    assert!(out.status.success(), "{}", text(&out.stderr));
    let c = common::counters(&out);
    assert!(
        c["uart_rx_bytes"].as_u64().unwrap() >= 12,
        "the request never reached the chip: {c}"
    );

    // An empty pipe: nothing would be sent, so nothing runs.
    let out = dmap_cmd(&["twin", s(&scan), "--requests", "/dev/stdin"])
        .stdin(Stdio::piped())
        .output()
        .unwrap();
    one_line("an empty pipe", &out, "nothing would be sent");
}

// 5. --power-cut that never happens

#[test]
fn a_power_cut_that_never_happens_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let scan = scan(dir.path());
    let out = twin(&[s(&scan), "--power-cut", "1"]);
    let err = text(&out.stderr);
    assert!(!out.status.success(), "exited 0: {err}");
    assert!(err.contains("no power cut happened"), "{err}");
}

// 6. no build outlives dmap

/// Processes (not zombies) whose environment holds `mark`, with their
/// command lines.
fn marked(mark: &str) -> Vec<(u32, String)> {
    let mut found = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(env) = std::fs::read(format!("/proc/{pid}/environ")) else {
            continue;
        };
        if !env.split(|&b| b == 0).any(|v| v == mark.as_bytes()) {
            continue;
        }
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
        let state = stat.rsplit_once(") ").map(|(_, r)| r.chars().next());
        if state != Some(Some('Z')) {
            let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
            found.push((pid, text(&cmdline).replace('\0', " ")));
        }
    }
    found
}

#[test]
fn no_build_outlives_dmap_on_sigterm_sigint_or_sighup() {
    let dir = tempfile::tempdir().unwrap();
    let scan = scan(dir.path());
    for sig in [libc::SIGTERM, libc::SIGINT, libc::SIGHUP] {
        // A full scale no other run uses: a compile-time configuration not
        // built yet, so that cargo is building when the signal comes.
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .subsec_nanos();
        let fs = (60_000 + nanos % 5_000).to_string();
        let mark = format!("DMAP_ORPHAN_MARK={}-{sig}-{nanos}", std::process::id());
        let (key, value) = mark.split_once('=').unwrap();
        let child = dmap_cmd(&["twin", s(&scan), "--full-scale", &fs])
            .env(key, value)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let pid = child.id() as i32;
        let until = Instant::now() + Duration::from_secs(300);
        // rustc compiling a crate (not cargo's first `rustc -vV`).
        while !marked(&mark)
            .iter()
            .any(|(_, c)| c.contains("rustc") && c.contains("--crate-name") && !c.contains("___"))
        {
            assert!(Instant::now() < until, "no rustc started within 300 s");
            std::thread::sleep(Duration::from_millis(50));
        }
        // SAFETY: a signal to our own child.
        unsafe { libc::kill(pid, sig) };
        let out = wait_at_most(child, 30, "dmap after the signal");
        assert!(!out.status.success(), "signal {sig}: dmap exited 0");
        // A killed process group is gone within milliseconds; the build
        // itself would take seconds more.
        let until = Instant::now() + Duration::from_secs(1);
        let mut left = marked(&mark);
        while !left.is_empty() && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(100));
            left = marked(&mark);
        }
        for (p, _) in &left {
            // SAFETY: processes this test started; cleaned up before failing.
            unsafe { libc::kill(*p as i32, libc::SIGKILL) };
        }
        assert!(
            left.is_empty(),
            "signal {sig}: still running after dmap ended: {left:?}"
        );
    }
}

// 7. readers check the signature and the announced size first

#[test]
fn npy_readers_stop_at_a_bad_signature_or_size_without_reading_on() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("z.npy");
    let png = dir.path().join("z.png");
    let cases: [Vec<&str>; 7] = [
        vec!["score", "/dev/zero", "-o", s(&o)],
        vec!["twin", "/dev/zero"],
        vec!["stream", "/dev/zero"],
        vec!["calibrate", "/dev/zero", "-o", s(&o)],
        vec!["render", "/dev/zero", "-o", s(&png)],
        vec!["eval", "/dev/zero", "--truth", "/dev/zero"],
        vec!["emulate", "/dev/zero", "--elf", "/nonexistent.elf"],
    ];
    for args in cases {
        let out = run_bounded(&args, Stdio::null(), 20);
        one_line(&args.join(" "), &out, "not a .npy file");
    }
    assert!(!o.exists() && !png.exists());

    // A header announcing 20 bytes, on a pipe that goes on: refused once
    // one byte more than announced has come.
    let mut npy = common::raw_npy("<u2", false, &[1, 1, 1, 10], &[7; 20]);
    let head = npy.clone();
    npy.extend(std::iter::repeat_n(0u8, 8 << 20));
    let mut child = dmap_cmd(&["score", "/dev/stdin", "-o", s(&o)])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || {
        let _ = stdin.write_all(&npy);
    });
    let out = wait_at_most(child, 20, "score of an overlong pipe");
    writer.join().unwrap();
    one_line("an overlong pipe", &out, "extra bytes after the data");
    // A regular file is sized before its data are read.
    let file = dir.path().join("long.npy");
    let mut long = head;
    long.extend([0u8; 3]);
    std::fs::write(&file, &long).unwrap();
    let out = run(&["score", s(&file), "-o", s(&o)]);
    one_line("3 bytes appended", &out, "holds 23 data bytes but shape");
}

#[test]
fn twin_requests_and_flash_are_read_within_bounds() {
    let dir = tempfile::tempdir().unwrap();
    let scan = scan(dir.path());
    let out = run_bounded(
        &["twin", s(&scan), "--requests", "/dev/zero"],
        Stdio::null(),
        30,
    );
    one_line("--requests /dev/zero", &out, "not a requests file");
    // A 20 GiB sparse file.
    let big = dir.path().join("big.bin");
    std::fs::File::create(&big)
        .unwrap()
        .set_len(20 << 30)
        .unwrap();
    let out = run_bounded(&["twin", s(&scan), "--flash", s(&big)], Stdio::null(), 30);
    one_line(
        "a 20 GiB --flash",
        &out,
        "not a bank 2 image (21474836480 bytes",
    );
}

// 8, 9. --flash that cannot be read or written back

#[test]
fn flash_that_cannot_be_a_bank_is_refused_before_the_run() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let scan = scan(dir.path());
    let folder = dir.path().join("folder");
    std::fs::create_dir(&folder).unwrap();
    let missing = dir.path().join("no-such-folder/bank2.bin");
    let readonly = dir.path().join("readonly.bin");
    std::fs::write(&readonly, vec![0xFF; 1081344]).unwrap();
    std::fs::set_permissions(&readonly, std::fs::Permissions::from_mode(0o444)).unwrap();
    let fifo = dir.path().join("fifo");
    let c = std::ffi::CString::new(s(&fifo)).unwrap();
    // SAFETY: a plain system call on a path of this test's.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    for (what, path, needle) in [
        ("a folder", &folder, "is a directory"),
        ("a missing folder", &missing, "cannot write in its folder"),
        ("a read-only file", &readonly, "is read-only"),
        ("a FIFO", &fifo, "not a regular file"),
    ] {
        let child = dmap_cmd(&["twin", s(&scan), "--flash", s(path)])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let out = wait_at_most(child, 60, what);
        one_line(what, &out, needle);
        assert!(
            text(&out.stderr).starts_with("dmap: error: --flash"),
            "{what}"
        );
    }
    assert_eq!(std::fs::read(&readonly).unwrap(), vec![0xFF; 1081344]);
}

// 10. clear errors

#[test]
fn command_errors_name_what_is_missing_and_numbers_stay_short() {
    let dir = tempfile::tempdir().unwrap();
    let scan = scan(dir.path());
    for (cmd, needle) in [
        ("0:", "no request after `0:`"),
        ("0:--help", "`--help` is not a request"),
        ("0:set", "<KEY=VALUE>"),
        ("0:get", "<KEY>"),
    ] {
        let out = twin(&[s(&scan), "--command", cmd]);
        one_line(cmd, &out, needle);
        assert!(!text(&out.stderr).contains("in the words of"), "{cmd}");
    }
    let o = dir.path().join("x.npy");
    for (args, needle) in [
        (
            vec![
                "sensor",
                "--port",
                "/nope",
                "calibrate",
                "--scans",
                "1",
                "--rate",
                "1e300",
            ],
            "got 1e300",
        ),
        (
            vec!["simulate", "-o", s(&o), "--power-rms-pct", "1e300"],
            "got 1e300",
        ),
        (
            vec!["simulate", "-o", s(&o), "--bubble", "0,0,0,1e300"],
            "radius 1e300 mm",
        ),
    ] {
        let out = run(&args);
        one_line(&args.join(" "), &out, needle);
        assert!(text(&out.stderr).len() < 200, "{}", text(&out.stderr));
    }
}

// 11. two runs on one flash file

#[test]
fn a_second_twin_run_on_the_same_flash_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scan = scan(dir.path());
    let flash = dir.path().join("bank2.bin");
    // The first run waits on a FIFO for its requests, holding the flash
    // file meanwhile.
    let fifo = dir.path().join("requests");
    let c = std::ffi::CString::new(s(&fifo)).unwrap();
    // SAFETY: a plain system call on a path of this test's.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let mut first = dmap_cmd(&[
        "twin",
        s(&scan),
        "--flash",
        s(&flash),
        "--requests",
        s(&fifo),
    ])
    .stdout(Stdio::piped())
    .stderr(Stdio::piped())
    .spawn()
    .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let second = dmap_cmd(&["twin", s(&scan), "--flash", s(&flash)])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let second = wait_at_most(second, 600, "the second run");
    let refused = text(&second.stderr).contains("in use by another dmap twin run");
    if !refused {
        let _ = first.kill();
        let _ = first.wait();
    }
    one_line("the second run", &second, "in use by another dmap twin run");
    // The first one goes on once its requests come.
    std::fs::write(&fifo, status_burst()).unwrap();
    let first = wait_at_most(first, 600, "the first run");
    assert!(first.status.success(), "{}", text(&first.stderr));
    assert_eq!(std::fs::metadata(&flash).unwrap().len(), 1081344);
}

// 12. the repository at run time

#[test]
fn twin_and_emulate_find_the_repository_at_run_time() {
    let dir = tempfile::tempdir().unwrap();
    let scan = scan(dir.path());
    // Outside any checkout, without --repo or CVM_REPO: a clear error,
    // not the checkout dmap was built in.
    for cmd in ["twin", "emulate"] {
        let out = dmap_cmd(&[cmd, s(&scan)])
            .current_dir(dir.path())
            .env_remove("CVM_REPO")
            .output()
            .unwrap();
        one_line(cmd, &out, "cannot find the repository");
        assert!(text(&out.stderr).contains("--repo"), "{cmd}");
        let help = text(&run(&[cmd, "--help"]).stdout);
        assert!(
            help.contains("--repo") && help.contains("CVM_REPO"),
            "{cmd} --help: {help}"
        );
    }
    // A repository of its own (here with a chip model that only reports
    // where it ran from), named by --repo or CVM_REPO: used.
    let fake = dir.path().join("repo");
    std::fs::create_dir_all(fake.join("host-tests/twin/h743twin")).unwrap();
    std::fs::write(fake.join("build.rs"), "").unwrap();
    std::fs::write(fake.join("Cargo.toml"), "").unwrap();
    std::fs::write(fake.join("host-tests/twin/h743twin/__init__.py"), "").unwrap();
    std::fs::write(
        fake.join("host-tests/twin/h743twin/__main__.py"),
        "import json, sys\nprint(json.dumps({\"status\": \"done\", \"fake_model\": True}), file=sys.stderr)\n",
    )
    .unwrap();
    let elf = elf_for(&scan);
    for how in ["--repo", "CVM_REPO"] {
        let mut cmd = dmap_cmd(&["twin", s(&scan), "--elf", s(&elf)]);
        cmd.current_dir(dir.path());
        if how == "--repo" {
            cmd.args(["--repo", s(&fake)]);
        } else {
            cmd.env("CVM_REPO", &fake);
        }
        let out = cmd.output().unwrap();
        assert!(out.status.success(), "{how}: {}", text(&out.stderr));
        assert_eq!(common::counters(&out)["fake_model"], true, "{how}");
    }
    let out = dmap_cmd(&["twin", s(&scan), "--repo", s(&dir.path().join("nope"))])
        .output()
        .unwrap();
    one_line("--repo not a repository", &out, "not the repository");
    let out = dmap_cmd(&["emulate", s(&scan)])
        .env("CVM_REPO", dir.path())
        .output()
        .unwrap();
    one_line("CVM_REPO not a repository", &out, "CVM_REPO");
}
