//! Criterion benchmarks for `bamudi`: the Module-3 likelihood (Eq. 40/51) at one `θ` for
//! `N_e = 500`, `N_o = 7` (`N_s = 3500`), alone and for 30 `θ` at once (the grid's batches), and
//! the one-off Cholesky factorisation of `V`.
use bamudi::internals::{FactoredCovariance, assemble_covariance};
use criterion::Criterion;
use nalgebra::DMatrix;

/// A squared-exponential covariance between `n` points on a line (a stand-in for a GP
/// posterior covariance `C_k`).
fn se_cov(n: usize, ell: f64, var: f64) -> DMatrix<f64> {
    DMatrix::from_fn(n, n, |i, j| {
        let d = (i as f64 - j as f64) / n as f64;
        var * (-0.5 * d * d / (ell * ell)).exp()
    })
}

fn problem() -> (DMatrix<f64>, Vec<DMatrix<f64>>) {
    let (n_e, n_o, k) = (500, 7, 12);
    let b = DMatrix::from_fn(n_o, k, |p, kk| ((p * 7 + kk * 3) % 11) as f64 / 11.0 - 0.5);
    let covs = (0..k)
        .map(|kk| se_cov(n_e, 0.1 + 0.02 * kk as f64, 1.0))
        .collect();
    (b, covs)
}

/// Registers the `bamudi` benchmarks.
pub fn benches(c: &mut Criterion) {
    let (b, covs) = problem();
    let mut g = c.benchmark_group("bamudi");
    g.sample_size(10);
    g.bench_function("assemble_V_3500", |bench| {
        bench.iter(|| assemble_covariance(&b, &covs, 1.0).unwrap())
    });
    let v = assemble_covariance(&b, &covs, 1.0).unwrap();
    g.bench_function("cholesky_V_3500", |bench| {
        bench.iter(|| FactoredCovariance::new(&v, "V").unwrap())
    });
    let f = FactoredCovariance::new(&v, "V").unwrap();
    let r: Vec<f64> = (0..3500)
        .map(|i| ((i * 37) % 101) as f64 / 101.0 - 0.5)
        .collect();
    g.bench_function("loglik_one_theta_3500", |bench| {
        bench.iter(|| f.log_density(&r).unwrap())
    });
    // 30 θ nodes evaluated as one batch: a zoom pass for one posterior on the gate's 241-node
    // grid (a pass holds 30 or 60 nodes; the coarse pass 60)
    let batch = DMatrix::from_fn(3500, 30, |i, j| r[(i + 17 * j) % 3500]);
    g.bench_function("loglik_30_theta_batched_3500", |bench| {
        bench.iter(|| f.log_densities(&batch).unwrap())
    });
    g.finish();
}
