//! Criterion benchmarks for `seqnet`.
use criterion::Criterion;

/// Registers the `seqnet` benchmarks.
pub fn benches(_c: &mut Criterion) {}
