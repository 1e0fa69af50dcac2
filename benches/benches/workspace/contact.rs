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
    theta_sweep_benches(&mut group, &model);
    group.finish();
}

/// A calibration's use of the model: one water level, the 241 gaps of a `θ` grid over
/// 60-150 in, cold (the reference) and with anchored warm starts (`AnchorCache`, a fresh cache
/// per sweep so that every anchor's cold solve is counted).
fn theta_sweep_benches(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    model: &mitergate::ContactModel,
) {
    let thetas: Vec<f64> = (0..241).map(|k| 60.0 + 0.375 * k as f64).collect();
    group.sample_size(10);
    group.bench_function("theta_sweep_241_cold", |b| {
        b.iter(|| {
            for &t in &thetas {
                black_box(model.solve(650.0, 100.0, t).unwrap());
            }
        })
    });
    group.bench_function("theta_sweep_241_anchored", |b| {
        b.iter(|| {
            let cache = mitergate::contact::AnchorCache::default();
            for &t in &thetas {
                black_box(cache.solve(model, 650.0, 100.0, t).unwrap());
            }
        })
    });
}
