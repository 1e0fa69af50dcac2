//! Criterion benchmarks across the workspace: one target, one module per crate.
//!
//! Run all: `cargo bench -p bamudi-benches`; one group: `cargo bench -p bamudi-benches -- gp/`.
use criterion::{criterion_group, criterion_main};

mod bamudi;
mod gp;
mod mitergate;
mod orthopoly;
mod seqnet;

criterion_group!(
    benches,
    orthopoly::benches,
    gp::benches,
    seqnet::benches,
    mitergate::benches,
    bamudi::benches
);
criterion_main!(benches);
