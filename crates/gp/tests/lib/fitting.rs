//! ML-II fitting: noise recovery, GLS trend recovery, determinism, likelihood units.

use crate::strategies::{smooth_data, standard_normal};
use gp::{GpParams, Mean};
use nalgebra::DMatrix;
use rand::{RngExt, SeedableRng, rngs::StdRng};

/// The estimated white-noise variance recovers the true one. With n = 200 residuals the
/// sampling standard deviation of a variance estimate is ≈ sqrt(2/n) = 10 % relative; the
/// GP also spends a few degrees of freedom on the smooth part. 35 % is 3.5 sigma.
#[test]
fn noise_variance_is_recovered() {
    let sigma = 0.1;
    for seed in [1u64, 2] {
        let (x, y) = smooth_data(200, 1, sigma, seed);
        let model = GpParams::new().restarts(2).seed(seed).fit(&x, &y).unwrap();
        let ratio = model.noise_variance() / (sigma * sigma);
        assert!(
            (ratio - 1.0).abs() < 0.35,
            "seed {seed}: noise ratio {ratio}"
        );
    }
}

/// GLS recovers a linear trend (data = trend + white noise). The OLS standard error of a slope
/// here is σ / (sqrt(n) sd(x)) ≈ 0.05 / (sqrt(60) · 2.9) ≈ 0.003 (x uniform on [0, 10]);
/// 0.02 is ~7 standard errors, generous because the GP part can absorb a little curvature.
#[test]
fn gls_recovers_linear_trend() {
    let mut rng = StdRng::seed_from_u64(4);
    let n = 60;
    let x = DMatrix::from_fn(n, 2, |_, _| 10.0 * rng.random::<f64>());
    let (c, b1, b2) = (2.0, 0.5, -1.5);
    let y: Vec<f64> = (0..n)
        .map(|i| c + b1 * x[(i, 0)] + b2 * x[(i, 1)] + 0.05 * standard_normal(&mut rng))
        .collect();
    let model = GpParams::new()
        .mean(Mean::Linear)
        .restarts(2)
        .fit(&x, &y)
        .unwrap();
    let beta = model.trend_coefficients();
    assert_eq!(beta.len(), 3);
    assert!((beta[1] - b1).abs() < 0.02, "slope 1 {}", beta[1]);
    assert!((beta[2] - b2).abs() < 0.02, "slope 2 {}", beta[2]);
    // Intercept error ≈ slope errors × mean x (5) plus its own se: 0.2.
    assert!((beta[0] - c).abs() < 0.2, "intercept {}", beta[0]);
    // Far outside the data the prediction follows the trend (the GP part reverts to 0).
    let far = DMatrix::from_row_slice(1, 2, &[40.0, -30.0]);
    let p = model.predict(&far).unwrap();
    let truth = c + b1 * 40.0 + b2 * -30.0;
    // Slope error 0.02 × 50 units of extrapolation distance = 1.
    assert!((p.mean[0] - truth).abs() < 1.0, "{} vs {truth}", p.mean[0]);
}

/// Same seed, same data → bit-identical model; the optimum beats or ties every start.
#[test]
fn fit_is_deterministic_and_picks_best_start() {
    let (x, y) = smooth_data(25, 2, 0.05, 8);
    let params = GpParams::new().restarts(3).seed(17);
    let (a, b) = (params.fit(&x, &y).unwrap(), params.fit(&x, &y).unwrap());
    assert_eq!(a.hyperparameters(), b.hyperparameters());
    assert_eq!(a.log_marginal_likelihood(), b.log_marginal_likelihood());
    let d = a.diagnostics();
    assert_eq!(d.starts.len(), 4);
    let best = d
        .starts
        .iter()
        .filter_map(|s| s.lml)
        .fold(f64::NEG_INFINITY, f64::max);
    assert_eq!(d.starts[d.best_start].lml, Some(best));
    assert_eq!(a.log_marginal_likelihood_standardized(), best);
}

/// The original-unit LML transforms with the output scale: scaling y by s shifts it by
/// −(n − p) ln s and leaves the standardised value unchanged.
#[test]
fn lml_in_original_units_scales_correctly() {
    let (x, y) = smooth_data(20, 1, 0.05, 12);
    let params = GpParams::new().mean(Mean::Constant);
    let theta = [0.0, 0.0, (1e-2f64).ln()];
    let a = params.fit_with_log_params(&x, &y, &theta).unwrap();
    let y10: Vec<f64> = y.iter().map(|v| 10.0 * v + 3.0).collect();
    let b = params.fit_with_log_params(&x, &y10, &theta).unwrap();
    // Same standardised problem: identical up to round-off in the standardisation.
    assert!(
        (a.log_marginal_likelihood_standardized() - b.log_marginal_likelihood_standardized()).abs()
            < 1e-9
    );
    let expected = a.log_marginal_likelihood() - 19.0 * 10f64.ln();
    assert!((b.log_marginal_likelihood() - expected).abs() < 1e-9);
    assert!((b.noise_variance() / a.noise_variance() - 100.0).abs() < 1e-9);
}
