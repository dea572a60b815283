//! The square kernels' embedding: `N` words per map, like the paper
//! kernels', from the Cholesky factors of the folded quadratic form.
//!
//! With square kernels (`b = (k, k)`, `k = 0..=K`, unit weights) the
//! distance is `d = Δᵀ M Δ` with `M = Σ_k A_k ⊗ A'_k`, `A_k = B_kᵀ B_k` and
//! `B_k` the 0/1 matrix of the boxes of half-width `k` clipped at the
//! border (`A_k[r][s]` counts the boxes that hold both cells). `M` is a sum
//! of Kronecker products, not one, so it has no separable factor like the
//! paper kernels'; but every `A_k` is centrosymmetric, so folding both
//! axes (`u = x[l] + x[J-1-l]`, `v = x[l] - x[J-1-l]`, the middle cell in
//! `u`, exactly as for the paper kernels) splits `M` into four blocks that
//! do not interact: even or odd along axis 1 times even or odd along axis
//! 2, of at most `8 x 8 = 64` cells. Each block `G` is positive definite
//! (the `k = 0` term is the identity), and its upper-triangular Cholesky
//! factor `R` (`Rᵀ R = G`) embeds the block's folded values `z` as `R z`.
//! The squared Euclidean distance of two embeddings is the CVM distance.
//!
//! The factors depend on the geometry and `K` only. They are computed in
//! f64 when the configuration is attached to a table
//! ([`Scorer::with_factors`](crate::scorer::Scorer::with_factors), at
//! start-up: up to 8 704 words, too many for the `Scorer` that every
//! firmware builds as a constant), and stored two rows at a time in groups
//! of three columns, so that the per-map loop reads three inputs and the
//! six coefficients of both rows that use them with two `LDM`s
//! (`padded_words`).
//!
//! # Formats and why nothing overflows
//!
//! `z` is in `Q(f)`, the factor in `Q(p)`, the embedding `E = R z` in
//! `Q(f + p - 32)`: one `round(r z / 2^32)` per term (`SMMLAR`). Every
//! sample lies in one folded count `v` of each block, so over a block
//! `Σ|v| <= S` (the map's sum), and `z` is `v` converted as the paper
//! kernels convert (`round((v << k) m / 2^32)`, within 1 of `v 2^f / S`;
//! raw: `v 2^f`, exact). Hence `Σ|z| <= X < 2^31` over a block, with
//! `X = 2^f + N` normalised (`f = 28`) and `X = N 65535 2^f` raw. `|R_ij| <= sqrt(G_jj)`, and `p` is the
//! finest with `sqrt(max G_jj) 2^p + 1/2 < 2^31 - 1`, so every partial sum
//! of a row is below `2^31 X / 2^32 + 32 < 2^30 + 32`. The embedding's
//! norm is at most `X sqrt(max M_ii) 2^(p-32)` (`|M_ij| <= sqrt(M_ii M_jj)`
//! for a positive definite `M`) plus the rounding, `√N (32 + X / 2^33)`,
//! and `f` and `p` are the finest for which that stays below `2^30`: every
//! word and every difference of two words fits `i32`, and a squared
//! distance (below `2^62`) fits the `i64` accumulator.
//!
//! # Accuracy
//!
//! Each word is within `s/2 + X / 2^33` units of the exact `R z 2^(p-32)`
//! (`s <= 64` rounded terms, and each coefficient rounded to `Q(p)`), and
//! the f64 Cholesky factor is exact to about `1e-14` of `G`. Against the
//! f64 brute force of Eq. 8 the distances meet the bound the paper kernels
//! meet (core-tests, `fixed_vs_f64`).
//!
//! `blocks` holds the geometry of the blocks and of the factor table,
//! `factors` the formats and the table's construction, `fold` and `embed`
//! the per-map passes, and `kernel` their inner loops, in Cortex-M
//! assembly (`kernel/arm.rs`) or in Rust (`kernel/portable.rs`).

mod blocks;
mod embed;
mod factors;
mod fold;
mod kernel;

pub use blocks::{Blocks, FOLD_WORDS};
pub use embed::embed;
pub use factors::{build, formats};
pub use fold::fold;
