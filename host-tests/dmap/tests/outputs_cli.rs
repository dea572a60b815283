//! What an output path does with what is already there (issue 37, item 1):
//! a device or FIFO is written in place, never replaced; a symbolic link is
//! followed; a regular file is replaced whole. Device nodes are this
//! test's own, made with `mknod` in its scratch directory.

use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};

use crate::common;
use common::{dmap, ok, s};

fn tmp(name: &str) -> PathBuf {
    common::tmp_in("outputs", name)
}

fn reference(path: &Path, seed: u64) {
    common::spot_scan(path, 6, 7, 5, seed);
}

fn references() -> (PathBuf, PathBuf) {
    let (a, b) = (tmp("r1.npy"), tmp("r2.npy"));
    reference(&a, 1);
    reference(&b, 2);
    (a, b)
}

/// `mknod path c 1 3`: a null device of the test's own.
fn null_device(path: &Path) -> bool {
    let _ = std::fs::remove_file(path);
    let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: a valid NUL-terminated path; mknod touches nothing else.
    let rc = unsafe { libc::mknod(c.as_ptr(), libc::S_IFCHR | 0o666, libc::makedev(1, 3)) };
    rc == 0
}

#[test]
fn an_output_on_a_device_writes_to_it_and_leaves_the_node() {
    let (r1, r2) = references();
    // A directory of its own: the other tests' temporary files are not
    // this one's to find.
    let dev = common::tmp_in("outputs-dev", "null-dev");
    if !null_device(&dev) {
        eprintln!("skipped: mknod needs root");
        return;
    }
    let out = dmap(&["calibrate", s(&r1), s(&r2), "--out", s(&dev)]);
    ok(&out);
    let t = std::fs::symlink_metadata(&dev).unwrap().file_type();
    assert!(t.is_char_device(), "the device node was replaced: {t:?}");
    // No temporary file left beside it.
    let left: Vec<_> = std::fs::read_dir(dev.parent().unwrap())
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with(".part"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    // The same for simulate's two outputs (scan and truth).
    let truth = common::tmp_in("outputs-dev", "null-truth");
    assert!(null_device(&truth));
    let out = dmap(&[
        "simulate",
        "--preset",
        "prototype",
        "--rows",
        "2",
        "--cols",
        "2",
        "--rays",
        "50",
        "--threads",
        "1",
        "--out",
        s(&dev),
        "--truth",
        s(&truth),
    ]);
    ok(&out);
    for p in [&dev, &truth] {
        assert!(
            std::fs::symlink_metadata(p)
                .unwrap()
                .file_type()
                .is_char_device()
        );
    }
}

#[test]
fn an_output_through_a_symlink_replaces_the_file_it_points_to() {
    let (r1, r2) = references();
    let real = tmp("real-cal.json");
    std::fs::write(&real, "old").unwrap();
    let link = tmp("link-cal.json");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink("real-cal.json", &link).unwrap();
    ok(&dmap(&["calibrate", s(&r1), s(&r2), "--out", s(&link)]));
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    let text = std::fs::read_to_string(&real).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["format"], "dmap-calibration");
    // A dangling link names the file to create.
    let made = tmp("made-cal.json");
    let _ = std::fs::remove_file(&made);
    let dangling = tmp("dangling-cal.json");
    let _ = std::fs::remove_file(&dangling);
    std::os::unix::fs::symlink("made-cal.json", &dangling).unwrap();
    ok(&dmap(&["calibrate", s(&r1), s(&r2), "--out", s(&dangling)]));
    assert!(
        std::fs::symlink_metadata(&dangling)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert_eq!(std::fs::read_to_string(&made).unwrap(), text);
}

#[test]
fn an_output_on_a_fifo_is_written_to_its_reader() {
    let (r1, r2) = references();
    let fifo = tmp("cal.fifo");
    let _ = std::fs::remove_file(&fifo);
    let c = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read(&fifo).unwrap())
    };
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(["calibrate", s(&r1), s(&r2), "--out", s(&fifo)])
        .output()
        .unwrap();
    ok(&out);
    let got = reader.join().unwrap();
    let file = tmp("fifo-ref.json");
    ok(&dmap(&["calibrate", s(&r1), s(&r2), "--out", s(&file)]));
    assert_eq!(got, std::fs::read(&file).unwrap());
    assert!(
        std::fs::symlink_metadata(&fifo)
            .unwrap()
            .file_type()
            .is_fifo()
    );
}

#[test]
fn an_output_on_a_directory_is_refused_in_one_line() {
    let (r1, r2) = references();
    let dir = tmp("a-dir");
    std::fs::create_dir_all(&dir).unwrap();
    let out = dmap(&["calibrate", s(&r1), s(&r2), "--out", s(&dir)]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("is a directory"), "{err}");
    assert!(dir.is_dir());
}
