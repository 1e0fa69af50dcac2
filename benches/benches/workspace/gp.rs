//! Criterion benchmarks for `gp`: the issue-2 anchor workload against scikit-learn.
//!
//! Data: the seed-0 anchor set of `/work/shared/anchors/gp_anchor.py` (500 points, 2-D inputs
//! in inches), written to `crates/gp/tests/data/anchor_n500.csv` by
//! `scripts/gp_vs_sklearn.py`. Model: SE-ARD + white noise, zero mean on standardised outputs
//! (= scikit-learn's `normalize_y=True`), default start + 5 random restarts.
use criterion::Criterion;
use gp::{GpParams, Kernel, Mean};
use nalgebra::DMatrix;
use std::hint::black_box;

/// Reads the anchor CSV (header `x0,x1,y`).
fn anchor_data() -> (DMatrix<f64>, Vec<f64>) {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../crates/gp/tests/data/anchor_n500.csv"
    );
    let text = std::fs::read_to_string(path).expect("anchor CSV (run scripts/gp_vs_sklearn.py)");
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().expect("number")).collect())
        .collect();
    let x = DMatrix::from_fn(rows.len(), 2, |i, j| rows[i][j]);
    let y = rows.iter().map(|r| r[2]).collect();
    (x, y)
}

/// The 50 x 50 prediction grid of the anchor (2,500 points).
fn grid() -> DMatrix<f64> {
    let g: Vec<f64> = (0..50).map(|i| 24.0 + 720.0 * i as f64 / 49.0).collect();
    DMatrix::from_fn(2500, 2, |r, c| if c == 0 { g[r % 50] } else { g[r / 50] })
}

fn params() -> GpParams {
    GpParams::new()
        .kernel(Kernel::SquaredExponential { ard: true })
        .mean(Mean::Zero)
        .restarts(5)
        .seed(0)
}

/// Registers the `gp` benchmarks.
pub fn benches(c: &mut Criterion) {
    let (x, y) = anchor_data();
    let model = params().fit(&x, &y).expect("anchor fit");
    eprintln!(
        "gp anchor fit: lml_standardised={:.4} lml_original={:.4} hyper={:?}",
        model.log_marginal_likelihood_standardized(),
        model.log_marginal_likelihood(),
        model.hyperparameters()
    );
    let mut group = c.benchmark_group("gp");
    group.sample_size(10);
    group.bench_function("fit_n500_d2_5restarts", |b| {
        b.iter(|| params().fit(black_box(&x), black_box(&y)).unwrap())
    });
    let xs = grid();
    group.bench_function("predict_mean_var_2500", |b| {
        b.iter(|| model.predict(black_box(&xs)).unwrap())
    });
    contracted_covariance(&mut group, &model, &x);
    group.finish();
}

/// `Σ(x*, X) w` at one new input against the 500 training inputs, as the conditional mode's
/// Module 4 needs it per predicted input: the dense route (`posterior_cov` times `w`) against
/// the contraction reduced once (`covariance_contraction`, whose one-off cost is benchmarked
/// too).
fn contracted_covariance(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    model: &gp::GpModel,
    x: &DMatrix<f64>,
) {
    let w: Vec<f64> = (0..x.nrows()).map(|i| (i as f64 * 0.37).sin()).collect();
    let wv = nalgebra::DVector::from_column_slice(&w);
    let one = DMatrix::from_row_slice(1, 2, &[300.0, 410.0]);
    group.bench_function("cov_times_w_500_dense_one_input", |b| {
        b.iter(|| model.posterior_cov(black_box(&one), x).unwrap() * &wv)
    });
    group.bench_function("cov_times_w_500_reduce", |b| {
        b.iter(|| model.covariance_contraction(black_box(x), &w).unwrap())
    });
    let reduced = model.covariance_contraction(x, &w).expect("contraction");
    group.bench_function("cov_times_w_500_contracted_one_input", |b| {
        b.iter(|| reduced.apply(model, black_box(&one)).unwrap())
    });
}
