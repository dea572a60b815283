//! The paper kernels' fixed-point formats follow from the overflow proof
//! in `cvm-core/src/scorer/formats.rs` ("Why nothing overflows"), restated here
//! from its text and evaluated on factors computed independently of the
//! core: the axis kernels by enumerating boxes (the reference crate's box
//! rule), folded by explicit change-of-basis matrices, factored by the
//! reference crate's Cholesky.
//!
//! Every format is the finest the proof allows (the search order of the
//! proof: `f` first, then `p1`), and every bound at that format equals the
//! proof's value to 1e-12: a term dropped from a bound, or a rounding slack
//! changed, shows here even where it does not change a format.

use cvm_core::{Bounds, Config, Geometry, Kernels, MAX_J, Scorer, Weights};
use cvm_core_tests::rng;
use cvm_reference::{box_range, cholesky_psd};
use rand::RngExt;

const I31: f64 = 2_147_483_647.0;
const LIMIT_E: f64 = 1_073_741_823.0;
/// Rounding error of a sum of at most 8 terms rounded one by one.
const EPS: f64 = 4.0;
/// Entries of the two packed triangular 8x8 blocks of a factor, each
/// rounded by at most 1/2: the integer factor's Frobenius norm is within
/// `sqrt(72) / 2` of the real one times `2^p`.
const FRO_SLACK: f64 = 4.242_640_687_119_285;

/// The largest magnitude and the Frobenius norm of the real Cholesky
/// factors of an axis's folded kernel blocks.
struct Axis {
    max: f64,
    fro: f64,
}

/// `K = Σ_b w_b B_bᵀ B_b` on `j` cells: `K[i][l]` adds `w_b` for every
/// centre whose box of size `b` holds both cells.
fn axis_kernel(j: usize, w: &[f64]) -> Vec<f64> {
    let mut k = vec![0.0; j * j];
    for (b, &wb) in w.iter().enumerate() {
        for centre in 1..=j {
            let (lo, hi) = box_range(centre, b + 1, j);
            let inside = |c: usize| (lo..=hi).contains(&(c + 1));
            for i in 0..j {
                for l in 0..j {
                    if inside(i) && inside(l) {
                        k[i * j + l] += wb;
                    }
                }
            }
        }
    }
    k
}

/// `Mᵀ K M` for the `j x m` matrix `M` (row-major).
fn congruence(k: &[f64], j: usize, m: &[f64], cols: usize) -> Vec<f64> {
    let mut out = vec![0.0; cols * cols];
    for a in 0..cols {
        for b in 0..cols {
            let mut s = 0.0;
            for i in 0..j {
                for l in 0..j {
                    s += m[i * cols + a] * k[i * j + l] * m[l * cols + b];
                }
            }
            out[a * cols + b] = s;
        }
    }
    out
}

fn axis(j: usize, w: &[f64]) -> Axis {
    let k = axis_kernel(j, w);
    let (h, g) = (j.div_ceil(2), j / 2);
    // x = Mₑ u + Mₒ v undoes the fold u[a] = x[a] + x[j-1-a] (the middle
    // cell alone), v[a] = x[a] - x[j-1-a].
    let mut me = vec![0.0; j * h];
    let mut mo = vec![0.0; j * g];
    for a in 0..g {
        me[a * h + a] = 0.5;
        me[(j - 1 - a) * h + a] = 0.5;
        mo[a * g + a] = 0.5;
        mo[(j - 1 - a) * g + a] = -0.5;
    }
    if j % 2 == 1 {
        me[g * h + g] = 1.0;
    }
    let mut entries = cholesky_psd(&congruence(&k, j, &me, h), h);
    entries.extend(cholesky_psd(&congruence(&k, j, &mo, g), g));
    Axis {
        max: entries.iter().fold(0.0, |m, r| r.abs().max(m)),
        fro: entries.iter().map(|r| r * r).sum::<f64>().sqrt(),
    }
}

/// The largest `p <= 62` whose rounded factor entries stay below `2^31 - 1`.
fn precision(a: &Axis) -> u32 {
    (0..=62u32)
        .rev()
        .find(|&p| a.max * 2f64.powi(p as i32) + 0.5 < I31)
        .expect("a factor that fits no format")
}

/// `(f, p1, p2)` and the bounds at them, by the proof.
fn by_the_proof(
    j1: usize,
    j2: usize,
    w1: &[f64],
    w2: &[f64],
    normalise: bool,
) -> (i32, [u32; 2], Bounds) {
    let (a1, a2) = (axis(j1, w1), axis(j2, w2));
    let n = (j1 * j2) as f64;
    let p2 = precision(&a2);
    let r2max = a2.max * 2f64.powi(p2 as i32) + 0.5;
    let r2fro = a2.fro * 2f64.powi(p2 as i32) + FRO_SLACK;
    let finest = if normalise { 28 } else { 11 };
    for f in (0..=finest).rev() {
        let scale = 2f64.powi(f);
        // Σ|y| over one block of a row, over one block of all rows, and
        // ‖F1 y‖_F, each with the conversion's rounding.
        let (yrow, yall, yfro) = if normalise {
            (scale + 8.0, scale + 128.0, 2.0 * scale + 32.0)
        } else {
            let c = 65535.0 * scale;
            (
                j2 as f64 * c + 8.0,
                n * c + 128.0,
                2.0 * n.sqrt() * c + 32.0,
            )
        };
        let row = yrow * r2max / 2f64.powi(32) + EPS;
        let fold = yall * r2max / 2f64.powi(32) + 16.0 * EPS;
        if row >= I31 || fold >= I31 {
            continue;
        }
        for p1 in (0..=precision(&a1)).rev() {
            let r1max = a1.max * 2f64.powi(p1 as i32) + 0.5;
            let r1fro = a1.fro * 2f64.powi(p1 as i32) + FRO_SLACK;
            let column = fold * r1max / 2f64.powi(32) + EPS;
            let embedding = r1fro * r2fro * yfro / 2f64.powi(64)
                + r1fro * (2.0 * n).sqrt() * EPS / 2f64.powi(32)
                + n.sqrt() * EPS;
            if column < I31 && embedding < LIMIT_E {
                let bounds = Bounds {
                    row,
                    fold,
                    column,
                    embedding,
                };
                return (f, [p1, p2], bounds);
            }
        }
    }
    panic!("no format for {j1}x{j2}");
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * a.abs().max(b.abs())
}

fn check(cfg: &Config, w1: &[f64], w2: &[f64]) {
    let scorer = Scorer::new(cfg).unwrap_or_else(|e| panic!("{cfg:?}: {e}"));
    let got = scorer.formats();
    let g = cfg.geometry;
    let (f, p, bounds) = by_the_proof(g.j1.into(), g.j2.into(), w1, w2, cfg.normalise);
    assert_eq!((got.input, got.factors), (f, p), "{cfg:?}");
    assert_eq!(got.embedding, f + p[0] as i32 + p[1] as i32 - 64, "{cfg:?}");
    let b = got
        .bounds
        .unwrap_or_else(|| panic!("no bounds for {cfg:?}"));
    for (name, x, y) in [
        ("row", b.row, bounds.row),
        ("fold", b.fold, bounds.fold),
        ("column", b.column, bounds.column),
        ("embedding", b.embedding, bounds.embedding),
    ] {
        assert!(close(x, y), "{name} bound {x} instead of {y}: {cfg:?}");
    }
    // The scorer converts maps in the format it reports.
    let mut y = vec![0i32; scorer.cells()];
    scorer.normalise(&vec![3; scorer.cells()], &mut y).unwrap();
    let expect = if cfg.normalise {
        (2f64.powi(f) / scorer.cells() as f64).round()
    } else {
        f64::from(3u32 << f)
    };
    assert!(
        (f64::from(y[0]) - expect).abs() <= 1.0,
        "{cfg:?}: y = {}",
        y[0]
    );
}

fn config(j1: u8, j2: u8, bmax: u8, weights: Weights, normalise: bool) -> Config {
    Config {
        geometry: Geometry::new(j1, j2).unwrap(),
        kernels: Kernels::Paper { bmax },
        weights,
        normalise,
        full_scale: u16::MAX,
    }
}

/// Every geometry and size cap, uniform and unit weights, normalised and raw.
#[test]
fn built_in_weights_take_the_finest_formats_the_proof_allows() {
    for normalise in [false, true] {
        for j1 in 1..=MAX_J as u8 {
            for j2 in 1..=MAX_J as u8 {
                for bmax in 0..=8u8 {
                    let n = |j: u8| usize::from(if bmax == 0 { j } else { bmax.min(j) });
                    let (n1, n2) = (n(j1), n(j2));
                    // w(b) = 1 / (n1 n2), split as 1/n1 on axis 1, 1/n2 on axis 2.
                    let cfg = config(j1, j2, bmax, Weights::Uniform, normalise);
                    check(&cfg, &vec![1.0 / n1 as f64; n1], &vec![1.0 / n2 as f64; n2]);
                    let cfg = config(j1, j2, bmax, Weights::Unit, normalise);
                    check(&cfg, &vec![1.0; n1], &vec![1.0; n2]);
                }
            }
        }
    }
}

/// Separable weights move the factors' norms continuously, so the bounds
/// land anywhere against their limits.
#[test]
fn separable_weights_take_the_finest_formats_the_proof_allows() {
    let mut r = rng(18);
    for case in 0..400 {
        let j1 = r.random_range(1..=MAX_J as u8);
        let j2 = r.random_range(1..=MAX_J as u8);
        let mut w1 = [0.0; MAX_J];
        let mut w2 = [0.0; MAX_J];
        for w in w1.iter_mut().chain(w2.iter_mut()) {
            *w = 10f64.powf(r.random_range(-1.0..1.0));
        }
        let cfg = config(j1, j2, 0, Weights::Separable { w1, w2 }, case % 2 == 0);
        check(&cfg, &w1[..j1.into()], &w2[..j2.into()]);
    }
}
