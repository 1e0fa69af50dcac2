//! Criterion benchmarks for `gp`.
use criterion::Criterion;

/// Registers the `gp` benchmarks.
pub fn benches(_c: &mut Criterion) {}
