//! `dmap score --distance cvm-fixed` (the firmware's arithmetic) against the
//! brute-force f64 gradient of Eq. 1 with Eq. 5, 6, 8, 9, within the bound
//! stated in the README ("Fixed point"), on random scans with dark maps and
//! 2-cell axes.

use cvm_reference::{BruteCvm, Geometry, gradient_image};
use dmap::options::{KernelArg, ScoringArgs, WeightArg};
use rand::rngs::ChaCha8Rng;
use rand::{Rng, RngExt, SeedableRng};
use std::process::Command;

fn scan(r: &mut impl Rng, rows: usize, cols: usize, n: usize) -> Vec<u16> {
    let mut prev: Vec<u16> = (0..n).map(|_| r.random_range(0..3000)).collect();
    let mut out = Vec::new();
    for _ in 0..rows * cols {
        let m: Vec<u16> = match r.random_range(0..10) {
            0 => vec![0; n],
            1 => (0..n).map(|_| r.random()).collect(),
            _ => prev
                .iter()
                .map(|&v| (v as f64 * r.random_range(0.7..1.3)) as u16)
                .collect(),
        };
        out.extend_from_slice(&m);
        prev = m;
    }
    out
}

#[test]
fn cvm_fixed_matches_the_brute_force_gradient() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("fixed_cli");
    std::fs::create_dir_all(&dir).unwrap();
    let mut r = ChaCha8Rng::seed_from_u64(21);
    for &(rows, cols, j1, j2) in &[(5, 6, 2, 2), (4, 7, 2, 9), (6, 5, 9, 9), (4, 4, 15, 15)] {
        for (flags, args) in [
            (vec![], ScoringArgs::default()),
            (
                vec!["--weights", "unit"],
                ScoringArgs {
                    weights: Some(WeightArg::Unit),
                    ..Default::default()
                },
            ),
            (
                vec!["--kernels", "square"],
                ScoringArgs {
                    kernels: KernelArg::Square,
                    ..Default::default()
                },
            ),
            (
                vec!["--raw"],
                ScoringArgs {
                    raw: true,
                    ..Default::default()
                },
            ),
        ] {
            let g = Geometry::new(j1, j2).unwrap();
            let data = scan(&mut r, rows, cols, j1 * j2);
            let path = dir.join(format!("scan_{j1}x{j2}.npy"));
            dmap::npy::write_scan_u16(&path, rows, cols, g, &data).unwrap();
            let out = dir.join(format!("fixed_{j1}x{j2}.npy"));
            let st = Command::new(env!("CARGO_BIN_EXE_dmap"))
                .args(["score", "--distance", "cvm-fixed"])
                .args(&flags)
                .arg(&path)
                .arg("-o")
                .arg(&out)
                .output()
                .unwrap();
            assert!(
                st.status.success(),
                "{}",
                String::from_utf8_lossy(&st.stderr)
            );
            let fixed = dmap::npy::read_gradient(&out).unwrap().data;

            let cfg = args.reference_config(j1, j2).unwrap();
            let raw: Vec<f64> = data.iter().map(|&v| v as f64).collect();
            let exact = gradient_image(&raw, rows, cols, g, &BruteCvm(cfg));
            let step = args.scorer(j1, j2).unwrap().score_to_units(1);
            let max = exact.iter().cloned().fold(0.0, f64::max);
            for (i, (&e, &f)) in exact.iter().zip(&fixed).enumerate() {
                let err = (e - f).abs();
                // The magnitude is floor(sqrt) of integer scores: one more step.
                let slack = if i % 3 == 2 { 2.0 * step } else { step };
                assert!(
                    err <= 1e-5 * max + slack,
                    "{j1}x{j2} {flags:?} at {i}: exact {e} fixed {f}"
                );
                if !args.raw && e >= 1e-3 * max {
                    assert!(
                        err <= 1e-4 * e + slack,
                        "{j1}x{j2} {flags:?} at {i}: exact {e} fixed {f}"
                    );
                }
            }
        }
    }
}
