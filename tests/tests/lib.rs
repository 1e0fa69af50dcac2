//! Workspace end-to-end tests: the whole BA-MUDI chain (Modules 2-4) on the beam-on-elastic-
//! foundation application of `crates/mlmodel/tests/apps/beam_app.rs`, with a known truth
//! `r_true = ρ g_u(x, θ*) + δ(x, d)`.

#[path = "../../crates/mlmodel/tests/apps/beam_app.rs"]
mod beam_app;

#[path = "e2e/invariants.rs"]
mod invariants;

use bamudi::{
    CalibrationParams, CoefficientMode, EstimatorParams, Experiments, RidgeParams, calibrate,
};
use beam_app::*;
use mlmodel::{LinearObservableModel, UnobservableModel};

const THETA_STAR_IN: f64 = 15.0;
const RHO_TRUE: f64 = 0.8;
const SIGMA_MICROSTRAIN: f64 = 1.0;
const PRIOR_IN: (f64, f64) = (5.0, 25.0);
const TERMS: usize = 4;

fn experiments(n_e: usize, seed: u64) -> Experiments {
    let (x, y) = simulate(n_e, THETA_STAR_IN, RHO_TRUE, SIGMA_MICROSTRAIN, seed);
    let model = BeamReaction::new(41);
    let outputs = (1..=7).map(|p| format!("gauge_{p}")).collect();
    Experiments::new(model.input_names(), outputs, x, y).unwrap()
}

fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    (s / n as f64).sqrt()
}

/// `theta_tol`: `None` requires θ* inside the 95% interval; `Some(t)` only |mean − θ*| < t
/// (for learnt estimators, whose approximation error in α̂ is not part of the Eq.-51 covariance
/// beyond what the GP white noise absorbs, so the interval can be over-confident).
fn check_calibration(
    cal: &bamudi::Calibration,
    model: &mlmodel::MultiLevelModel<BeamReaction, BeamStrain>,
    rho_tol: f64,
    theta_tol: Option<f64>,
) {
    let rho = cal.rho_star();
    let (m2, m3) = (cal.module2(), cal.module3());
    if std::env::var_os("BAMUDI_DEBUG").is_some() {
        for p in m2.rho.grid.iter().step_by(10) {
            eprintln!(
                "rho {:.2} J {:.3} S {:.3}",
                p.rho, p.objective, p.sum_squares
            );
        }
        eprintln!(
            "post with {:?} {:?} without {:?} {:?}",
            m3.posterior.mean(),
            m3.posterior.ci95(),
            m3.posterior_no_discrepancy.mean(),
            m3.posterior_no_discrepancy.ci95()
        );
    }
    // ρ is only identified up to the compensation between ρ, θ and δ (the paper finds 0.74
    // and 0.83 for a true 0.8). Here Eq. 31 averages g_u over the wide prior of θ, which
    // smears the reaction peak at the gap edge and pushes ρ* up (to the search bound 1.0 on
    // this data set); `rho_tol` states the accepted level.
    assert!((rho - RHO_TRUE).abs() < rho_tol, "rho* = {rho}");
    let post = &m3.posterior;
    let ci = post.ci95()[0];
    match theta_tol {
        None => assert!(
            ci.0 <= THETA_STAR_IN && THETA_STAR_IN <= ci.1,
            "95% CI {ci:?} misses θ* (mean {:?})",
            post.mean()
        ),
        Some(t) => assert!(
            (post.mean()[0] - THETA_STAR_IN).abs() < t,
            "posterior mean {:?}",
            post.mean()
        ),
    }
    let with = (post.mean()[0] - THETA_STAR_IN).abs();
    let without = (m3.posterior_no_discrepancy.mean()[0] - THETA_STAR_IN).abs();
    assert!(
        with < without,
        "with discrepancy |err| {with} not below without {without}"
    );

    // Module 4 at new inputs (Fig. 17-20): strains and reactions, BA-MUDI vs the uncorrected
    // model (ρ = 1, no δ, θ at the no-discrepancy posterior mean).
    let theta_nd = m3.posterior_no_discrepancy.mean();
    let predictor = cal.predictor(model).unwrap();
    let mut g = Normal64::new(4242);
    let (mut strain_err, mut strain_err_nd, mut strain_disc) = (Vec::new(), Vec::new(), Vec::new());
    let (mut resp_err, mut resp_err_nd) = (Vec::new(), Vec::new());
    for _ in 0..10 {
        let x = [
            P_RANGE_LBF.0 + (P_RANGE_LBF.1 - P_RANGE_LBF.0) * g.uniform(),
            Q_RANGE_LBF_PER_IN.0 + (Q_RANGE_LBF_PER_IN.1 - Q_RANGE_LBF_PER_IN.0) * g.uniform(),
        ];
        let truth = true_reaction(&model.unobservable, &x, THETA_STAR_IN, RHO_TRUE);
        let delta: Vec<f64> = model
            .unobservable
            .coordinates()
            .iter()
            .map(|&d| true_discrepancy(&x, d, THETA_STAR_IN))
            .collect();
        let mut nd = vec![0.0; 41];
        model.unobservable.evaluate(&x, &theta_nd, &mut nd).unwrap();
        let strain = |r: &[f64]| -> Vec<f64> {
            let mut out = vec![0.0; 7];
            mlmodel::ObservableModel::evaluate(
                &model.observable,
                &x,
                &[THETA_STAR_IN],
                r,
                &mut out,
            )
            .unwrap();
            out
        };
        let (s_true, s_nd) = (strain(&truth), strain(&nd));
        let a_delta = model.observable.matrix() * nalgebra::DVector::from_column_slice(&delta);
        let band = predictor.outputs(&x).unwrap();
        for p in 0..7 {
            strain_err.push(band.mean[p] - s_true[p]);
            strain_err_nd.push(s_nd[p] - s_true[p]);
            strain_disc.push(a_delta[p]);
            assert!(band.lower[p] <= band.mean[p] + 1e-9 && band.mean[p] <= band.upper[p] + 1e-9);
        }
        let resp = predictor.response(&x).unwrap();
        for b in 0..41 {
            resp_err.push(resp.mean[b] - truth[b]);
            resp_err_nd.push(nd[b] - truth[b]);
        }
    }
    let (e, e_nd, d) = (
        rms(strain_err.into_iter()),
        rms(strain_err_nd.into_iter()),
        rms(strain_disc.into_iter()),
    );
    let (r, r_nd) = (rms(resp_err.into_iter()), rms(resp_err_nd.into_iter()));
    if std::env::var_os("BAMUDI_DEBUG").is_some() {
        eprintln!(
            "strain RMS err {e} (uncorrected {e_nd}, A delta {d}); reaction RMS err {r} (uncorrected {r_nd})"
        );
    }
    if theta_tol.is_none() {
        // exact estimator: "well below the discrepancy itself", a third of the discrepancy's
        // strain effect and of the uncorrected model's error
        assert!(
            e < d / 3.0 && e < e_nd / 3.0,
            "strain RMS error {e} vs A·δ {d} and uncorrected {e_nd} (microstrain)"
        );
    } else {
        // learnt estimator (known weakness, see the crate docs): only better than uncorrected
        assert!(
            e < e_nd,
            "strain RMS error {e} vs uncorrected {e_nd} (microstrain)"
        );
    }
    assert!(
        r < r_nd,
        "reaction RMS error {r} vs uncorrected {r_nd} (lbf/in)"
    );
}

/// The paper's Module 3 on the beam. This test was written for it and stays on it. In the
/// default (marginal) mode the same data set gives the 95 % interval [15.33, 15.90] in with
/// θ* = 15 (mean 2.3 sd off): measured when the default changed and left as a known miss of
/// the marginal mode on this application (one data set cannot measure coverage; the coverage
/// study on the gate does, and the beam has no such study yet).
#[test]
fn beam_calibration_with_the_exact_estimator_recovers_the_truth() {
    let model = beam_model(PRIOR_IN, TERMS);
    let exps = experiments(60, 1);
    let cfg = CalibrationParams::default()
        .coefficients(CoefficientMode::PriorMarginal)
        .estimator(EstimatorParams::ExactLinear)
        .sigma_eps(Some(SIGMA_MICROSTRAIN))
        .theta_grid_points(101)
        .gp_restarts(1)
        .seed(3)
        .check()
        .unwrap();
    let cal = calibrate(&model, &exps, &cfg).unwrap();
    check_calibration(&cal, &model, 0.21, None);
    // the grid posterior is a density
    if let bamudi::ThetaPosterior::Grid(g) = &cal.module3().posterior {
        assert!((g.cdf.last().unwrap() - 1.0).abs() < 1e-12);
    }
    // serialisable, and the same seed reproduces the same numbers
    let path = std::env::temp_dir().join(format!("bamudi_e2e_{}.json", std::process::id()));
    cal.save(&path).unwrap();
    let back = bamudi::Calibration::load(&path).unwrap();
    assert_eq!(back.module2().rho, cal.module2().rho);
    let again = calibrate(&model, &exps, &cfg).unwrap();
    assert_eq!(again.module3().posterior, cal.module3().posterior);
    // Module 4 refuses a model that is not the calibrated one
    let other = beam_model(PRIOR_IN, TERMS + 1);
    assert!(back.predictor(&other).is_err());
}

#[test]
fn beam_calibration_with_the_smartcore_ridge_estimator() {
    let model = beam_model(PRIOR_IN, TERMS);
    let exps = experiments(60, 2);
    let cfg = CalibrationParams::default()
        .estimator(EstimatorParams::Ridge(RidgeParams { lambda: 1e-6 }))
        .training_size(3000)
        .sigma_eps(Some(SIGMA_MICROSTRAIN))
        .theta_grid_points(101)
        .gp_restarts(1)
        .seed(4)
        .check()
        .unwrap();
    let cal = calibrate(&model, &exps, &cfg).unwrap();
    assert_eq!(cal.module2().training_pool_size, 300);
    // 1 in = 5% of the prior width
    check_calibration(&cal, &model, 0.21, Some(1.0));
}

#[test]
fn rho_is_recovered_when_theta_is_nearly_known() {
    // With the prior collapsed around θ*, Eq. 31 no longer smears g_u over θ, so the only
    // confounding left is the part of δ outside the span of the Legendre basis.
    let model = beam_model((THETA_STAR_IN - 0.1, THETA_STAR_IN + 0.1), TERMS);
    let exps = experiments(60, 5);
    let cfg = CalibrationParams::default()
        .estimator(EstimatorParams::ExactLinear)
        .sigma_eps(Some(SIGMA_MICROSTRAIN))
        .theta_grid_points(21)
        .gp_restarts(0)
        .check()
        .unwrap();
    let cal = calibrate(&model, &exps, &cfg).unwrap();
    let rho = cal.rho_star();
    // Standard error of ρ from the curvature of the sum of squares S(ρ) ≈ S_min + c (ρ − ρ̂)²:
    // sd(ρ̂) ≈ σ_ε / √c. Allow three standard errors.
    let g = &cal.module2().rho.grid;
    let (a, m, b) = (g[50].sum_squares, g[70].sum_squares, g[90].sum_squares);
    let c = (a - 2.0 * m + b) / (2.0 * 0.2f64.powi(2));
    let sd = SIGMA_MICROSTRAIN / c.sqrt();
    assert!((rho - RHO_TRUE).abs() < 3.0 * sd, "rho* = {rho}, sd {sd}");
}

/// A prediction model that returns the response itself (the third level as the identity).
struct Echo(usize);

impl mlmodel::PredictionModel for Echo {
    fn output_names(&self) -> Vec<String> {
        (0..self.0).map(|i| format!("r{i}")).collect()
    }
    fn evaluate(&self, _: &[f64], _: &[f64], y_u: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        out.copy_from_slice(y_u);
        Ok(())
    }
}

/// The prediction level's joint draws (`Predictor::predict_through`) reproduce Module 4's
/// mixture (Eq. 52) point by point: pushed through the identity, their mean and sd equal the
/// response band's. Monte-Carlo error of 4,000 draws: the mean within 5 standard errors
/// (`5 sd / √n`), the sd within 10 % (its relative error is about `1/√(2n)` = 1.1 % for a
/// Gaussian, larger for the heavier-tailed θ mixture); bands in the default (marginal) mode,
/// which carries θ, ρ and the coefficients' full covariance.
#[test]
fn prediction_draws_reproduce_the_module4_mixture() {
    let model = beam_model(PRIOR_IN, TERMS);
    let exps = experiments(60, 1);
    let cfg = CalibrationParams::default()
        .estimator(EstimatorParams::ExactLinear)
        .sigma_eps(Some(SIGMA_MICROSTRAIN))
        .theta_grid_points(101)
        .gp_restarts(1)
        .seed(3)
        .check()
        .unwrap();
    let cal = calibrate(&model, &exps, &cfg).unwrap();
    let predictor = cal.predictor(&model).unwrap();
    let x = exps.x.row(7).iter().copied().collect::<Vec<f64>>();
    let band = predictor.response(&x).unwrap();
    let n = 4000;
    let echo = Echo(band.mean.len());
    let drawn = predictor.predict_through(&echo, &x, n, 11).unwrap();
    let again = predictor.predict_through(&echo, &x, n, 11).unwrap();
    assert_eq!(drawn, again, "the same seed gives the same band");
    for p in 0..band.mean.len() {
        let (m, sd) = (band.mean[p], band.sd[p]);
        let tol = 5.0 * sd / (n as f64).sqrt() + 1e-9 * m.abs().max(1.0);
        assert!(
            (drawn.mean[p] - m).abs() <= tol,
            "point {p}: mean {} vs {m}",
            drawn.mean[p]
        );
        assert!(
            (drawn.sd[p] - sd).abs() <= 0.1 * sd + 1e-9,
            "point {p}: sd {} vs {sd}",
            drawn.sd[p]
        );
    }
    assert!(
        predictor.predict_through(&echo, &x, 10, 1).is_err(),
        "too few draws"
    );
    // paths index the support of the predictor that drew them: another calibration's (a
    // coarser θ grid) are refused with an error, not an out-of-bounds panic
    let coarser = CalibrationParams::from(cfg.clone())
        .theta_grid_points(21)
        .check()
        .unwrap();
    let other = calibrate(&model, &exps, &coarser).unwrap();
    let foreign = other.predictor(&model).unwrap().draw_paths(50, 1);
    let err = predictor.draws_at(&foreign, &x).unwrap_err();
    assert!(err.to_string().contains("another predictor"), "{err}");
    assert_eq!(
        predictor
            .draws_at(&predictor.draw_paths(50, 1), &x)
            .unwrap()
            .len(),
        50
    );
}

#[path = "e2e/reproduce_quick.rs"]
mod reproduce_quick;

/// `n_e` experiments from a beam built `stiffness` x its drawing's `EI`, with no discrepancy
/// on the reaction side (`r = ρ g_u(x, θ*)`), `N(0, σ²)` noise.
fn as_built_experiments(n_e: usize, theta: f64, stiffness: f64, seed: u64) -> Experiments {
    as_built_strains(n_e, theta, stiffness, SIGMA_MICROSTRAIN, seed)
}

/// As [`as_built_experiments`], with noise of sd `noise` (microstrain; 0: the true strains).
fn as_built_strains(n_e: usize, theta: f64, stiffness: f64, noise: f64, seed: u64) -> Experiments {
    let reaction = BeamReaction::new(41);
    let strain = BeamStrain::with_stiffness(&reaction, stiffness);
    let mut g = Normal64::new(seed);
    let mut x = nalgebra::DMatrix::zeros(n_e, 2);
    let mut y = nalgebra::DMatrix::zeros(n_e, GAUGES_IN.len());
    for i in 0..n_e {
        let p = P_RANGE_LBF.0 + (P_RANGE_LBF.1 - P_RANGE_LBF.0) * g.uniform();
        let q = Q_RANGE_LBF_PER_IN.0 + (Q_RANGE_LBF_PER_IN.1 - Q_RANGE_LBF_PER_IN.0) * g.uniform();
        let mut r = vec![0.0; 41];
        reaction.evaluate(&[p, q], &[theta], &mut r).unwrap();
        r.iter_mut().for_each(|v| *v *= RHO_TRUE);
        let mut out = vec![0.0; GAUGES_IN.len()];
        mlmodel::ObservableModel::evaluate(&strain, &[p, q], &[theta], &r, &mut out).unwrap();
        x[(i, 0)] = p;
        x[(i, 1)] = q;
        for (j, o) in out.iter().enumerate() {
            y[(i, j)] = o + noise * g.normal();
        }
    }
    let outputs = (1..=7).map(|p| format!("gauge_{p}")).collect();
    Experiments::new(reaction.input_names(), outputs, x, y).unwrap()
}

/// The beam model with its flexural rigidity declared to a relative sd `sd`, or the drawing
/// alone (`None`).
fn beam_with_tolerance(sd: Option<f64>) -> mlmodel::MultiLevelModel<BeamReaction, BeamStrain> {
    let model = beam_model(PRIOR_IN, TERMS);
    let Some(sd) = sd else { return model };
    let r = BeamReaction::new(41);
    model
        .with_tolerances(vec![mlmodel::BuildTolerance {
            name: "EI".into(),
            low: BeamStrain::with_stiffness(&r, 1.0 - sd),
            high: BeamStrain::with_stiffness(&r, 1.0 + sd),
            responses: None,
        }])
        .unwrap()
}

/// A reality the model does not contain: the beam as built is 6 % softer than its drawing
/// (`EI x 0.94`, every strain 6.4 % larger, the reaction's and the loads' alike; no
/// discrepancy on the reaction side, so a miss is the build's). Six data sets with `θ*`
/// spread over the prior, each calibrated with the drawing in the default (marginal) mode:
/// * with `EI` declared to a relative sd of 4 % (the truth 1.5 sd off), the 95 % interval
///   holds `θ*` in at least 5 of 6 (at the nominal 0.95 the chance of 4 or fewer is 3 %),
///   the posterior of the deviation lies within 0.5 of the truth's −1.5 sd (its own sd is
///   about 0.08 given `θ̂`, `ρ̄`; the central difference's linearisation moves it by about
///   0.09 at 1.5 sd) and the verdict is adequate in at least 5 of 6 (a 1.5 sd build passes
///   its `build_tolerance` test, p 0.13);
/// * without, the same data's intervals miss in at least 4 of 6 — the check that this
///   reality matters (measured when written: 5 of 6 miss, every verdict inadequate);
/// * a build far outside its tolerance (`EI x 0.80`, 5 sd) is named: `build_tolerance`
///   fails and is attributed to the model's form.
///
/// Measured when written (`cargo test -p bamudi-e2e --test lib a_declared_build -- --nocapture`):
/// declared, 6 of 6 cover, deviations −1.39 to −1.66 sd.
#[test]
fn a_declared_build_tolerance_keeps_the_interval_on_a_softer_beam() {
    let n = 6;
    let (mut covered, mut adequate, mut missed_without) = (0, 0, 0);
    let cfg = |seed| {
        CalibrationParams::default()
            .estimator(EstimatorParams::ExactLinear)
            .theta_grid_points(101)
            .gp_restarts(1)
            .seed(seed)
            .check()
            .unwrap()
    };
    let (declared, drawing) = (beam_with_tolerance(Some(0.04)), beam_with_tolerance(None));
    for k in 0..n {
        let theta = PRIOR_IN.0 + (PRIOR_IN.1 - PRIOR_IN.0) * (k as f64 + 0.5) / n as f64;
        let exps = as_built_experiments(60, theta, 0.94, 100 + k as u64);
        let cal = calibrate(&declared, &exps, &cfg(k as u64)).unwrap();
        let (lo, hi) = cal.module3().posterior.ci95()[0];
        covered += usize::from(lo <= theta && theta <= hi);
        let tol = &cal.module3().marginal().unwrap().tolerances[0];
        assert!(
            (tol.mean + 1.5).abs() < 0.5 && tol.sd < 0.5,
            "θ* {theta}: EI's deviation {} ± {} sd, truth −1.5",
            tol.mean,
            tol.sd
        );
        adequate += usize::from(cal.adequacy().unwrap().verdict == bamudi::Verdict::Adequate);
        let plain = calibrate(&drawing, &exps, &cfg(k as u64)).unwrap();
        let (lo, hi) = plain.module3().posterior.ci95()[0];
        missed_without += usize::from(!(lo <= theta && theta <= hi));
    }
    assert!(covered >= 5, "declared: {covered} of {n} intervals hold θ*");
    assert!(adequate >= 5, "declared: {adequate} of {n} adequate");
    assert!(
        missed_without >= 4,
        "without: only {missed_without} of {n} miss"
    );
    let exps = as_built_experiments(60, 15.0, 0.80, 7);
    let cal = calibrate(&declared, &exps, &cfg(7)).unwrap();
    let ad = cal.adequacy().unwrap();
    let named = ad.failed.iter().find(|f| f.check == "build_tolerance");
    assert!(
        named.is_some_and(|f| f.attribution == bamudi::adequacy::Attribution::ModelForm),
        "{}",
        ad.summary()
    );
}

/// Module 4 carries a declared tolerance's reading into its predictions. The reality is the
/// one above that the model lacks (the beam 6 % softer than drawn; `EI`'s declared sd 4 %, so
/// the truth is −1.5 sd off). Three calibrations (60 noisy experiments each, `θ*` at 1/6, 1/2
/// and 5/6 of the prior); at 40 new loads from the same as-built beam the true (noise-free)
/// strains must lie inside the 95 % output bands at ≥ 90 % of the 3 x 40 x 7 (load, gauge)
/// pairs (nominal 95 %; the bound leaves room for the θ mixture's and the linearisation's
/// approximations, not for a missing deviation), the predicted means within half the noise
/// sd of them (root mean square), and the joint draws' response must agree with the response
/// band (the tolerance leaves the reaction alone here, so `R = 0`: the draws change only
/// through the joint covariance with `η`, which must leave them equal).
///
/// Measured when written (`cargo test -p bamudi-e2e --test lib module4_carries -- --nocapture`):
/// the bands hold 840 of 840 true strains, RMSE 0.109 microstrain (predicted sd 0.387: the
/// coefficients' posterior spread, which this truth, with no discrepancy, does not use). The
/// same test on the commit before Module 4 carried the tolerances: 38 of 840 (0.045), RMSE
/// 5.30 microstrain — the deviation Module 3 had read (−1.5 sd) left out of the predictions.
#[test]
fn module4_carries_a_declared_tolerance_into_its_predictions() {
    let declared = beam_with_tolerance(Some(0.04));
    let (mut inside, mut total, mut sq_err, mut sq_sd) = (0usize, 0usize, 0.0, 0.0);
    for k in [1usize, 3, 5] {
        let theta = PRIOR_IN.0 + (PRIOR_IN.1 - PRIOR_IN.0) * k as f64 / 6.0;
        let exps = as_built_experiments(60, theta, 0.94, 200 + k as u64);
        let cfg = CalibrationParams::default()
            .estimator(EstimatorParams::ExactLinear)
            .theta_grid_points(101)
            .gp_restarts(1)
            .seed(k as u64)
            .check()
            .unwrap();
        let cal = calibrate(&declared, &exps, &cfg).unwrap();
        let truth = as_built_strains(40, theta, 0.94, 0.0, 300 + k as u64);
        let predictor = cal.predictor(&declared).unwrap();
        let (mean, var) = predictor.output_moments(&truth.x).unwrap();
        for i in 0..truth.x.nrows() {
            let xi: Vec<f64> = truth.x.row(i).iter().copied().collect();
            let band = predictor.outputs(&xi).unwrap();
            for q in 0..truth.y.ncols() {
                let y = truth.y[(i, q)];
                inside += usize::from(band.lower[q] <= y && y <= band.upper[q]);
                total += 1;
                sq_err += (mean[(i, q)] - y).powi(2);
                sq_sd += var[(i, q)];
                // the two entry points compute the same mixture
                assert!((band.mean[q] - mean[(i, q)]).abs() <= 1e-9 * y.abs().max(1.0));
            }
        }
        let xi: Vec<f64> = truth.x.row(0).iter().copied().collect();
        let band = predictor.response(&xi).unwrap();
        let echo = Echo(band.mean.len());
        let drawn = predictor.predict_through(&echo, &xi, 4000, 5).unwrap();
        for p in 0..band.mean.len() {
            let (m, sd) = (band.mean[p], band.sd[p]);
            // Monte-Carlo error of 4,000 draws, as in prediction_draws_reproduce_the_module4_mixture
            assert!(
                (drawn.mean[p] - m).abs() <= 5.0 * sd / 4000f64.sqrt() + 1e-9 * m.abs().max(1.0)
            );
            assert!((drawn.sd[p] - sd).abs() <= 0.1 * sd + 1e-9);
        }
    }
    let coverage = inside as f64 / total as f64;
    eprintln!(
        "declared tolerance, Module 4: 95 % output bands hold {inside} of {total} true strains \
         ({coverage:.3}); RMSE {:.3} microstrain against a predicted sd of {:.3}",
        (sq_err / total as f64).sqrt(),
        (sq_sd / total as f64).sqrt()
    );
    assert!(coverage >= 0.90, "coverage {coverage}");
    let rmse = (sq_err / total as f64).sqrt();
    assert!(rmse < 0.5 * SIGMA_MICROSTRAIN, "RMSE {rmse} microstrain");
}
