//! Criterion benchmarks for `mitergate`: build (mesh + assemble + factor) and condense.
//!
//! `cargo bench -p bamudi-benches -- mitergate/`
use criterion::Criterion;
use mitergate::{GateConfig, GateModel};

fn config(element_size: f64) -> GateConfig {
    let mut cfg = GateConfig::default();
    cfg.mesh.element_size = element_size;
    cfg
}

/// Registers the `mitergate` benchmarks.
pub fn benches(c: &mut Criterion) {
    let mut g = c.benchmark_group("mitergate");
    g.sample_size(10);
    // 24 in: ~30k DOFs; 12 in: the default gate, ~83k DOFs
    for size in [24.0, 12.0] {
        let cfg = config(size);
        g.bench_function(format!("build_{size}in"), |b| {
            b.iter(|| GateModel::build(&cfg).unwrap())
        });
        let model = GateModel::build(&cfg).unwrap();
        g.bench_function(format!("condense_509_{size}in"), |b| {
            b.iter(|| model.condense(mitergate::DEFAULT_NU).unwrap())
        });
    }
    let model = GateModel::build(&config(12.0)).unwrap();
    let f = model.water_load(744.0, 24.0).unwrap();
    g.bench_function("solve_12in", |b| b.iter(|| model.solve(&f).unwrap()));
    g.finish();
}
