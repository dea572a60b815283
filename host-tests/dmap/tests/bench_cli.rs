//! `dmap bench`: the JSON contract, bad input, and that the implementations
//! it times agree with each other on the maps it times. No timing is
//! asserted: the figures belong to the benchmark, not to tests.

use dmap::bench::{Implementation, Kernels, SEED, agreement, synthetic_scan};
use dmap::options::{KernelArg, ScoringArgs, WeightArg};
use std::process::Command;

fn dmap(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(args)
        .output()
        .expect("run dmap")
}

#[test]
fn json_has_every_implementation_with_a_positive_rate() {
    let out = dmap(&["bench", "--json", "--seconds", "0.3"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).expect("utf-8");
    // Exactly one JSON value on stdout.
    let v: serde_json::Value = serde_json::from_str(text.trim()).expect("one JSON object");
    assert_eq!(v["geometry"], "15x15");
    let rates = v["maps_per_s"].as_object().expect("maps_per_s object");
    for key in ["brute", "sat", "embed_f64", "fixed", "emd"] {
        let r = rates[key].as_f64().unwrap_or(f64::NAN);
        assert!(r.is_finite() && r > 0.0, "{key}: {r}");
    }
    // The brute force does per distance what the others do once per map.
    assert!(rates["brute"].as_f64() < rates["embed_f64"].as_f64());
    for (key, dev) in v["agreement"].as_object().expect("agreement object") {
        let (d, tol) = (dev["max_abs_diff"].as_f64(), dev["allowed"].as_f64());
        assert!(d <= tol, "{key}: {d:?} > {tol:?}");
    }
    assert!(v["targets"].is_object(), "15x15 paper: targets apply");
}

#[test]
fn text_mode_names_the_targets_and_other_geometries_say_they_do_not_apply() {
    let out = dmap(&["bench", "--geometry", "5x7", "--seconds", "0.2"]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).expect("utf-8");
    assert!(text.starts_with("5x7 maps, one thread"), "{text}");
    assert!(text.contains("fixed / sat:"), "{text}");
    assert!(text.contains("apply to 15x15"), "{text}");
    assert!(!text.contains("PASS") && !text.contains("FAIL"), "{text}");
}

#[test]
fn bad_input_is_one_line_and_a_failure() {
    for args in [
        &["bench", "--seconds", "0"][..],
        &["bench", "--seconds", "nan"],
        &[
            "bench",
            "--geometry",
            "4x4",
            "--kernels",
            "square",
            "--bmax",
            "9",
        ],
    ] {
        let out = dmap(args);
        assert!(!out.status.success(), "{args:?} succeeded");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
        assert!(out.stdout.is_empty(), "{args:?}");
    }
    // A geometry clap refuses: a usage error naming the option.
    for geometry in ["17x3", "15", "0x4", "ax9", "4x0", "3x17"] {
        let out = dmap(&["bench", "--geometry", geometry]);
        assert_eq!(out.status.code(), Some(2), "{geometry}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{geometry}: {err}");
        assert!(
            err.contains(&format!(
                "invalid value '{geometry}' for '--geometry <J1xJ2>': \
                 expected J1xJ2 with each axis in 1..=16"
            )),
            "{geometry}: {err}"
        );
        assert!(out.stdout.is_empty(), "{geometry}");
    }
}

/// The sample every timed scan starts with: the f64 implementations agree
/// to 1e-9 of the largest magnitude, the fixed point within its stated
/// accuracy, the EMD simplex with the independent min-cost-flow solver.
#[test]
fn timed_implementations_agree_on_the_bench_maps() {
    let variants = [
        (9, 9, ScoringArgs::default()),
        (15, 15, ScoringArgs::default()),
        (
            5,
            7,
            ScoringArgs {
                weights: Some(WeightArg::Unit),
                ..ScoringArgs::default()
            },
        ),
        (
            6,
            6,
            ScoringArgs {
                kernels: KernelArg::Square,
                ..ScoringArgs::default()
            },
        ),
    ];
    for (j1, j2, scoring) in variants {
        let kernels = Kernels::new(&scoring, j1, j2).expect("valid configuration");
        let scan = synthetic_scan(j1, j2, 3, 4, SEED);
        let a = agreement(&kernels, &scan).expect("implementations run");
        assert!(a.max_magnitude > 0.0);
        let checked: Vec<_> = a.deviations.iter().map(|(imp, _, _)| *imp).collect();
        for imp in [
            Implementation::Brute,
            Implementation::Sat,
            Implementation::Fixed,
            Implementation::FixedBatch,
            Implementation::Emd,
        ] {
            assert!(checked.contains(&imp), "{imp:?} not checked");
        }
        for (imp, d, tol) in &a.deviations {
            assert!(
                d <= tol,
                "{j1}x{j2} {scoring:?}: {imp:?} off by {d:e} (allowed {tol:e})"
            );
        }
        // The tolerance of the fixed point is far below the signal.
        let (_, _, tol) = a
            .deviations
            .iter()
            .find(|(i, _, _)| *i == Implementation::Fixed)
            .unwrap();
        assert!(*tol < 1e-3 * a.max_magnitude);
    }
}

#[test]
fn the_scan_is_a_deterministic_moving_spot() {
    let a = synthetic_scan(9, 9, 4, 6, SEED);
    let b = synthetic_scan(9, 9, 2, 3, SEED);
    // A smaller scan is the top-left block of a larger one.
    for r in 0..2 {
        for c in 0..3 {
            let n = 81;
            assert_eq!(
                &a.counts[(r * 6 + c) * n..(r * 6 + c + 1) * n],
                &b.counts[(r * 3 + c) * n..(r * 3 + c + 1) * n]
            );
        }
    }
    // Neighbouring maps differ (the spot moves), none is dark.
    let n = 81;
    assert!((0..a.maps()).all(|i| a.counts[i * n..(i + 1) * n].iter().any(|&x| x > 1000)));
    assert_ne!(&a.counts[..n], &a.counts[n..2 * n]);
}
