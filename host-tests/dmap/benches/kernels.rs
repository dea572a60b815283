//! Development benchmarks of the scoring kernels at 9x9 and 15x15 (paper
//! kernels, uniform weights), on the maps `dmap bench` uses: the per-map
//! steps of the fixed-point core taken apart (normalise, prepare = normalise
//! plus embedding, one distance), the whole firmware pipeline per map, and
//! the f64 references (embedding, summed-area table, brute force, EMD).
//!
//! Run: `cargo bench -p dmap --bench kernels` (from `host-tests/`); add a
//! filter such as `-- 15x15/fixed` to run a subset.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use cvm_core::scorer::Scratch;
use cvm_reference::{CvmEmbedding, Emd, Ground, SummedAreaTable, cvm_brute, normalise};
use dmap::bench::{Implementation, Kernels, SEED, synthetic_scan};
use dmap::options::ScoringArgs;
use std::hint::black_box;
use std::time::Duration;

fn kernels(c: &mut Criterion) {
    for j in [9usize, 15] {
        let scoring = ScoringArgs::default();
        let config = scoring
            .reference_config(j, j)
            .expect("paper 9x9/15x15 is valid");
        let g = config.geometry();
        let scorer = scoring.scorer(j, j).expect("paper 9x9/15x15 is valid");
        let n = j * j;
        // Two neighbouring beams of the bench scan.
        let scan = synthetic_scan(j, j, 1, 2, SEED);
        let (fa, fb) = (&scan.counts[..n], &scan.counts[n..]);
        let (ra, rb) = (&scan.values[..n], &scan.values[n..]);

        let mut group = c.benchmark_group(format!("{j}x{j}"));
        group.throughput(Throughput::Elements(1));

        let mut x = vec![0i32; n];
        group.bench_function("fixed/normalise", |b| {
            b.iter(|| scorer.normalise(black_box(fa), &mut x))
        });
        let mut scratch = Scratch::new();
        let mut ea = vec![0i32; scorer.state_words()];
        group.bench_function("fixed/prepare", |b| {
            b.iter(|| scorer.prepare_with(black_box(fa), &mut ea, &mut scratch))
        });
        let mut eb = vec![0i32; scorer.state_words()];
        scorer.prepare(fb, &mut eb).expect("frame of J1*J2 samples");
        scorer.prepare(fa, &mut ea).expect("frame of J1*J2 samples");
        group.bench_function("fixed/distance", |b| {
            b.iter(|| scorer.distance(black_box(&ea), black_box(&eb)))
        });

        let embedding = CvmEmbedding::new(&config);
        group.bench_function("f64/embed", |b| b.iter(|| embedding.embed(black_box(ra))));
        let (xa, xb) = (embedding.embed(ra), embedding.embed(rb));
        group.bench_function("f64/embed_distance", |b| {
            b.iter(|| embedding.distance(black_box(&xa), black_box(&xb)))
        });
        group.bench_function("f64/sat_table", |b| {
            b.iter(|| SummedAreaTable::new(g, &normalise(black_box(ra)).map))
        });
        let emd = Emd::new(g, Ground::Euclid);
        let (ma, mb) = (emd.prepare(ra), emd.prepare(rb));
        group.bench_function("emd/distance", |b| {
            b.iter(|| emd.distance(black_box(&ma), black_box(&mb)))
        });
        group.sample_size(10);
        group.measurement_time(Duration::from_secs(3));
        group.bench_function("f64/brute_distance", |b| {
            b.iter(|| cvm_brute(&config, black_box(ra), black_box(rb)))
        });

        // Whole scans: the figure per map is what `dmap bench` reports.
        let all = Kernels::new(&scoring, j, j).expect("paper 9x9/15x15 is valid");
        for (imp, rows, cols) in [
            (Implementation::Fixed, 16, 64),
            (Implementation::EmbedF64, 16, 64),
            (Implementation::Sat, 2, 8),
        ] {
            let scan = synthetic_scan(j, j, rows, cols, SEED);
            group.throughput(Throughput::Elements((rows * cols) as u64));
            group.bench_function(format!("scan/{}", imp.key()), |b| {
                b.iter(|| all.run(imp, black_box(&scan), false).map(black_box))
            });
        }
        group.finish();
    }
}

criterion_group!(benches, kernels);
criterion_main!(benches);
