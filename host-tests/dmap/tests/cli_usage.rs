//! Argument mistakes get the same one-line error as bad data.

use std::process::Command;

fn run(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn usage_errors_are_one_line() {
    for args in [
        &["score"][..],
        &[
            "score",
            "scan.npy",
            "-o",
            "out.npy",
            "--kernels",
            "hexagonal",
        ],
        &["stream", "scan.npy", "--threshold", "many"],
        &["listen"],
        &["listen", "--input", "x", "--port", "/dev/null"],
        &["frobnicate"],
    ] {
        let (code, err) = run(args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.starts_with("dmap: error: "), "{args:?}: {err}");
        assert!(!err.contains("panicked"));
        // One pointer to the help, not clap's and dmap's both.
        assert_eq!(err.matches("help").count(), 1, "{args:?}: {err}");
        assert!(
            err.trim_end().ends_with("(see dmap --help)"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn help_still_works() {
    let out = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .arg("--help")
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("Usage:"));
}
