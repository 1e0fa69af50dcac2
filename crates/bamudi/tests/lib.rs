//! Integration tests of the `bamudi` building blocks (the full pipeline on the beam
//! application lives in the workspace e2e tests, `tests/tests/lib.rs`).

#[path = "../../mlmodel/tests/apps/beam_app.rs"]
mod beam_app;

use bamudi::internals::ExactLinearEstimator;
use bamudi::internals::adaptive_metropolis;
use bamudi::internals::{FactoredCovariance, assemble_covariance, iid_log_density};
use bamudi::internals::{
    LinearParts, TrainingSpec, XContext, generate_general, generate_linear, theta_rule,
};
use bamudi::observe::Silent;
use bamudi::posterior::GridPosterior;
use bamudi::surrogate::CoefficientEstimator;
use bamudi::{
    CalibrationConfig, CalibrationParams, Experiments, Marginalisation, McmcConfig, SamplingRule,
};
use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;

/// A small deterministic pseudo-random matrix (entries in [-1, 1)).
fn pseudo_random(rows: usize, cols: usize, seed: u64) -> DMatrix<f64> {
    let mut g = beam_app::Normal64::new(seed);
    DMatrix::from_fn(rows, cols, |_, _| 2.0 * g.uniform() - 1.0)
}

fn spd(n: usize, seed: u64) -> DMatrix<f64> {
    let m = pseudo_random(n, n, seed);
    &m * m.transpose() + DMatrix::identity(n, n) * 0.1
}

fn kron(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    DMatrix::from_fn(a.nrows() * b.nrows(), a.ncols() * b.ncols(), |r, c| {
        a[(r / b.nrows(), c / b.ncols())] * b[(r % b.nrows(), c % b.ncols())]
    })
}

#[test]
fn module3_likelihood_equals_brute_force_dense_evaluation() {
    let (n_e, n_o, k) = (4, 3, 2);
    let b = pseudo_random(n_o, k, 1);
    let covs: Vec<DMatrix<f64>> = (0..k).map(|kk| spd(n_e, 10 + kk as u64)).collect();
    let sigma2 = 0.5;
    // brute force: explicit Kronecker sum, LU inverse and determinant (a different algorithm)
    let mut v = DMatrix::identity(n_e * n_o, n_e * n_o) * sigma2;
    for kk in 0..k {
        let bk = b.column(kk).into_owned();
        v += kron(&covs[kk], &(&bk * bk.transpose()));
    }
    let r = DVector::from_iterator(n_e * n_o, pseudo_random(n_e * n_o, 1, 99).iter().copied());
    let inv = v.clone().try_inverse().unwrap();
    let det = v.clone().determinant();
    let n_s = (n_e * n_o) as f64;
    let brute = -0.5 * (r.transpose() * &inv * &r)[(0, 0)]
        - 0.5 * det.ln()
        - 0.5 * n_s * (2.0 * std::f64::consts::PI).ln();
    let fac =
        FactoredCovariance::new(&assemble_covariance(&b, &covs, sigma2).unwrap(), "test").unwrap();
    let ours = fac.log_density(r.as_slice()).unwrap();
    // 12x12 well-conditioned (eigenvalues >= 0.5): round-off of two O(n^3) algorithms only
    assert!(
        (ours - brute).abs() < 1e-9 * brute.abs().max(1.0),
        "{ours} vs {brute}"
    );
    assert_eq!(fac.report().jitter, 0.0);
    // the grid's batched form (one blocked solve for several θ's residuals) against the same
    // brute force, column by column; the tolerance is the one above for the same reason
    let resids = pseudo_random(n_e * n_o, 5, 7);
    let batched = fac.log_densities(&resids).unwrap();
    assert_eq!(batched.len(), 5);
    for (c, got) in batched.iter().enumerate() {
        let r = resids.column(c);
        let want = -0.5 * (r.transpose() * &inv * r)[(0, 0)]
            - 0.5 * det.ln()
            - 0.5 * n_s * (2.0 * std::f64::consts::PI).ln();
        assert!(
            (got - want).abs() < 1e-9 * want.abs().max(1.0),
            "column {c}: {got} vs {want}"
        );
    }
    assert!(
        fac.log_densities(&DMatrix::zeros(n_e * n_o - 1, 2))
            .is_err()
    );
}

/// The grid evaluates the dense likelihood of Module 3 (the paper's and the conditional mode)
/// in batches: every node's residuals, then one blocked solve with the factor of `V`. On the
/// beam application (data from a gap and `ρ` that no node equals, a covariance and a
/// coefficient shift that are not the model's), the batch must give each node's values as
/// `log_posteriors` gives them one at a time, and `-∞` outside the prior.
#[test]
fn batched_module3_nodes_equal_node_by_node_evaluation() {
    use bamudi::internals::LogPosteriors;
    use bamudi::internals::Problem;
    use bamudi::internals::{ThetaLikelihood, ThetaResiduals};
    use mlmodel::{ObservableModel, UnobservableModel};
    let model = beam_app::beam_model((5.0, 25.0), 4);
    let (n_e, n_o) = (30, beam_app::GAUGES_IN.len());
    let (x, y) = beam_app::simulate(n_e, 12.3, 0.9, 1.0, 3);
    let names = (
        model.unobservable.input_names(),
        model.observable.output_names(),
    );
    let exps = Experiments::new(names.0, names.1, x, y).unwrap();
    let cfg = CalibrationParams::default().check().unwrap();
    let p = Problem::new(&model, &exps, &cfg, &Silent).unwrap();
    let covs: Vec<DMatrix<f64>> = (0..p.parts.b.ncols())
        .map(|k| spd(n_e, 40 + k as u64) * 0.01)
        .collect();
    let factor =
        FactoredCovariance::new(&assemble_covariance(&p.parts.b, &covs, 1.0).unwrap(), "V")
            .unwrap();
    let lik = ThetaLikelihood {
        res: ThetaResiduals {
            p: &p,
            rho: 0.95,
            shift: pseudo_random(n_e, n_o, 5),
            conditional: None,
        },
        factor: &factor,
    };
    let nodes = [2.0, 5.5, 7.5, 12.0, 18.3, 24.9, 30.0];
    let batched = lik.log_posteriors_at_nodes(&nodes, &Silent).unwrap();
    assert_eq!(batched.len(), nodes.len());
    for (t, got) in nodes.iter().zip(&batched) {
        let want = lik.log_posteriors(&[*t]).unwrap();
        if !want.0.is_finite() {
            assert_eq!(*got, want, "θ = {t}");
            continue;
        }
        // the same 210 x 210 triangular system summed in another order: round-off relative
        // to the log density's size; the no-discrepancy value is computed identically
        assert!(
            (got.0 - want.0).abs() <= 1e-10 * want.0.abs().max(1.0),
            "θ = {t}: {} vs {}",
            got.0,
            want.0
        );
        assert_eq!(got.1, want.1, "θ = {t}");
    }
    assert_eq!(batched[0].0, f64::NEG_INFINITY);
    assert!(batched[1..6].iter().all(|v| v.0.is_finite()));
    // a pass with no node inside the prior solves with no column; an empty pass returns nothing
    let outside = lik.log_posteriors_at_nodes(&[1.0, 40.0], &Silent).unwrap();
    assert!(
        outside
            .iter()
            .all(|v| *v == (f64::NEG_INFINITY, f64::NEG_INFINITY))
    );
    assert!(
        lik.log_posteriors_at_nodes(&[], &Silent)
            .unwrap()
            .is_empty()
    );
    // a factor of another size than the residuals is an error, as node by node
    let small = FactoredCovariance::new(&spd(n_e * n_o - 1, 3), "V").unwrap();
    let mismatched = ThetaLikelihood {
        factor: &small,
        ..lik
    };
    assert!(
        mismatched
            .log_posteriors_at_nodes(&[12.0], &Silent)
            .is_err()
    );
    assert!(mismatched.log_posteriors(&[12.0]).is_err());
}

#[test]
fn iid_likelihood_is_the_product_of_normals() {
    let r = [0.3, -1.2, 2.0];
    let s2 = 0.7f64;
    let direct: f64 = r
        .iter()
        .map(|x| -0.5 * x * x / s2 - 0.5 * (2.0 * std::f64::consts::PI * s2).ln())
        .sum();
    // same formula, summed differently: round-off only
    assert!((iid_log_density(&r, s2) - direct).abs() < 1e-12);
}

#[test]
fn covariance_shape_mismatch_is_an_error() {
    let b = DMatrix::zeros(3, 2);
    let covs = vec![DMatrix::identity(4, 4)];
    assert!(assemble_covariance(&b, &covs, 1.0).is_err());
    // indefinite (eigenvalues 3 and -1): no small jitter can rescue it, so it is an error
    let err = FactoredCovariance::new(
        &DMatrix::from_fn(2, 2, |i, j| if i == j { 1.0 } else { 2.0 }),
        "V",
    )
    .unwrap_err();
    assert!(
        err.to_string().contains("V is not positive definite"),
        "{err}"
    );
}

#[test]
fn grid_posterior_integrates_to_one_and_matches_a_skewed_density() {
    // Gamma(3, 1) density on [0, 30]: mean 3, var 3
    let theta: Vec<f64> = (0..3001).map(|i| 30.0 * i as f64 / 3000.0).collect();
    let logp: Vec<f64> = theta
        .iter()
        .map(|&t| {
            if t > 0.0 {
                2.0 * t.ln() - t
            } else {
                f64::NEG_INFINITY
            }
        })
        .collect();
    let post = GridPosterior::new(theta.clone(), logp).unwrap();
    let h = 0.01;
    let integral: f64 =
        h * (post.density.iter().sum::<f64>() - 0.5 * (post.density[0] + post.density[3000]));
    // trapezoid normalisation makes this exact up to round-off
    assert!((integral - 1.0).abs() < 1e-12);
    assert!((post.cdf[3000] - 1.0).abs() < 1e-12);
    // trapezoid error O(h²) = 1e-4 times derivative bounds of order 1
    assert!((post.mean - 3.0).abs() < 1e-3);
    assert!((post.sd - 3f64.sqrt()).abs() < 1e-3);
    // Gamma(3,1) quantiles: 0.6187 and 7.2247; interpolation error O(h)
    assert!(
        (post.ci95.0 - 0.6187).abs() < 0.01 && (post.ci95.1 - 7.2247).abs() < 0.01,
        "{:?}",
        post.ci95
    );
    let masses: f64 = post.masses().iter().sum();
    assert!((masses - 1.0).abs() < 1e-12);
}

#[test]
fn grid_posterior_rejects_all_zero_density() {
    let err = GridPosterior::new(vec![0.0, 1.0, 2.0], vec![f64::NEG_INFINITY; 3]).unwrap_err();
    assert!(err.to_string().contains("degenerate"));
}

#[test]
fn mcmc_recovers_a_correlated_2d_gaussian() {
    let mean = [1.0, -2.0];
    let cov = DMatrix::from_row_slice(2, 2, &[1.0, 0.8, 0.8, 2.0]);
    let prec = cov.clone().try_inverse().unwrap();
    let logp = |t: &[f64]| {
        let d = DVector::from_vec(vec![t[0] - mean[0], t[1] - mean[1]]);
        Ok(-0.5 * (d.transpose() * &prec * &d)[(0, 0)])
    };
    let cfg = McmcConfig {
        chains: 4,
        warmup: 3000,
        samples: 20_000,
    };
    let starts = vec![
        vec![-3.0, 3.0],
        vec![4.0, -5.0],
        vec![0.0, 0.0],
        vec![3.0, 1.0],
    ];
    let res = adaptive_metropolis(logp, &starts, &[0.5, 0.5], &cfg, 11).unwrap();
    let ess = res.ess.iter().copied().fold(f64::INFINITY, f64::min);
    // Monte Carlo standard error of a mean is sd / sqrt(ESS); allow 4 standard errors
    for j in 0..2 {
        let se = cov[(j, j)].sqrt() / ess.sqrt();
        assert!(
            (res.mean[j] - mean[j]).abs() < 4.0 * se,
            "mean {j}: {} (se {se})",
            res.mean[j]
        );
    }
    // covariance entries: relative MC error ~ sqrt(2/ESS) ≈ 0.03 for ESS ~ 2000; allow 0.15
    for (a, b) in [(0, 0), (0, 1), (1, 1)] {
        assert!(
            (res.cov[(a, b)] - cov[(a, b)]).abs() < 0.15 * cov[(a, a)].max(cov[(b, b)]),
            "cov {a}{b}: {}",
            res.cov[(a, b)]
        );
    }
    assert!(res.rhat.iter().all(|r| *r < 1.01), "rhat {:?}", res.rhat);
    assert!(ess > 1000.0, "ess {ess}");
    // adapted random-walk acceptance in 2-D should be near the optimal ~0.35
    assert!(
        res.acceptance.iter().all(|a| (0.15..0.6).contains(a)),
        "{:?}",
        res.acceptance
    );
}

#[test]
fn mcmc_is_reproducible_from_its_seed() {
    let cfg = McmcConfig {
        chains: 2,
        warmup: 200,
        samples: 300,
    };
    let starts = vec![vec![0.0, 0.0], vec![1.0, 1.0]];
    let f = |t: &[f64]| Ok(-0.5 * (t[0] * t[0] + t[1] * t[1]));
    let a = adaptive_metropolis(f, &starts, &[1.0, 1.0], &cfg, 5).unwrap();
    let b = adaptive_metropolis(f, &starts, &[1.0, 1.0], &cfg, 5).unwrap();
    assert_eq!(a, b);
}

#[test]
fn mcmc_returns_the_density_error_instead_of_rejecting() {
    let cfg = McmcConfig {
        chains: 2,
        warmup: 50,
        samples: 50,
    };
    let starts = vec![vec![0.0], vec![0.1]];
    // The density fails away from the start: the run must report it, not treat it as -inf.
    let f = |t: &[f64]| {
        if t[0].abs() > 0.5 {
            Err(bamudi::BamudiError::DegeneratePosterior(format!(
                "model failed at {t:?}"
            )))
        } else {
            Ok(-0.5 * t[0] * t[0])
        }
    };
    let err = adaptive_metropolis(f, &starts, &[2.0], &cfg, 5).unwrap_err();
    assert!(err.to_string().contains("model failed"), "{err}");
}

#[test]
fn exact_estimator_equals_brute_force_gaussian_conditioning() {
    let (n_o, k) = (5, 3);
    let b = pseudo_random(n_o, k, 3);
    let est = ExactLinearEstimator::new(b.clone(), 0.4).unwrap();
    let m = DVector::from_vec(vec![0.5, -1.0, 0.2]);
    let cov = spd(k, 4);
    let r = DVector::from_vec(vec![1.0, -0.5, 0.3, 2.0, -1.0]);
    // joint Gaussian of (α, y = B α + ε): E[α | y] = m + Σ_αy Σ_yy⁻¹ (y - B m), via a full inverse
    let s_yy = &b * &cov * b.transpose() + DMatrix::identity(n_o, n_o) * 0.16;
    let s_ay = &cov * b.transpose();
    let brute = &m + s_ay * s_yy.try_inverse().unwrap() * (&r - &b * &m);
    let ours = est.conditional_mean(&m, &cov, &r).unwrap();
    // same maths via SVD pseudo-inverse vs LU inverse of a 5x5 SPD matrix: round-off only
    assert!((&ours - &brute).amax() < 1e-10, "{ours} vs {brute}");

    // and against Monte Carlo: self-normalised importance sampling over prior draws, for data
    // drawn from the model itself (so the posterior is not in a prior tail)
    let chol = cov.clone().cholesky().unwrap().l();
    let alpha0 = &m + &chol * DVector::from_vec(vec![0.5, -0.3, 0.2]);
    let r = &b * &alpha0 + DVector::from_vec(vec![0.2, -0.4, 0.1, 0.3, -0.2]);
    let exact = est.conditional_mean(&m, &cov, &r).unwrap();
    let post_cov = &cov - &cov * b.transpose() * s_yy_inv(&b, &cov, 0.16) * &b * &cov;
    let mut g = beam_app::Normal64::new(77);
    let (mut num, mut den, mut den2) = (DVector::zeros(k), 0.0, 0.0);
    for _ in 0..200_000 {
        let a = &m + &chol * DVector::from_fn(k, |_, _| g.normal());
        let w = (-0.5 * (&r - &b * &a).norm_squared() / 0.16).exp();
        num += &a * w;
        den += w;
        den2 += w * w;
    }
    let mc = num / den;
    let ess = den * den / den2;
    for j in 0..k {
        // importance-sampling standard error ≈ posterior sd / sqrt(ESS); allow 5 of them
        let tol = 5.0 * post_cov[(j, j)].sqrt() / ess.sqrt();
        assert!(
            (mc[j] - exact[j]).abs() < tol,
            "coef {j}: MC {} vs exact {} (tol {tol}, ESS {ess})",
            mc[j],
            exact[j]
        );
    }
}

fn s_yy_inv(b: &DMatrix<f64>, cov: &DMatrix<f64>, noise_var: f64) -> DMatrix<f64> {
    (b * cov * b.transpose() + DMatrix::identity(b.nrows(), b.nrows()) * noise_var)
        .try_inverse()
        .unwrap()
}

#[test]
fn exact_estimator_without_noise_is_least_squares_when_b_has_full_column_rank() {
    let b = pseudo_random(7, 4, 8);
    let est = ExactLinearEstimator::new(b.clone(), 0.0).unwrap();
    let ctx = vec![XContext {
        mean_ag: vec![0.0; 7],
        mean_offset: vec![1.0; 7],
        alpha_half_width: vec![2.0, 0.5, 1.0, 3.0],
        response_rms: 1.0,
    }];
    let y = DMatrix::from_row_slice(1, 7, &[1.0, 2.0, 0.0, -1.0, 3.0, 0.5, 1.5]);
    let got = est.predict(0.7, &DMatrix::zeros(1, 2), &y, &ctx).unwrap();
    let rhs = DVector::from_iterator(7, y.iter().map(|v| v - 1.0));
    let ls = (b.transpose() * &b).try_inverse().unwrap() * b.transpose() * rhs;
    // pseudo-inverse limit equals the normal equations up to round-off (cond(B) is modest)
    assert!((got.row(0).transpose() - ls).amax() < 1e-8);
}

fn write(name: &str, text: &str) -> std::path::PathBuf {
    let p = std::env::temp_dir().join(format!("bamudi_test_{}_{name}", std::process::id()));
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn csv_errors_name_file_row_and_column() {
    let cases = [
        (
            "missing.csv",
            "p,s\n1,2\n",
            "line 1",
            "`q`",
            "missing column",
        ),
        (
            "dup.csv",
            "p,q,q,s\n1,2,3,4\n",
            "line 1",
            "`q`",
            "duplicate",
        ),
        (
            "nan.csv",
            "p,q,s\n1,2,3\n4,NaN,6\n",
            "line 3",
            "`q`",
            "not finite",
        ),
        (
            "text.csv",
            "p,q,s\n1,2,3\n4,5,six\n",
            "line 3",
            "`s`",
            "not a number",
        ),
        ("empty.csv", "p,q,s\n1,,3\n", "line 2", "`q`", "empty"),
        ("short.csv", "p,q,s\n1,2\n", "line 2", "`-`", "fields"),
    ];
    for (name, text, row, col, what) in cases {
        let path = write(name, text);
        let err = Experiments::read_csv(&path, &["p", "q"], &["s"])
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(name) && err.contains(row) && err.contains(col) && err.contains(what),
            "{name}: {err}"
        );
    }
    let err = Experiments::read_csv(std::path::Path::new("/nonexistent/x.csv"), &["p"], &["s"])
        .unwrap_err()
        .to_string();
    assert!(err.contains("/nonexistent/x.csv"), "{err}");
}

#[test]
fn csv_round_trip_is_exact_and_ignores_extra_columns() {
    let x = pseudo_random(5, 2, 21);
    let y = pseudo_random(5, 3, 22) * 1e3;
    let e = Experiments::new(
        vec!["a".into(), "b".into()],
        vec!["u".into(), "v".into(), "w".into()],
        x,
        y,
    )
    .unwrap();
    let path = std::env::temp_dir().join(format!("bamudi_test_{}_rt.csv", std::process::id()));
    e.write_csv(&path).unwrap();
    assert_eq!(
        Experiments::read_csv(&path, &["a", "b"], &["u", "v", "w"]).unwrap(),
        e
    );
    // a subset of columns in another order
    let sub = Experiments::read_csv(&path, &["b"], &["w", "u"]).unwrap();
    assert_eq!(sub.x.column(0), e.x.column(1));
    assert_eq!(sub.y.column(0), e.y.column(2));
}

#[test]
fn config_toml_round_trip_and_named_errors() {
    let cfg = CalibrationParams::default()
        .marginalisation(Marginalisation::MonteCarlo { samples: 50 })
        .sampling(SamplingRule::default().alpha_scale(0.8))
        .check()
        .unwrap();
    let text = toml::to_string(cfg.params()).unwrap();
    assert_eq!(CalibrationConfig::from_toml_str(&text).unwrap(), cfg);
    let err = CalibrationConfig::from_toml_str("[sampling]\nrho_range = [1.0, 0.0]\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains("sampling.rho_range"), "{err}");
    let err = CalibrationConfig::from_toml_str("trainin_size = 5\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains("trainin_size"), "{err}");
    for bad in ["-1.0", "1e9", "nan"] {
        let err =
            CalibrationConfig::from_toml_str(&format!("[marginal]\nlevel_variance = {bad}\n"))
                .unwrap_err()
                .to_string();
        assert!(err.contains("marginal.level_variance"), "{bad}: {err}");
    }
}

#[test]
fn training_set_linear_fast_path_equals_general_path_and_is_deterministic() {
    let model = beam_app::beam_model((5.0, 25.0), 4);
    let parts = LinearParts::new(&model).unwrap();
    let rule = theta_rule(
        model.prior.as_ref(),
        &Marginalisation::Quadrature { order: 3 },
        0,
    )
    .unwrap();
    let sampling = SamplingRule::default().draws_per_x(4);
    let bounds = [beam_app::P_RANGE_LBF, beam_app::Q_RANGE_LBF_PER_IN];
    let spec = TrainingSpec {
        theta_rule: &rule,
        rule: &sampling,
        bounds: &bounds,
        size: 40,
        seed: 9,
    };
    let fast = generate_linear(&model, &parts, &spec, &Silent).unwrap();
    let slow = generate_general(&model, &spec, &Silent).unwrap();
    assert_eq!(fast.len(), 40);
    assert_eq!(fast.pool_size, 10);
    assert_eq!(fast.alpha, slow.alpha);
    assert_eq!(fast.x, slow.x);
    let scale = fast.mu_o.amax();
    // A (Σ w g) vs Σ w (A g): summation order only
    assert!((&fast.mu_o - &slow.mu_o).amax() < 1e-9 * scale);
    let again = generate_linear(&model, &parts, &spec, &Silent).unwrap();
    assert_eq!(again.mu_o, fast.mu_o);
    // the sampling rule: |α_k| within c (|s_k| + floor), ρ within its range
    assert!(fast.rho.iter().all(|r| (0.0..=1.2).contains(r)));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, .. ProptestConfig::default() })]
    /// The pseudo-inverse estimator reproduces α exactly from noise-free data whenever B has
    /// full column rank (K <= N_o), for any ρ and offsets.
    #[test]
    fn exact_estimator_inverts_noise_free_data(seed in 0u64..1000, rho in 0.0..1.2f64) {
        let b = pseudo_random(7, 3, seed);
        let est = ExactLinearEstimator::new(b.clone(), 0.0).unwrap();
        let alpha = pseudo_random(3, 1, seed + 1);
        let ag: Vec<f64> = pseudo_random(7, 1, seed + 2).iter().copied().collect();
        let off: Vec<f64> = pseudo_random(7, 1, seed + 3).iter().copied().collect();
        let y: Vec<f64> = (0..7).map(|p| rho * ag[p] + off[p] + (b.row(p) * &alpha)[(0, 0)]).collect();
        let ctx = vec![XContext { mean_ag: ag, mean_offset: off, alpha_half_width: vec![1.0; 3], response_rms: 1.0 }];
        let got = est.predict(rho, &DMatrix::zeros(1, 2), &DMatrix::from_row_slice(1, 7, &y), &ctx).unwrap();
        let cond = b.clone().svd(false, false).singular_values;
        prop_assume!(cond.min() > 1e-3 * cond.max());
        // conditioning-limited round-off
        let err = (got.row(0).transpose() - &alpha).amax();
        prop_assert!(err < 1e-8, "err {err}, singular values {cond}");
    }
}

#[test]
fn gp_posterior_covariance_over_noise_variance_is_the_mean_smoother() {
    // The conditional coefficient mode (bamudi::posterior::conditional) re-conditions the coefficient GPs
    // on new targets through S = Σ(X, X) / σ_n² (and S(x*) = Σ(x*, X) / σ_n² at new inputs).
    // Check the identity against the GP's own predictive mean, at the training inputs and at
    // new ones, for a constant-mean GP with estimated noise.
    let n = 60;
    let x = DMatrix::from_fn(n, 2, |i, j| {
        24.0 + 720.0 * (((i * 37 + j * 11) % n) as f64 / n as f64)
    });
    let mut g = beam_app::Normal64::new(4);
    let y: Vec<f64> = (0..n)
        .map(|i| 3.0 + (x[(i, 0)] / 200.0).sin() - (x[(i, 1)] / 300.0).cos() + 0.1 * g.normal())
        .collect();
    let model = gp::GpParams::new()
        .kernel(gp::Kernel::SquaredExponential { ard: true })
        .mean(gp::Mean::Constant)
        .estimate_noise(true)
        .restarts(1)
        .seed(3)
        .fit(&x, &y)
        .unwrap();
    let xs = DMatrix::from_fn(5, 2, |i, j| 100.0 + 120.0 * i as f64 + 7.0 * j as f64);
    let yv = DVector::from_vec(y);
    for pts in [&x, &xs] {
        let smoothed = model.posterior_cov(pts, &x).unwrap() * &yv / model.noise_variance();
        let mean = model.predict(pts).unwrap().mean;
        let err = (smoothed - &mean).amax();
        // two routes to the same linear map: round-off of a 60-point system only
        assert!(err < 1e-8 * mean.amax(), "smoother vs GP mean: {err}");
    }
}

/// Beam records from a reality the model does not contain on the observable side either: the
/// simulator's tapered discrepancy (not a Legendre series), gauge 0 reading 4 µε high (four
/// noise sds) and gauge 1 with a 3 % gain error (a drifted bridge). The tests that use them
/// check identities, which must hold on any data, not only on data the model explains.
fn beam_records_with_faulty_gauges(n: usize, seed: u64) -> (DMatrix<f64>, DMatrix<f64>) {
    let (x, mut y) = beam_app::simulate(n, 12.3, 0.9, 1.0, seed);
    y.column_mut(0).add_scalar_mut(4.0);
    y.column_mut(1).scale_mut(1.03);
    (x, y)
}

/// The beam (prior 5-25, 4 terms) and 30 of those records (seed 11) as experiments.
fn beam_with_faulty_records() -> (
    mlmodel::MultiLevelModel<beam_app::BeamReaction, beam_app::BeamStrain>,
    Experiments,
) {
    use mlmodel::{ObservableModel, UnobservableModel};
    let model = beam_app::beam_model((5.0, 25.0), 4);
    let (x, y) = beam_records_with_faulty_gauges(30, 11);
    let names = (
        model.unobservable.input_names(),
        model.observable.output_names(),
    );
    let exps = Experiments::new(names.0, names.1, x, y).unwrap();
    (model, exps)
}

/// The beam calibrated in each coefficient mode (exact estimator, 41 grid points).
fn in_each_mode(
    model: &mlmodel::MultiLevelModel<beam_app::BeamReaction, beam_app::BeamStrain>,
    exps: &Experiments,
) -> Vec<(bamudi::CoefficientMode, bamudi::Calibration)> {
    use bamudi::{Calibrate, CoefficientMode, EstimatorParams};
    let modes = [
        CoefficientMode::PriorMarginal,
        CoefficientMode::ConditionalOnTheta,
        CoefficientMode::default(),
    ];
    modes
        .into_iter()
        .map(|mode| {
            let cfg = CalibrationParams::default()
                .estimator(EstimatorParams::ExactLinear)
                .theta_grid_points(41)
                .coefficients(mode.clone())
                .check()
                .unwrap();
            (mode, Calibrate::new(&cfg).run(model, exps).unwrap())
        })
        .collect()
}

/// The model-row memo changes no number of a calibration: the beam calibrated (marginal
/// mode, exact estimator) without a memo, with one, and again with the now-filled memo (every
/// row a hit) gives the same Module 2 and Module 3, value for value; so does Module 3 run on
/// a calibration's surrogate (`run_with_surrogate`), or on one fitted alone (`fit_surrogate`), against a
/// full run in that mode.
#[test]
fn row_memo_and_module3_reruns_change_no_calibration() {
    use bamudi::{Calibrate, CoefficientMode, EstimatorParams};
    use mlmodel::{ObservableModel, UnobservableModel};
    let plain = beam_app::beam_model((5.0, 25.0), 4);
    let memo = beam_app::beam_model((5.0, 25.0), 4).with_row_memo(100_000);
    let (x, y) = beam_records_with_faulty_gauges(30, 11);
    let names = (
        plain.unobservable.input_names(),
        plain.observable.output_names(),
    );
    let exps = Experiments::new(names.0, names.1, x, y).unwrap();
    let cfg = CalibrationParams::default()
        .estimator(EstimatorParams::ExactLinear)
        .theta_grid_points(41)
        .check()
        .unwrap();
    let json = |c: &bamudi::Calibration| {
        let m2 = serde_json::to_value(c.module2()).unwrap();
        let verdict = serde_json::to_value(c.adequacy()).unwrap();
        (m2, serde_json::to_value(c.module3()).unwrap(), verdict)
    };
    let reference = Calibrate::new(&cfg).run(&plain, &exps).unwrap();
    let first = Calibrate::new(&cfg).run(&memo, &exps).unwrap();
    let filled = memo.row_memo().len();
    assert!(filled > 0, "the calibration read no row through the memo");
    let second = Calibrate::new(&cfg).run(&memo, &exps).unwrap();
    assert_eq!(memo.row_memo().len(), filled, "the second run met new rows");
    assert!(json(&first) == json(&reference) && json(&second) == json(&reference));
    let in_mode = |mode| {
        let params = cfg.clone().into_params().coefficients(mode);
        params.check().unwrap()
    };
    // Module 3 re-run on `base` equals the full calibration in `params`' mode (returned).
    // Both checks below go through this closure; it holds the same `json(rerun) == json(full)`
    // assertion each of them had written out before (folded, not changed).
    let rerun_equals_run = |params: &bamudi::CalibrationConfig, base: &bamudi::Surrogate| {
        let rerun = Calibrate::new(params)
            .run_with_surrogate(&memo, &exps, base)
            .unwrap();
        let full = Calibrate::new(params).run(&plain, &exps).unwrap();
        assert!(json(&rerun) == json(&full));
        full
    };
    let paper = in_mode(CoefficientMode::PriorMarginal);
    let full = rerun_equals_run(&paper, &first.surrogate());
    // the conditional mode on the paper mode's Module 2 (the reproduction's sensitivity study)
    let conditional = in_mode(CoefficientMode::ConditionalOnTheta);
    rerun_equals_run(&conditional, &full.surrogate());
    // and on Module 2 fitted alone
    let alone = Calibrate::new(&paper).fit_surrogate(&memo, &exps).unwrap();
    assert_eq!(
        serde_json::to_value(alone.module2()).unwrap(),
        json(&full).0
    );
    rerun_equals_run(&conditional, &alone);
    // the marginal mode (the default, the reproduction's headline) on the paper mode's
    rerun_equals_run(&cfg, &full.surrogate());
    // other outputs at the same inputs, or other inputs, are other data: refused
    let refused = |x: DMatrix<f64>, y: DMatrix<f64>, what: &str| {
        let names = (exps.input_names.clone(), exps.output_names.clone());
        let other = Experiments::new(names.0, names.1, x, y).unwrap();
        let err = Calibrate::new(&conditional)
            .run_with_surrogate(&memo, &other, &alone)
            .unwrap_err();
        assert!(err.to_string().contains(what), "{err}");
    };
    let mut y = exps.y.clone();
    y[(3, 1)] += 1e-9;
    refused(exps.x.clone(), y, "experiment outputs differ");
    let mut x = exps.x.clone();
    x[(3, 0)] += 1e-9;
    refused(x, exps.y.clone(), "experiment inputs differ");
    // a configuration whose Module 2 would differ is refused, not run on the old one
    let ridge = conditional
        .into_params()
        .estimator(EstimatorParams::Ridge(bamudi::RidgeParams { lambda: 1e-3 }))
        .check()
        .unwrap();
    let err = Calibrate::new(&ridge)
        .run_with_surrogate(&memo, &exps, &full.surrogate())
        .unwrap_err();
    assert!(err.to_string().contains("estimator differs"), "{err}");
}

/// Each coefficient mode's fit is its own variant of `ModeFit`, and a saved calibration keeps
/// the flat layout of `module3` it always had (the same keys in the same order, `null` where a
/// mode has none): saved, read and saved again, the text is the same, the variant is the
/// mode's, and a file mixing two modes' fits, or whose fit is not its configuration's mode,
/// is refused with the key named.
#[test]
fn each_mode_saves_and_reads_its_own_fit() {
    use bamudi::CoefficientMode;
    use bamudi::posterior::ModeFit;
    let (model, exps) = beam_with_faulty_records();
    let layout = [
        "rho_star",
        "rho_profile",
        "refit_gps",
        "alpha_hat",
        "alpha_correction",
        "sigma_eps",
        "sigma_eps_estimated",
        "covariance",
        "posterior",
        "posterior_no_discrepancy",
        "no_discrepancy",
        "marginal",
        "averaged",
    ];
    let mut saved = Vec::new();
    for (mode, cal) in in_each_mode(&model, &exps) {
        let m3 = cal.module3();
        assert_eq!(m3.mode.kind(), mode.kind());
        match (&m3.mode, &mode) {
            (ModeFit::PriorMarginal, CoefficientMode::PriorMarginal)
            | (ModeFit::ConditionalOnTheta(_), CoefficientMode::ConditionalOnTheta)
            | (ModeFit::Marginal(_), CoefficientMode::Marginal(_)) => {}
            (fit, _) => panic!("{mode:?} fitted {:?}", fit.kind()),
        }
        let text = cal.to_json_string().unwrap();
        let value: serde_json::Value = serde_json::from_str(&text).unwrap();
        // the keys of module3's own object, in the order written (serde_json's map here is
        // ordered by key, so they are read off the text)
        assert_eq!(top_level_keys(&text, "\"module3\":{"), layout, "{mode:?}");
        let again = bamudi::Calibration::from_json_str(&text, "saved").unwrap();
        assert_eq!(again.module3().mode.kind(), mode.kind());
        // the configuration holds the marginal mode's prior in that mode only
        let prior = value["config"].get("marginal");
        assert_eq!(prior.is_some(), mode.marginal_prior().is_some(), "{mode:?}");
        assert_eq!(again.to_json_string().unwrap(), text, "{mode:?}");
        saved.push(value);
    }
    let refused = |v: &serde_json::Value| {
        bamudi::Calibration::from_json_str(&v.to_string(), "edited")
            .unwrap_err()
            .to_string()
    };
    // the marginal mode's file given the conditional mode's correction too
    let mut mixed = saved[2].clone();
    mixed["module3"]["alpha_correction"] = saved[1]["module3"]["alpha_correction"].clone();
    let e = refused(&mixed);
    assert!(
        e.contains("alpha_correction") && e.contains("one mode"),
        "{e}"
    );
    // the conditional mode's correction without its profile
    let mut partial = saved[1].clone();
    partial["module3"]["rho_profile"] = serde_json::Value::Null;
    let e = refused(&partial);
    assert!(e.contains("module3.rho_profile"), "{e}");
    // the paper's mode's file configured as the marginal mode
    let mut other = saved[0].clone();
    other["config"]["coefficients"] = serde_json::json!("marginal");
    let e = refused(&other);
    assert!(e.contains("config.coefficients"), "{e}");
    // a paper's-mode file holding marginal settings (written before they were refused, or
    // under other defaults) loads: the settings it never read are dropped
    let mut older = saved[0].clone();
    older["config"]["marginal"]["level_variance"] = serde_json::json!(1e3);
    let read = bamudi::Calibration::from_json_str(&older.to_string(), "older").unwrap();
    assert_eq!(read.config().coefficients, CoefficientMode::PriorMarginal);
}

/// The keys of the JSON object that starts right after `opening` in `text` (its own keys,
/// not its members'), in the order written.
fn top_level_keys(text: &str, opening: &str) -> Vec<String> {
    let start = text.find(opening).expect("the object") + opening.len();
    let (mut depth, mut in_string, mut escaped) = (1usize, false, false);
    let (mut keys, mut current, mut expect_key) = (Vec::new(), String::new(), true);
    for c in text[start..].chars() {
        if in_string {
            match (escaped, c) {
                (true, _) => escaped = false,
                (false, '\\') => escaped = true,
                (false, '"') => in_string = false,
                _ => {}
            }
            if depth == 1 && expect_key && in_string {
                current.push(c);
            }
            continue;
        }
        match c {
            '"' => {
                in_string = true;
                current.clear();
            }
            ':' if depth == 1 && expect_key => {
                keys.push(current.clone());
                expect_key = false;
            }
            ',' if depth == 1 => expect_key = true,
            '{' | '[' => depth += 1,
            '}' | ']' => {
                depth -= 1;
                if depth == 0 {
                    break;
                }
            }
            _ => {}
        }
    }
    keys
}

/// `Predictor::response_moments` (and `output_moments`) are the response (outputs) band's mean
/// and the variance whose square root is its `sd`, bit for bit, in each
/// coefficient mode (it is the same mixture without the quantile searches), at loads inside
/// and outside the experiments' range (point load lbf, uniform load lbf/in), on records with
/// faulty gauges.
#[test]
fn response_moments_are_the_bands_moments() {
    let (model, exps) = beam_with_faulty_records();
    for (mode, cal) in in_each_mode(&model, &exps) {
        let predictor = cal.predictor(&model).unwrap();
        for xi in [[1500.0, 20.0], [8000.0, 90.0], [12_000.0, 5.0]] {
            let xi = &xi[..];
            let band = predictor.response(xi).unwrap();
            let (mean, var) = predictor.response_moments(xi).unwrap();
            assert_eq!(mean, band.mean, "{mode:?} at {xi:?}");
            let sd: Vec<f64> = var.iter().map(|v| v.sqrt()).collect();
            assert_eq!(sd, band.sd, "{mode:?} at {xi:?}");
            // the band is not degenerate: its quantiles are what response_moments skips
            assert!(band.lower.iter().zip(&band.upper).any(|(l, u)| u > l));
            // and the outputs' moments, many rows at once, are the outputs band's
            let out = predictor.outputs(xi).unwrap();
            let (m, v) = predictor
                .output_moments(&DMatrix::from_row_slice(1, xi.len(), xi))
                .unwrap();
            assert_eq!(m.row(0).iter().copied().collect::<Vec<_>>(), out.mean);
            let sd: Vec<f64> = v.row(0).iter().map(|v| v.sqrt()).collect();
            assert_eq!(sd, out.sd, "{mode:?} at {xi:?}");
        }
    }
}

/// The evidence weighing of the models with and without a discrepancy
/// ([`bamudi::posterior`]) on the beam, marginal mode:
///
/// * on strains the model class holds (`ρ A g(θ*) + b + noise`, no discrepancy) it gives the
///   model without one the larger weight, and the mixture's `θ` is nearly that model's,
///   narrower than the discrepancy model's; every prediction is the two models' mixture with
///   these weights;
/// * on the beam's records with a discrepancy the weight without one is negligible, and the
///   answer is bit for bit the one of a calibration that assumes a discrepancy.
#[test]
fn the_discrepancy_is_weighed_by_evidence_and_kept_only_where_the_data_need_it() {
    use bamudi::params::DiscrepancyPresence;
    use bamudi::{Calibrate, EstimatorParams, MarginalPrior};
    use mlmodel::{ObservableModel, UnobservableModel};
    let model = beam_app::beam_model((5.0, 25.0), 4);
    let names = (
        model.unobservable.input_names(),
        model.observable.output_names(),
    );
    let (theta_true, rho_true) = (12.3, 0.9);
    let (x, with_delta) = beam_app::simulate(40, theta_true, rho_true, 1.0, 17);
    // the same loads, strains from the model class itself
    let mut rng = beam_app::Normal64::new(23);
    let mut clean = DMatrix::zeros(x.nrows(), with_delta.ncols());
    for i in 0..x.nrows() {
        let row = model
            .model_row(&[x[(i, 0)], x[(i, 1)]], &[theta_true])
            .unwrap();
        let n_o = row.len() / 2;
        for q in 0..n_o {
            clean[(i, q)] = rho_true * row[q] + row[n_o + q] + rng.normal();
        }
    }
    let calibrate = |y: &DMatrix<f64>, presence| {
        let exps =
            Experiments::new(names.0.clone(), names.1.clone(), x.clone(), y.clone()).unwrap();
        let cfg = CalibrationParams::default()
            .estimator(EstimatorParams::ExactLinear)
            .theta_grid_points(41)
            .coefficients(bamudi::CoefficientMode::Marginal(MarginalPrior {
                presence,
                ..MarginalPrior::default()
            }))
            .check()
            .unwrap();
        Calibrate::new(&cfg).run(&model, &exps).unwrap()
    };
    let loads = [[1500.0, 20.0], [8000.0, 90.0]];

    // no discrepancy in the data
    let weighed = calibrate(&clean, DiscrepancyPresence::Weighed);
    let assumed = calibrate(&clean, DiscrepancyPresence::Assumed);
    let avg = weighed.module3().averaged().expect("weighed");
    let p0 = avg.probability_without;
    // Under no discrepancy, p0 < 1/2 needs the discrepancy model to gain more than its penalty
    // (½ ln N_s per hyper-parameter, 2 of them: ln 280 = 5.6 nats) by fitting noise: for two
    // nested parameters 2 x gain is about χ²(2), beyond 11.3 with probability 0.4 %.
    assert!(p0 > 0.5, "P(no discrepancy) = {p0}");
    let (answer, with) = (
        avg.posterior.summary(0),
        weighed.module3().posterior.summary(0),
    );
    // 4 sd: a calibrated posterior misses by more with probability 6e-5
    assert!(
        (answer.mean - theta_true).abs() < 4.0 * answer.sd,
        "{answer:?}"
    );
    assert!(answer.sd < with.sd, "answer {answer:?} vs with {with:?}");
    // the predictions are the mixture: mean (1 − p0) m1 + p0 m0, m1 the calibration that
    // assumes a discrepancy (the same Modules 2-3), m0 the fit without one
    let (p_w, p_a) = (
        weighed.predictor(&model).unwrap(),
        assumed.predictor(&model).unwrap(),
    );
    assert_eq!(p_w.probability_without(), p0);
    for xi in loads {
        let m1 = p_a.response(&xi).unwrap().mean;
        let m0 = p_w.no_discrepancy_response(&xi).unwrap().mean;
        let (mean, _) = p_w.response_moments(&xi).unwrap();
        for ((m, a), b) in mean.iter().zip(&m1).zip(&m0) {
            let want = (1.0 - p0) * a + p0 * b;
            // a sum of a few hundred weighted terms in another order: rounding only
            assert!(
                (m - want).abs() <= 1e-9 * (a.abs() + b.abs() + 1.0),
                "{m} vs {want}"
            );
        }
        // the discrepancy is zero with probability p0
        let d1 = p_a.discrepancy(&xi).unwrap().mean;
        let d = p_w.discrepancy(&xi).unwrap().mean;
        for (d, d1) in d.iter().zip(&d1) {
            assert!((d - (1.0 - p0) * d1).abs() <= 1e-12 * (d1.abs() + 1.0));
        }
        // joint draws follow the same mixture: their mean within 5 standard errors, their
        // variance within 25 % (4000 draws: the sample variance's relative sd is 2.2 % for a
        // normal, more for a mixture; 25 % is several of those and far below a missing
        // spread, which would leave the model-0 draws only the ρ and θ terms)
        let draws = p_w.response_draws(&xi, 4000, 5).unwrap();
        let band = p_w.response(&xi).unwrap();
        for j in (0..mean.len()).step_by(7) {
            let n = draws.len() as f64;
            let dm = draws.iter().map(|d| d.response[j]).sum::<f64>() / n;
            let se = band.sd[j] / n.sqrt();
            assert!(
                (dm - band.mean[j]).abs() <= 5.0 * se + 1e-9,
                "point {j}: {dm} vs {}",
                band.mean[j]
            );
            let dv = draws
                .iter()
                .map(|d| (d.response[j] - dm).powi(2))
                .sum::<f64>()
                / (n - 1.0);
            let bv = band.sd[j].powi(2);
            assert!(
                (dv - bv).abs() <= 0.25 * bv + 1e-12,
                "point {j}: variance {dv} vs {bv}"
            );
        }
    }

    // the beam's discrepancy in the data: the answer is the discrepancy model's, bit for bit
    let weighed = calibrate(&with_delta, DiscrepancyPresence::Weighed);
    let assumed = calibrate(&with_delta, DiscrepancyPresence::Assumed);
    let p0 = weighed.module3().averaged().unwrap().probability_without;
    assert!(
        p0 < bamudi::predict::NEGLIGIBLE_MODEL_WEIGHT,
        "P(no discrepancy) = {p0}"
    );
    let (p_w, p_a) = (
        weighed.predictor(&model).unwrap(),
        assumed.predictor(&model).unwrap(),
    );
    assert!(
        assumed.module3().averaged().is_none(),
        "assumed: nothing weighed"
    );
    for xi in loads {
        assert_eq!(p_w.response(&xi).unwrap(), p_a.response(&xi).unwrap());
        assert_eq!(p_w.outputs(&xi).unwrap(), p_a.outputs(&xi).unwrap());
        assert_eq!(p_w.discrepancy(&xi).unwrap(), p_a.discrepancy(&xi).unwrap());
        assert_eq!(
            p_w.response_moments(&xi).unwrap(),
            p_a.response_moments(&xi).unwrap()
        );
        let row = DMatrix::from_row_slice(1, 2, &xi);
        assert_eq!(
            p_w.output_moments(&row).unwrap(),
            p_a.output_moments(&row).unwrap()
        );
        // the same random stream: no model drawn when nothing is weighed
        assert_eq!(
            p_w.response_draws(&xi, 200, 9).unwrap(),
            p_a.response_draws(&xi, 200, 9).unwrap()
        );
    }
}
