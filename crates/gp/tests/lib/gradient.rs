//! Analytic gradients against central finite differences.

use crate::strategies::{kernel, mean, smooth_data};
use gp::{LmlProblem, NoiseModel};
use proptest::prelude::*;

/// Central-difference step in log-parameter space. Truncation error ~ h² f''' ≈ 1e-8 relative,
/// round-off ~ eps |f| / h ≈ 1e-11 · |f|; both far below the tolerance used below.
const H: f64 = 1e-4;

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, .. ProptestConfig::default() })]

    /// The LML gradient (restricted likelihood, any kernel/mean) matches central differences.
    #[test]
    fn lml_gradient_matches_finite_differences(
        k in kernel(),
        m in mean(),
        d in 1usize..=3,
        n in 8usize..=20,
        seed in 0u64..1000,
        ln_sf2 in -1.0f64..1.5,
        ln_ls in proptest::collection::vec(-0.5f64..1.5, 3),
        ln_sn2 in -6.0f64..-1.0,
        estimate_noise in any::<bool>(),
    ) {
        let (x, y) = smooth_data(n, d, 0.1, seed);
        let noise = if estimate_noise { NoiseModel::Estimated } else { NoiseModel::Fixed(1e-2) };
        let problem = LmlProblem::new(k, m, noise, &x, &y).unwrap();
        let mut theta = vec![ln_sf2];
        theta.extend(&ln_ls[..k.n_length_scales(d)]);
        if estimate_noise { theta.push(ln_sn2); }
        let v = problem.lml_and_gradient(&theta).unwrap();
        // Noise >= e^-6 relative to O(1) signal keeps K well conditioned: no jitter, smooth LML.
        prop_assert_eq!(v.jitter, 0.0);
        for i in 0..theta.len() {
            let mut tp = theta.clone(); tp[i] += H;
            let mut tm = theta.clone(); tm[i] -= H;
            let fd = (problem.log_marginal_likelihood(&tp).unwrap().lml
                - problem.log_marginal_likelihood(&tm).unwrap().lml) / (2.0 * H);
            // 1e-5 relative (plus 1e-6 absolute for near-zero components): a few orders above
            // the finite-difference error estimated at `H`, orders below any formula mistake.
            prop_assert!((fd - v.gradient[i]).abs() <= 1e-5 * fd.abs().max(v.gradient[i].abs()) + 1e-6,
                "param {}: analytic {} vs fd {}", i, v.gradient[i], fd);
        }
    }

    /// The kernel's value_and_gradient matches central differences.
    #[test]
    fn kernel_gradient_matches_finite_differences(
        k in kernel(),
        a in proptest::collection::vec(-2.0f64..2.0, 3),
        b in proptest::collection::vec(-2.0f64..2.0, 3),
        ln_sf2 in -1.0f64..1.0,
        ln_ls in proptest::collection::vec(-1.0f64..1.0, 3),
    ) {
        let m = k.n_length_scales(3);
        let (v, g) = k.value_and_gradient(&a, &b, ln_sf2, &ln_ls[..m]);
        let mut theta = vec![ln_sf2];
        theta.extend(&ln_ls[..m]);
        let eval = |t: &[f64]| k.value_and_gradient(&a, &b, t[0], &t[1..]).0;
        prop_assert!((eval(&theta) - v).abs() < 1e-15);
        for i in 0..theta.len() {
            let mut tp = theta.clone(); tp[i] += H;
            let mut tm = theta.clone(); tm[i] -= H;
            let fd = (eval(&tp) - eval(&tm)) / (2.0 * H);
            // Kernel values are O(1): 1e-7 absolute is ~10x the central-difference error at H.
            prop_assert!((fd - g[i]).abs() < 1e-7, "param {}: analytic {} vs fd {}", i, g[i], fd);
        }
    }
}

/// The LML value agrees with a direct nalgebra computation of the restricted likelihood.
#[test]
fn lml_value_matches_dense_reference() {
    use nalgebra::{DMatrix, DVector};
    let (x, y) = smooth_data(15, 2, 0.1, 7);
    let k = gp::Kernel::Matern52 { ard: true };
    let theta = [0.3, 0.2, 0.7, -3.0];
    for m in [gp::Mean::Zero, gp::Mean::Constant, gp::Mean::Linear] {
        let problem = LmlProblem::new(k, m, NoiseModel::Estimated, &x, &y).unwrap();
        let ours = problem.log_marginal_likelihood(&theta).unwrap().lml;
        let n = 15;
        let kk = DMatrix::from_fn(n, n, |i, j| {
            let xi: Vec<f64> = x.row(i).iter().copied().collect();
            let xj: Vec<f64> = x.row(j).iter().copied().collect();
            k.value_and_gradient(&xi, &xj, theta[0], &theta[1..3]).0
                + if i == j { theta[3].exp() } else { 0.0 }
        });
        let p = m.n_coefficients(2);
        let h = DMatrix::from_fn(n, p, |i, c| if c == 0 { 1.0 } else { x[(i, c - 1)] });
        let yv = DVector::from_column_slice(&y);
        let kinv = kk.clone().try_inverse().unwrap();
        let a = h.transpose() * &kinv * &h;
        let (beta, logdet_a, half_hth) = if p > 0 {
            let b = a.clone().try_inverse().unwrap() * h.transpose() * &kinv * &yv;
            (
                b,
                a.determinant().ln(),
                0.5 * (h.transpose() * &h).determinant().ln(),
            )
        } else {
            (DVector::zeros(0), 0.0, 0.0)
        };
        let r = &yv - &h * beta;
        let reference = -0.5 * (r.transpose() * &kinv * &r)[(0, 0)]
            - 0.5 * kk.determinant().ln()
            - 0.5 * logdet_a
            + half_hth
            - 0.5 * (n - p) as f64 * (2.0 * std::f64::consts::PI).ln();
        // Both are O(10) sums of well-conditioned 15x15 quantities: 1e-8 covers inverse/det round-off.
        assert!(
            (ours - reference).abs() < 1e-8,
            "{m:?}: {ours} vs {reference}"
        );
    }
}
