//! The CVM distance as a squared Euclidean distance of per-map embeddings
//! (docs/method.md §4).

use crate::kernels::{CvmConfig, KernelFamily};
use crate::linalg::{axis_gram, cholesky_psd};

#[derive(Clone, Debug)]
enum Factor {
    /// Paper kernels: `K = K1 ⊗ K2`, `K_i = R_i^T R_i`; the embedding of `ã`
    /// is `R1 ã R2^T`.
    Separable { r1: Vec<f64>, r2: Vec<f64> },
    /// Square kernels: `K = sum_k C_k ⊗ C_k` has no Kronecker structure, so
    /// the whole `(J1 J2) x (J1 J2)` matrix is factored, `K = R^T R`, and the
    /// embedding is `R vec(ã)`.
    Full { r: Vec<f64> },
}

/// Factor tables of one CVM configuration, computed once; then each map is
/// embedded once ([`CvmEmbedding::embed`]) and every distance is the squared
/// Euclidean distance of two embeddings ([`CvmEmbedding::distance`]).
#[derive(Clone, Debug)]
pub struct CvmEmbedding {
    config: CvmConfig,
    factor: Factor,
}

impl CvmEmbedding {
    /// Build the factor tables for `config`.
    pub fn new(config: &CvmConfig) -> Self {
        let g = config.geometry();
        let factor = match config.family() {
            KernelFamily::Paper { w1, w2 } => {
                let k1 = axis_gram(g.j1(), w1.iter().enumerate().map(|(i, &w)| (i + 1, w)));
                let k2 = axis_gram(g.j2(), w2.iter().enumerate().map(|(i, &w)| (i + 1, w)));
                Factor::Separable {
                    r1: cholesky_psd(&k1, g.j1()),
                    r2: cholesky_psd(&k2, g.j2()),
                }
            }
            KernelFamily::Square { k_max } => {
                let n = g.cells();
                let mut k = vec![0.0; n * n];
                for s in 0..=*k_max {
                    let c1 = axis_gram(g.j1(), [(s, 1.0)]);
                    let c2 = axis_gram(g.j2(), [(s, 1.0)]);
                    for a1 in 0..g.j1() {
                        for c1i in 0..g.j1() {
                            let x = c1[a1 * g.j1() + c1i];
                            if x == 0.0 {
                                continue;
                            }
                            for a2 in 0..g.j2() {
                                for c2i in 0..g.j2() {
                                    k[g.index(a1, a2) * n + g.index(c1i, c2i)] +=
                                        x * c2[a2 * g.j2() + c2i];
                                }
                            }
                        }
                    }
                }
                Factor::Full {
                    r: cholesky_psd(&k, n),
                }
            }
        };
        Self {
            config: config.clone(),
            factor,
        }
    }

    /// The configuration these tables belong to.
    pub fn config(&self) -> &CvmConfig {
        &self.config
    }

    /// Length of an embedding (`J1 * J2`).
    pub fn dim(&self) -> usize {
        self.config.geometry().cells()
    }

    /// The per-axis Cholesky factors `(R1, R2)` (row-major, upper triangular)
    /// for paper kernels, `None` for square kernels.
    pub fn separable_factors(&self) -> Option<(&[f64], &[f64])> {
        match &self.factor {
            Factor::Separable { r1, r2 } => Some((r1, r2)),
            Factor::Full { .. } => None,
        }
    }

    /// Embed a raw map (normalising it first if the configuration says so).
    ///
    /// # Panics
    /// If the map's length is not `J1 * J2`.
    pub fn embed(&self, raw: &[f64]) -> Vec<f64> {
        let g = self.config.geometry();
        let m = self.config.prepare(raw);
        let (j1, j2) = (g.j1(), g.j2());
        match &self.factor {
            Factor::Separable { r1, r2 } => {
                // T = ã R2^T, then E = R1 T: two passes of J1*J2*J instead of
                // one of (J1*J2)^2.
                let mut t = vec![0.0; j1 * j2];
                for a in 0..j1 {
                    for q in 0..j2 {
                        let mut s = 0.0;
                        for c in q..j2 {
                            s += m[a * j2 + c] * r2[q * j2 + c];
                        }
                        t[a * j2 + q] = s;
                    }
                }
                let mut e = vec![0.0; j1 * j2];
                for p in 0..j1 {
                    for a in p..j1 {
                        let x = r1[p * j1 + a];
                        for q in 0..j2 {
                            e[p * j2 + q] += x * t[a * j2 + q];
                        }
                    }
                }
                e
            }
            Factor::Full { r } => {
                let n = j1 * j2;
                (0..n)
                    .map(|p| (p..n).map(|c| r[p * n + c] * m[c]).sum())
                    .collect()
            }
        }
    }

    /// The CVM distance of the two maps whose embeddings are given.
    pub fn distance(&self, e1: &[f64], e2: &[f64]) -> f64 {
        e1.iter().zip(e2).map(|(x, y)| (x - y) * (x - y)).sum()
    }
}

/// Convenience: build the tables, embed both maps, return their distance.
/// Use [`CvmEmbedding`] directly when there are many maps.
pub fn cvm_embedding(config: &CvmConfig, a1: &[f64], a2: &[f64]) -> f64 {
    let e = CvmEmbedding::new(config);
    e.distance(&e.embed(a1), &e.embed(a2))
}
