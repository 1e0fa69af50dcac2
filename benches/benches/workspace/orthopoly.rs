//! Criterion benchmarks for `orthopoly`.
//!
//! Run: `cargo bench -p bamudi-benches -- orthopoly`. The matrix case matches the paper's
//! quoin discretisation (509 points on [0, 762] in, 6 Legendre terms, Eq. 15/49); numpy's time
//! for the same matrix comes from `python3 scripts/orthopoly_fixture.py --time`.
use std::hint::black_box;

use criterion::Criterion;
use orthopoly::{Basis, Family, gauss_hermite_prob, gauss_legendre};

/// Registers the `orthopoly` benchmarks.
pub fn benches(c: &mut Criterion) {
    let quoin: Vec<f64> = (0..509).map(|i| 762.0 * i as f64 / 508.0).collect();
    let basis = Basis::new(Family::Legendre, 0.0, 762.0, 6).unwrap();
    let mut group = c.benchmark_group("orthopoly");
    group.bench_function("basis_matrix_legendre_509x6", |b| {
        b.iter(|| basis.matrix(black_box(&quoin)).unwrap())
    });
    let field = basis
        .reconstruct(&[120.0, -35.0, 8.0, 2.5, -1.0, 0.25], &quoin)
        .unwrap();
    group.bench_function("project_legendre_509x6", |b| {
        b.iter(|| basis.project(black_box(&quoin), black_box(&field)).unwrap())
    });
    group.bench_function("gauss_legendre_64", |b| {
        b.iter(|| gauss_legendre(black_box(64), 0.0, 762.0).unwrap())
    });
    group.bench_function("gauss_hermite_prob_64", |b| {
        b.iter(|| gauss_hermite_prob(black_box(64)).unwrap())
    });
    group.finish();
}
