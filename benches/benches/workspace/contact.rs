//! Criterion benchmarks for the quoin contact model `g_BC(x, θ)` (`mitergate::contact`) on the
//! default gate (12 in mesh, N_u = 509).
use criterion::Criterion;
use mitergate::CondensedGate;
use mitergate::contact::ContactParams;
use mitergate::data::truth::sample_levels;
use std::hint::black_box;

/// The gate the benchmarks run on.
fn bench_gate() -> CondensedGate {
    mitergate::GateModel::build(&mitergate::GateConfig::default())
        .and_then(|m| m.condense(mitergate::DEFAULT_NU))
        .expect("the default gate builds and condenses")
}

/// Registers the contact benchmarks: one-time precomputation, single evaluations at a high
/// and a (slow, many active-set changes) small head, and the mean over 32 random inputs.
pub fn contact_benches(c: &mut Criterion) {
    let gate = bench_gate();
    let mut group = c.benchmark_group("contact");
    group.bench_function("build_default_gate_nu509", |b| {
        b.iter(|| {
            ContactParams::default()
                .build(black_box(gate.clone()))
                .unwrap()
        })
    });
    let model = ContactParams::default().build(gate).unwrap();
    group.bench_function("solve_744_24_theta90", |b| {
        b.iter(|| {
            model
                .solve(black_box(744.0), black_box(24.0), black_box(90.0))
                .unwrap()
        })
    });
    group.bench_function("solve_300_299_theta90", |b| {
        b.iter(|| {
            model
                .solve(black_box(300.0), black_box(299.0), black_box(90.0))
                .unwrap()
        })
    });
    let inputs: Vec<([f64; 2], f64)> = sample_levels(32, 5)
        .into_iter()
        .enumerate()
        .map(|(k, x)| (x, 81.0 + 84.0 * k as f64 / 31.0))
        .collect();
    group.bench_function("solve_32_random_inputs", |b| {
        b.iter(|| {
            for (x, theta) in &inputs {
                black_box(model.solve(x[0], x[1], *theta).unwrap());
            }
        })
    });
    group.finish();
}
