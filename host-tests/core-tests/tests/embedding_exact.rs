//! The folded fixed-point embedding, bit for bit, against an independent
//! integer model of the arithmetic the scorer documents (module docs of
//! `cvm_core::scorer`, docs/method.md §4):
//!
//! * each axis kernel `K = Σ_b w(b) B_bᵀ B_b` is folded into an even block
//!   `Mₑᵀ K Mₑ` and an odd block `Mₒᵀ K Mₒ`, each factored `RᵀR` (upper
//!   triangular, a pivot at or below `1e-12` of `K`'s largest diagonal
//!   entry gives a zero row) and quantised to `round(R 2^p)` with the
//!   finest `p <= 62` that keeps every entry below `2^31 - 1`;
//! * a detector row is folded along axis 2 (`a[l] ± a[J2-1-l]`, the middle
//!   cell alone), each folded count converted to `Q(f)`: normalised
//!   `y = round((v << k) m / 2^32)` with `S << k` in `[2^30, 2^31)` and
//!   `m = floor(2^(32+f) / (S << k))`, raw `y = v 2^f`;
//! * the row pass and, after folding along axis 1, the column pass sum one
//!   `round(r y / 2^32)` per term (`SMMLAR`: round half up), and the words
//!   are stored `e[k * J1 + i]`, even columns of axis 2 first, each column
//!   even part first;
//! * a distance is `Σ (Ea - Eb)²` in `Q(2e)`, `e = f + p1 + p2 - 64`,
//!   rounded half up to the score format `Q(q)`.
//!
//! For the small maps here every format bound holds with room to spare, so
//! the documented choice is `f = 28` (normalised) or `11` (raw) and the
//! finest `p1`, `p2`. Written with full matrices, `i128` products and
//! Euclidean division; nothing is shared with the core but its public API.

use cvm_core::{Config, Geometry, Kernels, Weights};
use cvm_core_tests::{random_map, rng};
use rand::RngExt;

type M = Vec<Vec<f64>>;

/// `Σ_b w(b) B_bᵀ B_b` on an axis of `j` cells, sizes `1..=n`, every box
/// found by testing each cell's distance to the centre.
fn axis_kernel(j: usize, w: &[f64]) -> M {
    let mut k = vec![vec![0.0; j]; j];
    for (bi, &wb) in w.iter().enumerate() {
        let b = bi + 1;
        for c in 0..j {
            let cells: Vec<usize> = (0..j).filter(|&i| i.abs_diff(c) <= b).collect();
            for &x in &cells {
                for &y in &cells {
                    k[x][y] += wb;
                }
            }
        }
    }
    k
}

/// The fold matrices `Mₑ` (`j x h`) and `Mₒ` (`j x g`): `x = Mₑ u + Mₒ v`.
fn fold_matrices(j: usize) -> (M, M) {
    let (h, g) = (j.div_ceil(2), j / 2);
    let mut me = vec![vec![0.0; h]; j];
    let mut mo = vec![vec![0.0; g]; j];
    for a in 0..g {
        me[a][a] = 0.5;
        me[j - 1 - a][a] = 0.5;
        mo[a][a] = 0.5;
        mo[j - 1 - a][a] = -0.5;
    }
    if j % 2 == 1 {
        me[j / 2][h - 1] = 1.0;
    }
    (me, mo)
}

/// `Mᵀ K M`.
fn congruence(k: &M, m: &M) -> M {
    let (j, c) = (k.len(), m.first().map_or(0, Vec::len));
    let mut out = vec![vec![0.0; c]; c];
    for (a, row) in out.iter_mut().enumerate() {
        for (b, o) in row.iter_mut().enumerate() {
            let mut s = 0.0;
            for x in 0..j {
                for y in 0..j {
                    s += m[x][a] * k[x][y] * m[y][b];
                }
            }
            *o = s;
        }
    }
    out
}

/// Upper-triangular `R` with `RᵀR = A` (`A` semi-definite): the
/// Cholesky–Banachiewicz order on `L = Rᵀ`, zero rows below `tol`.
fn cholesky(a: &M, tol: f64) -> M {
    let n = a.len();
    let mut l = vec![vec![0.0; n]; n];
    for i in 0..n {
        let s = a[i][i] - (0..i).map(|p| l[i][p] * l[i][p]).sum::<f64>();
        if s <= tol {
            continue;
        }
        let d = s.sqrt();
        l[i][i] = d;
        for r in i + 1..n {
            let t = a[r][i] - (0..i).map(|p| l[r][p] * l[i][p]).sum::<f64>();
            l[r][i] = t / d;
        }
    }
    (0..n).map(|i| (0..n).map(|c| l[c][i]).collect()).collect()
}

struct AxisFactor {
    h: usize,
    g: usize,
    even: Vec<Vec<i64>>,
    odd: Vec<Vec<i64>>,
    p: i32,
}

fn axis_factor(j: usize, w: &[f64]) -> AxisFactor {
    let k = axis_kernel(j, w);
    let tol = 1e-12 * (0..j).map(|i| k[i][i]).fold(0.0, f64::max);
    let (me, mo) = fold_matrices(j);
    let (re, ro) = (
        cholesky(&congruence(&k, &me), tol),
        cholesky(&congruence(&k, &mo), tol),
    );
    let max = re
        .iter()
        .chain(&ro)
        .flatten()
        .fold(0.0f64, |m, x| m.max(x.abs()));
    let p = (0..=62)
        .rev()
        .find(|&p| max * 2f64.powi(p) + 0.5 < 2147483647.0)
        .unwrap();
    let q = |r: &M| -> Vec<Vec<i64>> {
        r.iter()
            .map(|row| {
                row.iter()
                    .map(|x| (x * 2f64.powi(p)).round() as i64)
                    .collect()
            })
            .collect()
    };
    AxisFactor {
        h: j.div_ceil(2),
        g: j / 2,
        even: q(&re),
        odd: q(&ro),
        p,
    }
}

/// `round(x / 2^32)`, half up.
fn rnd32(x: i128) -> i128 {
    (x + (1i128 << 31)).div_euclid(1i128 << 32)
}

/// `Σ_{l>=k} round(r[k][l] u[l] / 2^32)` for every `k`.
fn apply(r: &[Vec<i64>], u: &[i128]) -> Vec<i128> {
    (0..u.len())
        .map(|k| (k..u.len()).map(|l| rnd32(r[k][l] as i128 * u[l])).sum())
        .collect()
}

/// Even and odd halves of a vector folded on itself.
fn fold(x: &[i128]) -> (Vec<i128>, Vec<i128>) {
    let j = x.len();
    let (h, g) = (j.div_ceil(2), j / 2);
    let even = (0..h)
        .map(|l| if l < g { x[l] + x[j - 1 - l] } else { x[l] })
        .collect();
    let odd = (0..g).map(|l| x[l] - x[j - 1 - l]).collect();
    (even, odd)
}

struct Model {
    j1: usize,
    j2: usize,
    a1: AxisFactor,
    a2: AxisFactor,
    f: i32,
    normalise: bool,
}

impl Model {
    fn new(j1: usize, j2: usize, w1: &[f64], w2: &[f64], normalise: bool) -> Self {
        Model {
            j1,
            j2,
            a1: axis_factor(j1, w1),
            a2: axis_factor(j2, w2),
            f: if normalise { 28 } else { 11 },
            normalise,
        }
    }

    fn e(&self) -> i32 {
        self.f + self.a1.p + self.a2.p - 64
    }

    /// The conversion of a folded count of a map with sample sum `s`.
    fn converter(&self, s: u64) -> impl Fn(i128) -> i128 {
        let (f, norm) = (self.f, self.normalise);
        let (k, m) = if !norm || s == 0 {
            (0, 0)
        } else {
            let k = (0..32).find(|&k| (s << k) >= 1 << 30).unwrap();
            let m = (1u128 << (32 + f)) / (u128::from(s) << k);
            (k, m as i128)
        };
        move |v: i128| {
            if norm { rnd32((v << k) * m) } else { v << f }
        }
    }

    fn embed(&self, frame: &[u16]) -> Vec<i64> {
        let (j1, j2) = (self.j1, self.j2);
        let conv = self.converter(frame.iter().map(|&a| u64::from(a)).sum());
        // Row pass: columns of T, even columns of axis 2 first.
        let mut t = vec![vec![0i128; j1]; j2];
        for i in 0..j1 {
            let row: Vec<i128> = (0..j2).map(|c| i128::from(frame[i * j2 + c])).collect();
            let (ue, uo) = fold(&row);
            let ye: Vec<i128> = ue.into_iter().map(&conv).collect();
            let yo: Vec<i128> = uo.into_iter().map(&conv).collect();
            for (k, v) in apply(&self.a2.even, &ye).into_iter().enumerate() {
                t[k][i] = v;
            }
            for (k, v) in apply(&self.a2.odd, &yo).into_iter().enumerate() {
                t[self.a2.h + k][i] = v;
            }
        }
        // Column pass.
        let mut e = Vec::with_capacity(j1 * j2);
        for col in &t {
            let (ue, uo) = fold(col);
            e.extend(apply(&self.a1.even, &ue));
            e.extend(apply(&self.a1.odd, &uo));
        }
        assert_eq!(e.len(), j1 * j2);
        assert_eq!((self.a1.h + self.a1.g, self.a2.h + self.a2.g), (j1, j2));
        e.into_iter().map(|v| i64::try_from(v).unwrap()).collect()
    }

    fn score(&self, ea: &[i64], eb: &[i64], q: i32) -> u32 {
        let acc: i128 = ea
            .iter()
            .zip(eb)
            .map(|(x, y)| i128::from(x - y).pow(2))
            .sum();
        let shift = 2 * self.e() - q;
        let v = if shift > 0 {
            (acc + (1i128 << (shift - 1))) >> shift
        } else {
            acc << -shift
        };
        u32::try_from(v).unwrap_or(u32::MAX)
    }
}

fn frames(cells: usize, j2: usize, seed: u64) -> Vec<Vec<u16>> {
    let mut r = rng(seed);
    let mut v = vec![vec![0; cells], vec![u16::MAX; cells], vec![1; cells]];
    for k in 0..cells {
        let mut m = vec![0u16; cells];
        m[k] = r.random_range(1..=u16::MAX);
        v.push(m);
    }
    for _ in 0..24 {
        v.push(random_map(&mut r, cells, j2));
    }
    // Small counts, where the rounding of every term matters most.
    for _ in 0..8 {
        v.push((0..cells).map(|_| r.random_range(0..5)).collect());
    }
    v
}

#[test]
fn embedding_and_distances_are_bit_exact_on_small_maps() {
    let geometries = [
        (1, 1),
        (1, 2),
        (2, 1),
        (1, 3),
        (2, 2),
        (2, 3),
        (3, 2),
        (3, 3),
        (1, 5),
        (3, 4),
        (4, 4),
        (4, 5),
        (5, 5),
    ];
    let mut compared = 0usize;
    for (gi, &(j1, j2)) in geometries.iter().enumerate() {
        for normalise in [true, false] {
            for (weights, bmax) in [
                (Weights::Uniform, 0u8),
                (Weights::Unit, 0),
                (Weights::Uniform, 2),
            ] {
                let cfg = Config {
                    geometry: Geometry::new(j1 as u8, j2 as u8).unwrap(),
                    kernels: Kernels::Paper { bmax },
                    weights,
                    normalise,
                    full_scale: u16::MAX,
                };
                let scorer = dmap::fixed::scorer(&cfg).unwrap();
                let axis_w = |j: usize| -> Vec<f64> {
                    let n = if bmax == 0 {
                        j
                    } else {
                        j.min(usize::from(bmax))
                    };
                    match weights {
                        Weights::Unit => vec![1.0; n],
                        _ => vec![1.0 / n as f64; n],
                    }
                };
                let model = Model::new(j1, j2, &axis_w(j1), &axis_w(j2), normalise);
                let what = format!("{j1}x{j2} {weights:?} bmax={bmax} normalise={normalise}");
                // The states below equal the model's bit for bit, which
                // pins the input format Q(f) as well.
                let maps = frames(j1 * j2, j2, gi as u64);
                let mut embedded = Vec::new();
                for frame in &maps {
                    let mut state = vec![0i32; j1 * j2];
                    scorer.prepare(frame, &mut state).unwrap();
                    let want = model.embed(frame);
                    let got: Vec<i64> = state.iter().map(|&v| i64::from(v)).collect();
                    assert_eq!(got, want, "{what}: frame {frame:?}");
                    embedded.push((state, want));
                }
                for (a, (sa, ea)) in embedded.iter().enumerate() {
                    for (sb, eb) in embedded.iter().skip(a).step_by(3) {
                        let want = model.score(ea, eb, scorer.score_frac_bits());
                        assert_eq!(scorer.distance(sa, sb), want, "{what}");
                        compared += 1;
                    }
                }
            }
        }
    }
    assert!(compared > 5000, "{compared}");
}
