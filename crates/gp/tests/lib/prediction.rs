//! Prediction properties: non-negative variance, permutation invariance, interpolation,
//! posterior covariance consistency, the Eq. (A4) term, serde round trip.

use crate::strategies::{kernel, mean, smooth_data};
use gp::{GpParams, Kernel, Mean};
use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;

/// A grid of test points spanning and exceeding the training box [0, 10]^d.
fn test_points(d: usize, m: usize) -> DMatrix<f64> {
    DMatrix::from_fn(m, d, |i, j| {
        -3.0 + 16.0 * ((i * (j + 3) + j) % m) as f64 / m as f64
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, .. ProptestConfig::default() })]

    /// Latent variance is never negative and posterior_cov's diagonal equals it.
    #[test]
    fn variance_nonnegative_and_matches_cov_diagonal(
        k in kernel(), m in mean(), d in 1usize..=2, n in 10usize..=25, seed in 0u64..500,
    ) {
        let (x, y) = smooth_data(n, d, 0.05, seed);
        let model = GpParams::new().kernel(k).mean(m).restarts(1).seed(seed).fit(&x, &y).unwrap();
        let xs = test_points(d, 30);
        let pred = model.predict(&xs).unwrap();
        let cov = model.posterior_cov(&xs, &xs).unwrap();
        let scale = model.hyperparameters().signal_variance + 1.0;
        for i in 0..xs.nrows() {
            prop_assert!(pred.variance[i] >= 0.0);
            // Same formula evaluated by two code paths (column norms vs matmul): agreement
            // to 1e-9 of the prior variance scale is round-off level.
            prop_assert!((cov[(i, i)] - pred.variance[i]).abs() <= 1e-9 * scale,
                "{} vs {}", cov[(i, i)], pred.variance[i]);
            // Symmetry of the joint covariance.
            for j in 0..i {
                prop_assert!((cov[(i, j)] - cov[(j, i)]).abs() <= 1e-9 * scale);
            }
        }
    }

    /// Conditioning on a permuted training set gives the same predictions.
    #[test]
    fn predictions_invariant_to_permutation(
        k in kernel(), m in mean(), seed in 0u64..500, shift in 1usize..10,
    ) {
        let (x, y) = smooth_data(15, 2, 0.05, seed);
        let perm: Vec<usize> = (0..15).map(|i| (i * 4 + shift) % 15).collect(); // 4 is coprime to 15
        let xp = DMatrix::from_fn(15, 2, |i, j| x[(perm[i], j)]);
        let yp: Vec<f64> = perm.iter().map(|&i| y[i]).collect();
        let params = GpParams::new().kernel(k).mean(m);
        let theta = vec![0.1; 1 + k.n_length_scales(2) + 1];
        let a = params.fit_with_log_params(&x, &y, &theta).unwrap();
        let b = params.fit_with_log_params(&xp, &yp, &theta).unwrap();
        let xs = test_points(2, 20);
        let (pa, pb) = (a.predict(&xs).unwrap(), b.predict(&xs).unwrap());
        // Only the summation order differs: 1e-9 is far above round-off, far below any real change.
        prop_assert!((pa.mean - pb.mean).amax() < 1e-9);
        prop_assert!((pa.variance - pb.variance).amax() < 1e-9);
        prop_assert!((a.log_marginal_likelihood() - b.log_marginal_likelihood()).abs() < 1e-9);
    }
}

/// With full ML-II optimisation the optimum, and hence the predictions, are also permutation
/// invariant (up to optimiser tolerance).
#[test]
fn fitted_predictions_invariant_to_permutation() {
    let (x, y) = smooth_data(30, 2, 0.05, 3);
    let perm: Vec<usize> = (0..30).rev().collect();
    let xp = DMatrix::from_fn(30, 2, |i, j| x[(perm[i], j)]);
    let yp: Vec<f64> = perm.iter().map(|&i| y[i]).collect();
    let params = GpParams::new().restarts(2).seed(1);
    let (a, b) = (params.fit(&x, &y).unwrap(), params.fit(&xp, &yp).unwrap());
    let xs = test_points(2, 25);
    let (pa, pb) = (a.predict(&xs).unwrap(), b.predict(&xs).unwrap());
    // Output scale is O(1); the optimiser stops when the LML changes by < 1e-10 n, so the optimum
    // is located to ~1e-4 in log parameters, which moves predictions by well under 1e-3.
    assert!((pa.mean - pb.mean).amax() < 1e-3);
    assert!((pa.variance - pb.variance).amax() < 1e-3);
}

/// With a tiny fixed nugget the posterior mean reproduces the training outputs and the latent
/// variance there is ~0.
#[test]
fn near_interpolation_with_tiny_noise() {
    for k in [
        Kernel::SquaredExponential { ard: true },
        Kernel::Matern52 { ard: false },
    ] {
        let (x, y) = smooth_data(20, 2, 0.0, 11);
        let model = GpParams::new()
            .kernel(k)
            .estimate_noise(false)
            .nugget(1e-10)
            .restarts(1)
            .fit(&x, &y)
            .unwrap();
        let pred = model.predict(&x).unwrap();
        let err = (pred.mean - DVector::from_column_slice(&y)).amax();
        // Nugget 1e-10 (plus any logged jitter ≤ 1e-4 of the variance) of a unit-variance output:
        // residuals scale like sqrt(nugget+jitter) at worst, 1e-3 leaves margin.
        assert!(
            err < 1e-3,
            "{k:?}: max interpolation error {err} (jitter {})",
            model.diagnostics().jitter
        );
        assert!(
            pred.variance.amax() < 1e-3,
            "{k:?}: variance at data {}",
            pred.variance.amax()
        );
    }
}

/// The GLS term of Eq. (A4) only adds variance: the model's latent variance is at least the
/// simple-kriging variance `k(x,x) − kᵀK⁻¹k` built independently from the reported
/// hyper-parameters, and strictly larger far from the data (extrapolating the trend).
#[test]
fn a4_term_increases_variance() {
    let (x, y) = smooth_data(25, 2, 0.1, 5);
    let kern = Kernel::SquaredExponential { ard: true };
    let model = GpParams::new()
        .kernel(kern)
        .mean(Mean::Linear)
        .restarts(1)
        .fit(&x, &y)
        .unwrap();
    let h = model.hyperparameters();
    let noise = h.noise_variance + model.diagnostics().jitter;
    let ln_ls: Vec<f64> = h.length_scales.iter().map(|l| l.ln()).collect();
    let kfun = |a: &[f64], b: &[f64]| {
        kern.value_and_gradient(a, b, h.signal_variance.ln(), &ln_ls)
            .0
    };
    let rows: Vec<Vec<f64>> = (0..25)
        .map(|i| x.row(i).iter().copied().collect())
        .collect();
    let kk = DMatrix::from_fn(25, 25, |i, j| {
        kfun(&rows[i], &rows[j]) + if i == j { noise } else { 0.0 }
    });
    let kinv = kk.try_inverse().unwrap();
    let xs = test_points(2, 30);
    let pred = model.predict(&xs).unwrap();
    let mut max_gap: f64 = 0.0;
    for t in 0..xs.nrows() {
        let pt: Vec<f64> = xs.row(t).iter().copied().collect();
        let kv = DVector::from_fn(25, |i, _| kfun(&rows[i], &pt));
        let sk = kfun(&pt, &pt) - (kv.transpose() * &kinv * &kv)[(0, 0)];
        // Dense inverse round-off on a 25x25 kernel matrix: 1e-8 of the signal variance.
        assert!(
            pred.variance[t] >= sk - 1e-8 * h.signal_variance,
            "point {t}: {} < {sk}",
            pred.variance[t]
        );
        max_gap = max_gap.max(pred.variance[t] - sk);
    }
    // The trend extrapolated 3 units beyond the data carries real uncertainty.
    assert!(
        max_gap > 1e-4 * h.signal_variance,
        "A4 term never visible: {max_gap}"
    );
}

/// A serialised and restored model predicts identically.
#[test]
fn serde_round_trip() {
    let (x, y) = smooth_data(12, 1, 0.05, 9);
    let model = GpParams::new()
        .mean(Mean::Linear)
        .restarts(0)
        .fit(&x, &y)
        .unwrap();
    let json = serde_json::to_string(&model).unwrap();
    let back: gp::GpModel = serde_json::from_str(&json).unwrap();
    let xs = test_points(1, 10);
    let (a, b) = (model.predict(&xs).unwrap(), back.predict(&xs).unwrap());
    // serde_json's default float parser may be off by one ulp per number (exact round trips
    // need its `float_roundtrip` feature); that perturbs results at the 1e-12 level.
    assert!((a.mean - b.mean).amax() < 1e-10);
    assert!((a.variance - b.variance).amax() < 1e-10);
    assert!((model.log_marginal_likelihood() - back.log_marginal_likelihood()).abs() < 1e-9);
}

/// The model is usable across threads.
#[test]
fn model_is_send_and_sync() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<gp::GpModel>();
    assert_send_sync::<gp::LmlProblem>();
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, .. ProptestConfig::default() })]

    /// The contraction `x ↦ Σ(x, X₂) w` equals the dense covariance times `w`, for every
    /// kernel and trend, at points inside and outside the data (a wrong sign or a dropped
    /// GLS term moves it by the size of the terms themselves, O(σ_f² |w|)).
    #[test]
    fn contraction_matches_the_dense_covariance(
        k in kernel(), m in mean(), d in 1usize..=2, n in 10usize..=25, seed in 0u64..500,
    ) {
        let (x, y) = smooth_data(n, d, 0.05, seed);
        let model = GpParams::new().kernel(k).mean(m).restarts(1).seed(seed).fit(&x, &y).unwrap();
        let x2 = test_points(d, 17);
        let w: Vec<f64> = (0..17).map(|i| ((i * 7 + seed as usize) % 11) as f64 - 5.0).collect();
        let xs = test_points(d, 23);
        let dense = model.posterior_cov(&xs, &x2).unwrap() * DVector::from_column_slice(&w);
        let fast = model.covariance_contraction(&x2, &w).unwrap().apply(&model, &xs).unwrap();
        // Both routes cancel terms of size σ_f² |w|₁ down to the result; 1e-9 of that is
        // rounding of sums over at most 25 training points, far below any real difference.
        let scale = (model.hyperparameters().signal_variance + 1.0)
            * w.iter().map(|v| v.abs()).sum::<f64>();
        prop_assert!((&fast - &dense).amax() <= 1e-9 * scale, "{fast} vs {dense}");
    }
}

#[test]
fn contraction_refuses_another_model_and_bad_weights() {
    let (x, y) = crate::strategies::smooth_data(12, 1, 0.05, 3);
    let a = GpParams::new().restarts(0).fit(&x, &y).unwrap();
    let y2: Vec<f64> = y.iter().map(|v| 2.0 * v).collect();
    let b = GpParams::new().restarts(0).fit(&x, &y2).unwrap();
    let x2 = test_points(1, 4);
    let c = a.covariance_contraction(&x2, &[1.0; 4]).unwrap();
    assert!(matches!(
        c.apply(&b, &x2),
        Err(gp::GpError::InvalidParameter { name: "model", .. })
    ));
    assert!(matches!(
        a.covariance_contraction(&x2, &[1.0; 3]),
        Err(gp::GpError::ShapeMismatch {
            name: "w",
            expected: 4,
            found: 3,
            ..
        })
    ));
    assert!(matches!(
        a.covariance_contraction(&x2, &[1.0, f64::NAN, 0.0, 0.0]),
        Err(gp::GpError::NonFinite {
            name: "w",
            row: 1,
            ..
        })
    ));
}
