//! Criterion benchmarks for `mitergate`.
use criterion::Criterion;

/// Registers the `mitergate` benchmarks.
pub fn benches(_c: &mut Criterion) {}
