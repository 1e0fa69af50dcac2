//! Criterion benchmarks across the workspace: one target, one module per crate.
//!
//! Run all: `cargo bench -p bamudi-benches`; one group: `cargo bench -p bamudi-benches -- gp/`.
// `criterion_group!` generates an undocumented public function.
#![allow(missing_docs)]

use criterion::{criterion_group, criterion_main};

mod bamudi;
mod contact;
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
    contact::contact_benches,
    bamudi::benches
);
criterion_main!(benches);
