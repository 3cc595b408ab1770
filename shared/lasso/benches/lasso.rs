//! Time of one homotopy solve on matcher-shaped problems (4 rows) of growing width.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use linetrack_lasso::Homotopy;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

fn matcher_like(n: usize) -> Vec<[f64; 4]> {
    let mut rng = ChaCha8Rng::seed_from_u64(n as u64);
    (0..n)
        .map(|_| {
            [
                rng.random_range(0.0..1.57),
                rng.random_range(0.0..1.57),
                rng.random_range(0.0..1.0),
                rng.random_range(1.0..5.0),
            ]
        })
        .collect()
}

fn bench_solve(c: &mut Criterion) {
    let b = [0.0, 0.0, 1.0, 1.0];
    let mut group = c.benchmark_group("homotopy_solve");
    for n in [8usize, 100, 1000] {
        let columns = matcher_like(n);
        let mut solver = Homotopy::<4>::new();
        let mut w = vec![0.0; n];
        group.bench_with_input(
            BenchmarkId::from_parameter(n),
            &columns,
            |bench, columns| bench.iter(|| solver.solve(black_box(columns), &b, 0.1, &mut w)),
        );
    }
    group.finish();
}

criterion_group!(benches, bench_solve);
criterion_main!(benches);
