//! `dmap listen` ended by Ctrl-C (SIGINT) or SIGTERM, as `--port DEV
//! --scans 0` is meant to be: the scans complete by then are reported and
//! written exactly as a stream holding only them would be, the scan under
//! way is reported cut, and the exit status is that of a cut stream (1),
//! or 0 when no scan was under way. The stream comes through a FIFO, a
//! pipe on standard input, or a pseudo-terminal standing in for the
//! serial port; the signal is sent once `dmap` has read every byte
//! written (the pipe's or terminal's queue is empty), so what it decoded
//! is known exactly.

use crate::common;

use common::{dmap_ok, s, spot_scan, tmp_in};
use serde_json::Value;
use std::io::Write;
use std::os::fd::{AsRawFd, RawFd};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

const TAG: &str = "listen-interrupt";

/// Two different scans' streams (with score lines, so that every line
/// type but `D` occurs, and defect lines too).
/// Tests run in parallel: each names its own scan files with `tag`.
fn two_streams(tag: &str) -> (Vec<u8>, Vec<u8>) {
    let mut out = Vec::new();
    for seed in [1, 2] {
        let scan = tmp_in(TAG, &format!("{tag}-scan{seed}.npy"));
        spot_scan(&scan, 8, 30, 5, seed);
        let o = dmap_ok(&[
            "stream",
            s(&scan),
            "--scores",
            "--max-defect-lines",
            "3",
            "--power-threshold",
            "0.003",
        ]);
        out.push(o.stdout);
    }
    (out.remove(0), out.remove(0))
}

/// Bytes waiting in the queue of `fd` (a pipe end or a terminal).
fn queued(fd: RawFd) -> usize {
    let mut n: libc::c_int = 0;
    // SAFETY: FIONREAD writes one int.
    let r = unsafe { libc::ioctl(fd, libc::FIONREAD, &mut n) };
    assert_eq!(r, 0, "FIONREAD: {}", std::io::Error::last_os_error());
    n as usize
}

/// Waits until `dmap` has read everything queued on `fd` (bounded: a
/// `dmap` that reads nothing fails the test rather than hang it).
fn wait_drained(fd: RawFd, child: &mut Child) {
    for _ in 0..60_000 {
        if queued(fd) == 0 {
            return;
        }
        assert!(
            child.try_wait().unwrap().is_none(),
            "dmap ended before reading its input"
        );
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    panic!("dmap did not read its input");
}

/// Bytes `child` has read through `read` calls so far (`rchar`).
fn bytes_read(child: &Child) -> usize {
    let io = std::fs::read_to_string(format!("/proc/{}/io", child.id())).unwrap();
    io.lines()
        .find_map(|l| l.strip_prefix("rchar: "))
        .unwrap()
        .parse()
        .unwrap()
}

/// Waits until `child` has `path` open (bounded).
fn wait_open(child: &mut Child, path: &str) {
    for _ in 0..60_000 {
        let open = std::fs::read_dir(format!("/proc/{}/fd", child.id()))
            .unwrap()
            .filter_map(|e| std::fs::read_link(e.ok()?.path()).ok())
            .any(|l| l.to_string_lossy() == path);
        if open {
            return;
        }
        assert!(child.try_wait().unwrap().is_none(), "dmap ended");
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    panic!("dmap did not open {path}");
}

/// Waits until `child` has read `n` more bytes than `base` (bounded): a
/// terminal's queue is filled asynchronously, so its count cannot tell.
fn wait_read(child: &mut Child, base: usize, n: usize) {
    for _ in 0..60_000 {
        if bytes_read(child) >= base + n {
            return;
        }
        assert!(child.try_wait().unwrap().is_none(), "dmap ended");
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    panic!("dmap did not read its input");
}

fn signal(child: &Child, sig: i32) {
    // SAFETY: a signal to our own child, which has not been reaped.
    assert_eq!(unsafe { libc::kill(child.id() as i32, sig) }, 0);
}

/// `dmap listen` and its JSON document, after it ended.
fn finish(child: Child) -> (Option<i32>, Value, String) {
    let out = child.wait_with_output().unwrap();
    let v: Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "no JSON document ({e}); status {}, stderr: {}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (
        out.status.code(),
        v,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// What `dmap listen --json -o` makes of `bytes` read from a file: the
/// reference for the interrupted runs.
fn reference(name: &str, bytes: &[u8]) -> (Value, Vec<u8>) {
    let input = tmp_in(TAG, &format!("{name}.txt"));
    let img = tmp_in(TAG, &format!("{name}.npy"));
    std::fs::write(&input, bytes).unwrap();
    let out = dmap_ok(&["listen", "--input", s(&input), "--json", "-o", s(&img)]);
    (
        serde_json::from_slice(&out.stdout).unwrap(),
        std::fs::read(&img).unwrap(),
    )
}

fn kinds(v: &Value) -> Vec<String> {
    v["problems"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["kind"].as_str().unwrap().to_string())
        .collect()
}

/// The byte offset of the middle of the second scan's first score line:
/// a cut there leaves a partial line.
fn mid_line(second: &[u8]) -> usize {
    let text = std::str::from_utf8(second).unwrap();
    let at = text.find("\nS,").unwrap() + 1;
    at + 40
}

/// Checks an interrupted run that had decoded `first` whole and part of a
/// second scan: scan 1 as the reference, scan 2 cut, its image not
/// written and a file already there left alone.
fn check_cut(code: Option<i32>, v: &Value, err: &str, first: &[u8], img: &Path, img2: &Path) {
    // Tests run in parallel: the reference's files are named for `img`.
    let name = format!("{}-alone", img.file_stem().unwrap().to_string_lossy());
    let (want, want_img) = reference(&name, first);
    assert_eq!(code, Some(1), "{err}");
    assert_eq!(v["interrupted"], "SIGINT");
    let scans = v["scans"].as_array().unwrap();
    assert_eq!(scans.len(), 2, "{v}");
    assert_eq!(scans[0], want["scans"][0]);
    assert_eq!(scans[1]["totals"], Value::Null);
    assert_eq!(kinds(v), ["cut", "scan-cut"], "{v}");
    let p = &v["problems"].as_array().unwrap()[1];
    assert!(
        p["what"]
            .as_str()
            .unwrap()
            .starts_with("interrupted by SIGINT before the scan's end line"),
        "{p}"
    );
    assert_eq!(std::fs::read(img).unwrap(), want_img);
    assert_eq!(std::fs::read(img2).unwrap(), b"an earlier good image");
    assert!(err.contains("scan 2 has no end line (cut)"), "{err}");
    assert!(err.contains("not written"), "{err}");
}

fn outputs(name: &str) -> (PathBuf, PathBuf) {
    let img = tmp_in(TAG, &format!("{name}.npy"));
    let img2 = tmp_in(TAG, &format!("{name}_2.npy"));
    let _ = std::fs::remove_file(&img);
    std::fs::write(&img2, b"an earlier good image").unwrap();
    (img, img2)
}

/// A FIFO: one complete scan and part of a second, then SIGINT.
#[test]
fn sigint_on_a_fifo_keeps_the_complete_scan_and_reports_the_cut_one() {
    let (first, second) = two_streams("fifo");
    let fifo = tmp_in(TAG, "fifo");
    let _ = std::fs::remove_file(&fifo);
    let c = std::ffi::CString::new(s(&fifo)).unwrap();
    // SAFETY: a NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let (img, img2) = outputs("fifo");
    let mut child = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(["listen", "--input", s(&fifo), "--json", "-o", s(&img)])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Opening blocks until dmap opens its end.
    let mut w = std::fs::OpenOptions::new().write(true).open(&fifo).unwrap();
    w.write_all(&first).unwrap();
    w.write_all(&second[..mid_line(&second)]).unwrap();
    wait_drained(w.as_raw_fd(), &mut child);
    signal(&child, libc::SIGINT);
    let (code, v, err) = finish(child);
    drop(w);
    check_cut(code, &v, &err, &first, &img, &img2);
}

/// Standard input from a pipe (`... | dmap listen --input -`).
#[test]
fn sigint_on_standard_input_keeps_the_complete_scan() {
    let (first, second) = two_streams("stdin");
    let (img, img2) = outputs("stdin");
    let mut child = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(["listen", "--input", "-", "--json", "-o", s(&img)])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut w = child.stdin.take().unwrap();
    w.write_all(&first).unwrap();
    w.write_all(&second[..mid_line(&second)]).unwrap();
    wait_drained(w.as_raw_fd(), &mut child);
    signal(&child, libc::SIGINT);
    let (code, v, err) = finish(child);
    drop(w);
    check_cut(code, &v, &err, &first, &img, &img2);
}

/// A pseudo-terminal in raw mode: its slave's name.
fn pty() -> (std::fs::File, std::fs::File, String) {
    let (mut master, mut slave) = (0, 0);
    // SAFETY: openpty writes two descriptors; no name buffer, no settings.
    let r = unsafe {
        libc::openpty(
            &mut master,
            &mut slave,
            std::ptr::null_mut(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert_eq!(r, 0, "openpty: {}", std::io::Error::last_os_error());
    // Not inherited by dmap (nor by other tests' children): dmap's own
    // opening of the slave is what the test waits for.
    for fd in [master, slave] {
        // SAFETY: fcntl on descriptors just opened.
        assert_eq!(
            unsafe { libc::fcntl(fd, libc::F_SETFD, libc::FD_CLOEXEC) },
            0
        );
    }
    // SAFETY: both descriptors are ours from here on.
    let (master, slave) = unsafe {
        use std::os::fd::FromRawFd;
        (
            std::fs::File::from_raw_fd(master),
            std::fs::File::from_raw_fd(slave),
        )
    };
    // Raw before dmap opens it: nothing written is echoed or edited.
    let mut t: libc::termios = unsafe { std::mem::zeroed() };
    // SAFETY: `t` is a termios record for the slave's settings.
    unsafe {
        assert_eq!(libc::tcgetattr(slave.as_raw_fd(), &mut t), 0);
        libc::cfmakeraw(&mut t);
        assert_eq!(libc::tcsetattr(slave.as_raw_fd(), libc::TCSANOW, &t), 0);
    }
    let name = std::fs::read_link(format!("/proc/self/fd/{}", slave.as_raw_fd()))
        .unwrap()
        .to_string_lossy()
        .into_owned();
    (master, slave, name)
}

/// `--port DEV --scans 0` (a pseudo-terminal as the port): two complete
/// scans, then SIGINT between scans ends the run cleanly (status 0, both
/// images written); with a scan under way, it is reported cut.
#[test]
fn sigint_ends_a_port_run_of_scans_0() {
    let (first, second) = two_streams("port");
    let both = [first.clone(), second.clone()].concat();
    let (want, _) = reference("both", &both);
    for cut in [false, true] {
        let (mut master, slave, port) = pty();
        let (img, img2) = outputs(&format!("port-{cut}"));
        let mut child = Command::new(env!("CARGO_BIN_EXE_dmap"))
            .args(["listen", "--port", &port, "--scans", "0", "--json"])
            .args(["-o", s(&img)])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Nothing but the port is read once it is open.
        wait_open(&mut child, &port);
        let base = bytes_read(&child);
        let sent = if cut {
            [&first[..], &second[..mid_line(&second)]].concat()
        } else {
            both.clone()
        };
        master.write_all(&sent).unwrap();
        wait_read(&mut child, base, sent.len());
        drop(slave);
        signal(&child, libc::SIGINT);
        let (code, v, err) = finish(child);
        if cut {
            check_cut(code, &v, &err, &first, &img, &img2);
        } else {
            assert_eq!(code, Some(0), "{err}");
            assert_eq!(v["interrupted"], "SIGINT");
            assert_eq!(v["damaged"], false);
            assert_eq!(v["scans"], want["scans"]);
            assert_ne!(std::fs::read(&img2).unwrap(), b"an earlier good image");
        }
    }
}

/// SIGTERM (a service stopped) is handled like SIGINT.
#[test]
fn sigterm_between_scans_is_a_clean_end() {
    let (first, _) = two_streams("term");
    let (want, want_img) = reference("term", &first);
    let img = tmp_in(TAG, "term-out.npy");
    let mut child = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(["listen", "--input", "-", "--json", "-o", s(&img)])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut w = child.stdin.take().unwrap();
    w.write_all(&first).unwrap();
    wait_drained(w.as_raw_fd(), &mut child);
    signal(&child, libc::SIGTERM);
    let (code, v, err) = finish(child);
    drop(w);
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(v["interrupted"], "SIGTERM");
    assert_eq!(v["scans"], want["scans"]);
    assert_eq!(std::fs::read(&img).unwrap(), want_img);
}
