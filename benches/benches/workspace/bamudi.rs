//! Criterion benchmarks for `bamudi`.
use criterion::Criterion;

/// Registers the `bamudi` benchmarks.
pub fn benches(_c: &mut Criterion) {}
