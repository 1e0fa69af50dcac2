//! The orchestration of Modules 2-4 ([`calibrate`]) and the calibrated model ([`Calibration`]).

use crate::conditional::{ConditionalCoefficients, ModelRows, RhoProfile};
use crate::config::{CalibrationConfig, CoefficientMode, EstimatorConfig};
use crate::error::{BamudiError, Result};
use crate::estimator::{
    CoefficientEstimator, ExactLinearEstimator, FittedEstimator, LstmEstimator, LstmSettings,
    RidgeEstimator,
};
use crate::experiments::Experiments;
use crate::likelihood::{FactorReport, FactoredCovariance, assemble_covariance, iid_log_density};
use crate::mcmc::{McmcResult, adaptive_metropolis};
use crate::posterior::GridPosterior;
use crate::rho::{RhoCurve, estimate_rho};
use crate::surrogate::CoefficientGps;
use crate::training::{self, LinearParts, XContext, derive_seed, progress_bar};
use faer::Par;
use mlmodel::{LinearObservableModel, MultiLevelModel, QuadratureRule, UnobservableModel};
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Wall-clock seconds spent in each step.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Timings {
    /// Module 2: training-set generation (Eq. 27).
    pub training_set_s: f64,
    /// Module 2: fitting the coefficient estimator (Eq. 29).
    pub estimator_s: f64,
    /// Module 2: `ρ*` search and `α̂` (Eq. 30-32).
    pub rho_s: f64,
    /// Module 2: coefficient GPs (Eq. 33-37).
    pub gp_s: f64,
    /// Module 3: covariance factorisation and posterior of `θ` (both variants).
    pub module3_s: f64,
}

/// Posterior of `θ`: exact grid quadrature for one dimension, MCMC otherwise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "method", rename_all = "snake_case")]
pub enum ThetaPosterior {
    /// One-dimensional grid posterior.
    Grid(GridPosterior),
    /// Multi-dimensional MCMC posterior.
    Mcmc(McmcResult),
}

impl ThetaPosterior {
    /// Posterior mean per dimension.
    pub fn mean(&self) -> Vec<f64> {
        match self {
            Self::Grid(g) => vec![g.mean],
            Self::Mcmc(m) => m.mean.clone(),
        }
    }
    /// Posterior standard deviation per dimension.
    pub fn sd(&self) -> Vec<f64> {
        match self {
            Self::Grid(g) => vec![g.sd],
            Self::Mcmc(m) => (0..m.mean.len()).map(|j| m.cov[(j, j)].sqrt()).collect(),
        }
    }
    /// Equal-tailed 95% credible interval per dimension.
    pub fn ci95(&self) -> Vec<(f64, f64)> {
        match self {
            Self::Grid(g) => vec![g.ci95],
            Self::Mcmc(m) => m.ci95.clone(),
        }
    }
    /// Weighted support points for mixtures (Module 4): grid nodes carrying all but `1e-9` of
    /// the mass (renormalised), or at most `max_draws` evenly thinned MCMC draws.
    pub fn support(&self, max_draws: usize) -> Vec<(Vec<f64>, f64)> {
        match self {
            Self::Grid(g) => {
                let masses = g.masses();
                let mut idx: Vec<usize> = (0..masses.len()).collect();
                idx.sort_by(|a, b| masses[*b].total_cmp(&masses[*a]));
                let mut kept = Vec::new();
                let mut acc = 0.0;
                for i in idx {
                    if acc >= 1.0 - 1e-9 {
                        break;
                    }
                    acc += masses[i];
                    kept.push((vec![g.theta[i]], masses[i]));
                }
                kept.iter_mut().for_each(|k| k.1 /= acc);
                kept
            }
            Self::Mcmc(m) => {
                let all: Vec<&Vec<f64>> = m.chains.iter().flatten().collect();
                let step = all.len().div_ceil(max_draws.max(1)).max(1);
                let pts: Vec<Vec<f64>> = all.iter().step_by(step).map(|p| (*p).clone()).collect();
                let w = 1.0 / pts.len() as f64;
                pts.into_iter().map(|p| (p, w)).collect()
            }
        }
    }
}

/// The result of a BA-MUDI calibration (serialisable; see [`crate::report`] for the files).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Calibration {
    /// The configuration used.
    pub config: CalibrationConfig,
    /// Input names (from the experiments).
    pub input_names: Vec<String>,
    /// Output names (from the experiments).
    pub output_names: Vec<String>,
    /// Input box used for the training set.
    pub x_bounds: Vec<(f64, f64)>,
    /// Nodes/weights that marginalise `θ` in Module 2.
    pub theta_rule: QuadratureRule,
    /// `A`, `L`, `B = A L`.
    pub parts: LinearParts,
    /// Distinct `x` values in the training set (0 for the exact estimator, which needs none).
    pub training_pool_size: usize,
    /// The fitted estimator of Eq. 29.
    pub estimator: FittedEstimator,
    /// The `ρ` search (Eq. 30) with its curve.
    pub rho: RhoCurve,
    /// `α̂` at the experiments (Eq. 32), `N_e x K`.
    pub alpha_hat: DMatrix<f64>,
    /// Experiment inputs (for plots of the GP fits).
    pub x_experiments: DMatrix<f64>,
    /// The coefficient GPs (Eq. 33-37).
    pub gps: CoefficientGps,
    /// [`CoefficientMode::ConditionalOnTheta`] only: smoother weights (`N_e x K`, see
    /// [`ConditionalCoefficients::weights`]) of the posterior-averaged coefficient change
    /// `E_θ[α̂(θ)] − α̂`; the GP mean at `x` becomes `μ_k(x) + Σ_k(x, X) w_k`. `alpha_hat`
    /// then holds `E_θ[α̂(θ)]`.
    #[serde(default)]
    pub alpha_correction: Option<DMatrix<f64>>,
    /// [`CoefficientMode::ConditionalOnTheta`] only: the profile search that set `rho.rho_star`
    /// (the Eq.-30 value is kept inside it).
    #[serde(default)]
    pub rho_profile: Option<RhoProfile>,
    /// `σ_ε` used in Module 3.
    pub sigma_eps: f64,
    /// Whether `σ_ε` was estimated (see [`estimate_sigma`]) rather than configured.
    pub sigma_eps_estimated: bool,
    /// Factorisation of the Eq.-51 covariance.
    pub covariance: FactorReport,
    /// Posterior of `θ` with the discrepancy model (Eq. 38-43).
    pub posterior: ThetaPosterior,
    /// Posterior of `θ` without discrepancy (`ρ = 1`, `δ = 0`, `V = σ_ε² I`; Fig. 16).
    pub posterior_no_discrepancy: ThetaPosterior,
    /// Seconds per step.
    pub timings: Timings,
}

/// A distributed or output prediction with its 95% credible band.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Band {
    /// Posterior predictive mean.
    pub mean: Vec<f64>,
    /// Posterior predictive standard deviation.
    pub sd: Vec<f64>,
    /// 2.5% quantile.
    pub lower: Vec<f64>,
    /// 97.5% quantile.
    pub upper: Vec<f64>,
}

fn check_data<U: UnobservableModel, O: LinearObservableModel>(
    model: &MultiLevelModel<U, O>,
    exps: &Experiments,
) -> Result<()> {
    if exps.x.ncols() != model.unobservable.input_dim() {
        return Err(BamudiError::dim(
            "experiment inputs vs model inputs",
            model.unobservable.input_dim(),
            exps.x.ncols(),
        ));
    }
    if exps.y.ncols() != model.observable.output_dim() {
        return Err(BamudiError::dim(
            "experiment outputs vs model outputs",
            model.observable.output_dim(),
            exps.y.ncols(),
        ));
    }
    if exps.len() < 3 {
        return Err(BamudiError::dim(
            "number of experiments (at least 3)",
            3,
            exps.len(),
        ));
    }
    Ok(())
}

fn x_row(x: &DMatrix<f64>, i: usize) -> Vec<f64> {
    x.row(i).iter().copied().collect()
}

/// Module-2 prior-averaged contexts at the rows of `x`.
pub fn contexts<U: UnobservableModel, O: LinearObservableModel>(
    model: &MultiLevelModel<U, O>,
    parts: &LinearParts,
    rule: &QuadratureRule,
    cfg: &CalibrationConfig,
    x: &DMatrix<f64>,
) -> Result<Vec<XContext>> {
    (0..x.nrows())
        .into_par_iter()
        .map(|i| training::x_context(model, parts, rule, &cfg.sampling, &x_row(x, i)))
        .collect()
}

/// Estimated `σ_ε` when the configuration gives none: the root-mean-square residual of the
/// Module-2 corrected prediction at `ρ*` with the GP-mean coefficients and `θ` averaged over
/// its prior, `σ̂² = Σ_i ‖y_i − ρ* A ḡ(x_i) − b̄(x_i) − B μ_α(x_i)‖² / (N_e N_o)`. It is
/// conservative (too large): the residual also carries the prior-averaging of `θ` and the GP
/// smoothing error.
pub fn estimate_sigma(
    y: &DMatrix<f64>,
    rho: f64,
    ctx: &[XContext],
    parts: &LinearParts,
    mu_alpha: &DMatrix<f64>,
) -> f64 {
    let pred = crate::rho::predicted_outputs(rho, mu_alpha, ctx, parts);
    let ss: f64 = (y - pred).iter().map(|r| r * r).sum();
    (ss / (y.nrows() * y.ncols()) as f64).sqrt()
}

/// Runs Modules 2-3 of BA-MUDI for a linear observable model; Module 4 is then available as
/// [`Calibration::predict_response`] / [`Calibration::predict_outputs`].
pub fn calibrate<U, O>(
    model: &MultiLevelModel<U, O>,
    exps: &Experiments,
    cfg: &CalibrationConfig,
) -> Result<Calibration>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    cfg.validate()?;
    check_data(model, exps)?;
    let mut timings = Timings::default();
    let bounds = match &cfg.sampling.x_bounds {
        Some(b) => b.clone(),
        None => exps
            .input_bounds()
            .into_iter()
            .map(|(lo, hi)| {
                if hi > lo {
                    (lo, hi)
                } else {
                    (lo - 0.5 * lo.abs().max(1.0), hi + 0.5 * hi.abs().max(1.0))
                }
            })
            .collect(),
    };
    let theta_rule = training::theta_rule(
        model.prior.as_ref(),
        &cfg.marginalisation,
        derive_seed(cfg.seed, 1),
    )?;
    let parts = LinearParts::new(model)?;

    // Module 2a: training set and estimator
    let t = Instant::now();
    let training = match cfg.estimator {
        EstimatorConfig::ExactLinear => None,
        _ => Some(training::generate_linear(
            model,
            &parts,
            &theta_rule,
            &cfg.sampling,
            &bounds,
            cfg.training_size,
            derive_seed(cfg.seed, 2),
            cfg.progress,
        )?),
    };
    timings.training_set_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let estimator = match (&cfg.estimator, &training) {
        (EstimatorConfig::ExactLinear, _) => FittedEstimator::ExactLinear(
            ExactLinearEstimator::from_parts(&parts, cfg.sampling.noise_sd)?,
        ),
        (EstimatorConfig::Ridge { lambda }, Some(tr)) => {
            FittedEstimator::Ridge(RidgeEstimator::fit(tr, *lambda)?)
        }
        (
            EstimatorConfig::Lstm {
                hidden,
                layers,
                steps,
                epochs,
                batch_size,
                learning_rate,
                validation_fraction,
                patience,
            },
            Some(tr),
        ) => {
            let settings = LstmSettings {
                hidden: *hidden,
                layers: *layers,
                steps: *steps,
                epochs: *epochs,
                batch_size: *batch_size,
                learning_rate: *learning_rate,
                validation_fraction: *validation_fraction,
                patience: *patience,
            };
            FittedEstimator::Lstm(Box::new(LstmEstimator::fit(
                tr,
                &settings,
                derive_seed(cfg.seed, 6),
                cfg.progress,
            )?))
        }
        (_, None) => unreachable!("a training set is generated for every learnt estimator"),
    };
    timings.estimator_s = t.elapsed().as_secs_f64();
    let pool = training.as_ref().map_or(0, |t| t.pool_size);
    drop(training);
    finish_calibration(
        model, exps, cfg, bounds, theta_rule, parts, pool, estimator, timings,
    )
}

/// Modules 2b-3 given a fitted estimator (shared by [`calibrate`] and re-runs that load a
/// saved estimator).
pub fn finish_calibration<U, O>(
    model: &MultiLevelModel<U, O>,
    exps: &Experiments,
    cfg: &CalibrationConfig,
    x_bounds: Vec<(f64, f64)>,
    theta_rule: QuadratureRule,
    parts: LinearParts,
    training_pool_size: usize,
    estimator: FittedEstimator,
    mut timings: Timings,
) -> Result<Calibration>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    // Module 2b: ρ*, α̂, GPs
    let t = Instant::now();
    let ctx = contexts(model, &parts, &theta_rule, cfg, &exps.x)?;
    let mut rho = estimate_rho(&estimator, &exps.x, &exps.y, &ctx, &parts, &cfg.rho)?;
    let mut alpha_hat = estimator.predict(rho.rho_star, &exps.x, &exps.y, &ctx)?;
    timings.rho_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let fit_gps = |alpha: &DMatrix<f64>| {
        CoefficientGps::fit(&exps.x, alpha, cfg.gp_restarts, derive_seed(cfg.seed, 3))
    };
    let mut gps = fit_gps(&alpha_hat)?;
    timings.gp_s = t.elapsed().as_secs_f64();
    let mut gp_moments = GpMoments::of(&gps, &exps.x)?;

    // Conditional mode: ρ by the profile search, then the GPs refitted to α̂(ρ*, θ̂)
    let mut rho_profile = None;
    let mut candidate_rows = Vec::new();
    if cfg.coefficients == CoefficientMode::ConditionalOnTheta {
        let t = Instant::now();
        candidate_rows = sigma_candidates(model, cfg)
            .par_iter()
            .map(|theta| model_rows(model, exps, &parts, theta))
            .collect::<Result<Vec<_>>>()?;
        let cc = gp_moments.conditional(&estimator, &ctx, exps, &alpha_hat)?;
        let mut profile = cc.profile_rho(&candidate_rows, &parts.b, &cfg.rho, rho.rho_star)?;
        if let Some(bracket) = neighbour_bracket(model, cfg, &profile.theta_star) {
            let rows_at = |t: f64| model_rows(model, exps, &parts, &[t]);
            if let Some(rows) =
                cc.refine_scalar_theta(&mut profile, bracket, rows_at, &parts.b, &cfg.rho)?
            {
                candidate_rows.push(rows);
            }
        }
        let best = candidate_rows
            .iter()
            .find(|r| r.theta == profile.theta_star)
            .ok_or_else(|| BamudiError::Numerical {
                context: "rho profile".into(),
                reason: "best theta candidate not found".into(),
            })?;
        let base = cc.alpha(profile.rho_star, &best.ag, &best.b)?;
        drop(cc);
        timings.rho_s += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let refit = fit_gps(&base)?;
        let refit_moments = GpMoments::of(&refit, &exps.x)?;
        profile.rms_after_refit = refit_moments
            .conditional(&estimator, &ctx, exps, &base)?
            .rms(profile.rho_star, best, &parts.b)?;
        timings.gp_s += t.elapsed().as_secs_f64();
        // Kept only if it fits at least as well: B mixes the coefficients, and a refit that
        // interpolates some of them and smooths others can fit worse than the Module-2 GPs.
        if profile.refit_kept() {
            (gps, gp_moments, alpha_hat) = (refit, refit_moments, base);
        } else {
            eprintln!(
                "bamudi: GP refit at rho* = {:.4}, theta = {:?} fits worse ({:.4} vs {:.4} RMS); \
                 keeping the Module-2 GPs",
                profile.rho_star, profile.theta_star, profile.rms_after_refit, profile.rms_at_star
            );
        }
        rho.rho_star = profile.rho_star;
        rho_profile = Some(profile);
    }

    // Module 3
    let t = Instant::now();
    let conditional = match cfg.coefficients {
        CoefficientMode::PriorMarginal => None,
        CoefficientMode::ConditionalOnTheta => {
            Some(gp_moments.conditional(&estimator, &ctx, exps, &alpha_hat)?)
        }
    };
    let (sigma_eps, sigma_eps_estimated) = match (cfg.sigma_eps, &conditional) {
        (Some(s), _) => (s, false),
        (None, None) => (
            estimate_sigma(&exps.y, rho.rho_star, &ctx, &parts, &gp_moments.mean),
            true,
        ),
        (None, Some(cc)) => (
            cc.best_theta(rho.rho_star, &candidate_rows, &parts.b)?.0,
            true,
        ),
    };
    drop(candidate_rows);
    let v = assemble_covariance(&parts.b, &gp_moments.covs, sigma_eps * sigma_eps)?;
    let factor = FactoredCovariance::new(v, "Eq. 51 covariance V")?;
    let lik = ThetaLikelihood {
        res: ThetaResiduals {
            model,
            exps,
            parts: &parts,
            rho: rho.rho_star,
            shift: &gp_moments.mean * parts.b.transpose(), // B μ_α(x_i), row i
            conditional: conditional.as_ref(),
        },
        factor: &factor,
        sigma2: sigma_eps * sigma_eps,
    };
    let (posterior, posterior_no_discrepancy) = lik.posteriors(cfg)?;
    let mean_delta = match &conditional {
        None => None,
        Some(cc) => Some(lik.res.posterior_mean_delta(cc, &posterior)?),
    };
    drop(lik);
    drop(conditional);
    let alpha_correction = match mean_delta {
        None => None,
        Some(d) => {
            alpha_hat += &d;
            Some(ConditionalCoefficients::weights(&d, &gp_moments.noise_var))
        }
    };
    timings.module3_s = t.elapsed().as_secs_f64();

    Ok(Calibration {
        config: cfg.clone(),
        input_names: exps.input_names.clone(),
        output_names: exps.output_names.clone(),
        x_bounds,
        theta_rule,
        parts,
        training_pool_size,
        estimator,
        rho,
        alpha_hat,
        x_experiments: exps.x.clone(),
        gps,
        alpha_correction,
        rho_profile,
        sigma_eps,
        sigma_eps_estimated,
        covariance: factor.report(),
        posterior,
        posterior_no_discrepancy,
        timings,
    })
}

/// Residuals of the Module-3 mean (Eq. 50) against the data at a candidate `θ`.
pub struct ThetaResiduals<'a, U, O> {
    /// The model.
    pub model: &'a MultiLevelModel<U, O>,
    /// The data.
    pub exps: &'a Experiments,
    /// `A`, `L`, `B`.
    pub parts: &'a LinearParts,
    /// `ρ*`.
    pub rho: f64,
    /// `B μ_α(x_i)` per experiment (`N_e x N_o`) from the Module-2 GPs.
    pub shift: DMatrix<f64>,
    /// Present in [`CoefficientMode::ConditionalOnTheta`]: re-estimates `α` at each `θ`.
    pub conditional: Option<&'a ConditionalCoefficients<'a>>,
}

impl<U: UnobservableModel, O: LinearObservableModel> ThetaResiduals<'_, U, O> {
    /// Stacked residuals `y − E_o(θ)` with (Eq. 41/50) and without discrepancy (`ρ = 1`, `δ = 0`).
    pub fn residuals(&self, theta: &[f64]) -> Result<(Vec<f64>, Vec<f64>)> {
        let (n_e, n_o) = (self.exps.len(), self.exps.y.ncols());
        let ModelRows { ag, b, .. } = model_rows(self.model, self.exps, self.parts, theta)?;
        let extra = match self.conditional {
            None => None,
            Some(c) => Some(c.smooth(&c.delta(self.rho, &ag, &b)?) * self.parts.b.transpose()),
        };
        let mut with = Vec::with_capacity(n_e * n_o);
        let mut without = Vec::with_capacity(n_e * n_o);
        for i in 0..n_e {
            for p in 0..n_o {
                let y = self.exps.y[(i, p)];
                let shift = self.shift[(i, p)] + extra.as_ref().map_or(0.0, |e| e[(i, p)]);
                with.push(y - (self.rho * ag[(i, p)] + b[(i, p)] + shift));
                without.push(y - (ag[(i, p)] + b[(i, p)]));
            }
        }
        Ok((with, without))
    }

    /// `E_θ[α̂(θ)] − α̂` over the posterior support (at most 50 points for MCMC).
    fn posterior_mean_delta(
        &self,
        cc: &ConditionalCoefficients<'_>,
        posterior: &ThetaPosterior,
    ) -> Result<DMatrix<f64>> {
        let parts = posterior
            .support(50)
            .par_iter()
            .map(|(theta, w)| {
                let rows = model_rows(self.model, self.exps, self.parts, theta)?;
                Ok(cc.delta(self.rho, &rows.ag, &rows.b)? * *w)
            })
            .collect::<Result<Vec<_>>>()?;
        let zero = DMatrix::zeros(self.exps.len(), self.parts.b.ncols());
        Ok(parts.into_iter().fold(zero, |acc, d| acc + d))
    }
}

/// `A g_u(x_i, θ)` and `b(x_i, θ)` at every experiment (`N_e x N_o` each; rows in parallel).
fn model_rows<U: UnobservableModel, O: LinearObservableModel>(
    model: &MultiLevelModel<U, O>,
    exps: &Experiments,
    parts: &LinearParts,
    theta: &[f64],
) -> Result<ModelRows> {
    let (n_e, n_o) = (exps.len(), exps.y.ncols());
    let per_row = (0..n_e)
        .into_par_iter()
        .map(|i| {
            let x = x_row(&exps.x, i);
            let mut g = vec![0.0; model.unobservable.response_len()];
            let mut b = vec![0.0; n_o];
            model.unobservable.evaluate(&x, theta, &mut g)?;
            model.observable.offset(&x, theta, &mut b)?;
            Ok((&parts.a * nalgebra::DVector::from_vec(g), b))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(ModelRows {
        theta: theta.to_vec(),
        ag: DMatrix::from_fn(n_e, n_o, |i, p| per_row[i].0[p]),
        b: DMatrix::from_fn(n_e, n_o, |i, p| per_row[i].1[p]),
    })
}

/// The coefficient GPs' means, latent covariances and noise variances at the experiments.
struct GpMoments {
    mean: DMatrix<f64>,
    covs: Vec<DMatrix<f64>>,
    noise_var: Vec<f64>,
    signal_var: Vec<f64>,
}

impl GpMoments {
    fn of(gps: &CoefficientGps, x: &DMatrix<f64>) -> Result<Self> {
        let (mean, _) = gps.predict(x)?;
        let covs = (0..gps.len())
            .map(|k| gps.covariance(k, x, x))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            mean,
            covs,
            noise_var: gps.noise_variances(),
            signal_var: gps
                .models
                .iter()
                .map(|m| m.hyperparameters().signal_variance)
                .collect(),
        })
    }

    /// The conditional-mode coefficient model over these GPs fitted to `alpha_hat`.
    fn conditional<'a>(
        &self,
        estimator: &'a FittedEstimator,
        ctx: &'a [XContext],
        exps: &'a Experiments,
        alpha_hat: &'a DMatrix<f64>,
    ) -> Result<ConditionalCoefficients<'a>> {
        ConditionalCoefficients::new(
            estimator,
            ctx,
            &exps.x,
            &exps.y,
            alpha_hat,
            &self.mean,
            &self.covs,
            &self.noise_var,
            &self.signal_var,
        )
    }
}

/// Candidate `θ` values for the conditional-mode `σ_ε` estimate: the coarse grid of the
/// one-dimensional posterior, or 16 prior draws.
fn sigma_candidates<U: UnobservableModel, O: LinearObservableModel>(
    model: &MultiLevelModel<U, O>,
    cfg: &CalibrationConfig,
) -> Vec<Vec<f64>> {
    let bounds = model.prior.bounds();
    if bounds.len() == 1 {
        let (lo, hi) = bounds[0];
        let n0 = coarse_nodes(cfg);
        (0..n0)
            .map(|i| vec![lo + (hi - lo) * i as f64 / (n0 - 1) as f64])
            .collect()
    } else {
        model.prior.sample(16, derive_seed(cfg.seed, 8))
    }
}

/// For a scalar `θ`: the interval between the coarse candidates next to `theta` (inside the
/// prior support), where the conditional mode refines the profile optimum.
fn neighbour_bracket<U: UnobservableModel, O: LinearObservableModel>(
    model: &MultiLevelModel<U, O>,
    cfg: &CalibrationConfig,
    theta: &[f64],
) -> Option<(f64, f64)> {
    let bounds = model.prior.bounds();
    let ([(lo, hi)], [t]) = (&bounds[..], theta) else {
        return None;
    };
    let h = (hi - lo) / (coarse_nodes(cfg) - 1) as f64;
    Some(((t - h).max(*lo), (t + h).min(*hi)))
}

/// Nodes of the first, uniform pass of the grid posterior.
fn coarse_nodes(cfg: &CalibrationConfig) -> usize {
    (cfg.theta_grid_points.max(8) / 4).max(3)
}

/// Everything the Module-3 log densities need.
pub struct ThetaLikelihood<'a, U, O> {
    /// The residual model.
    pub res: ThetaResiduals<'a, U, O>,
    /// Factored `V`.
    pub factor: &'a FactoredCovariance,
    /// `σ_ε²` for the no-discrepancy likelihood.
    pub sigma2: f64,
}

impl<U: UnobservableModel, O: LinearObservableModel> ThetaLikelihood<'_, U, O> {
    /// Unnormalised log posteriors (with, without discrepancy) at `θ`; `-∞` outside the prior.
    pub fn log_posteriors(&self, theta: &[f64], par: Par) -> Result<(f64, f64)> {
        let lp = self.res.model.prior.ln_pdf(theta);
        if !lp.is_finite() {
            return Ok((f64::NEG_INFINITY, f64::NEG_INFINITY));
        }
        let (with, without) = self.res.residuals(theta)?;
        Ok((
            lp + self.factor.log_density(&with, par)?,
            lp + iid_log_density(&without, self.sigma2),
        ))
    }

    /// Log posteriors (with, without discrepancy) at each node, in parallel.
    fn evaluate_nodes(&self, nodes: &[f64], cfg: &CalibrationConfig) -> Result<Vec<(f64, f64)>> {
        let pb = progress_bar(nodes.len() as u64, "Module 3: theta grid", cfg.progress);
        let vals = nodes
            .par_iter()
            .map(|t| {
                let r = self.log_posteriors(&[*t], Par::Seq);
                pb.inc(1);
                r
            })
            .collect::<Result<Vec<_>>>()?;
        pb.finish_and_clear();
        Ok(vals)
    }

    /// Exact grid quadrature with adaptive zoom: a quarter of `theta_grid_points` spread
    /// uniformly over the prior support, then zoom passes of `theta_grid_points / 8` nodes per
    /// posterior, each placed uniformly where that posterior has mass (log density within 30 of
    /// its maximum, i.e. relative density > 1e-13, padded to the neighbouring nodes), until
    /// every posterior's mass region holds at least [`MIN_LIVE_NODES`] nodes or the node budget
    /// is spent. Posteriors are often orders of magnitude narrower than the prior; the zoom puts
    /// the nodes where the integrand lives, and the trapezoid rule handles the uneven spacing.
    fn grid_posteriors(
        &self,
        (lo, hi): (f64, f64),
        cfg: &CalibrationConfig,
    ) -> Result<(ThetaPosterior, ThetaPosterior)> {
        let budget = cfg.theta_grid_points.max(8);
        let n0 = coarse_nodes(cfg);
        let coarse: Vec<f64> = (0..n0)
            .map(|i| lo + (hi - lo) * i as f64 / (n0 - 1) as f64)
            .collect();
        let vals = self.evaluate_nodes(&coarse, cfg)?;
        let mut all: Vec<(f64, (f64, f64))> = coarse.into_iter().zip(vals).collect();
        let n_zoom = (budget / 8).max(2);
        let tol = 1e-9 * (hi - lo);
        while all.len() + n_zoom <= budget {
            let mut fine = Vec::new();
            for which in 0..2 {
                if live_count(&all, which) < MIN_LIVE_NODES {
                    fine.extend(zoom_nodes(&all, which, n_zoom, (lo, hi)));
                }
            }
            fine.sort_by(f64::total_cmp);
            fine.dedup_by(|a, b| (*a - *b).abs() <= tol);
            fine.retain(|t| all.iter().all(|a| (a.0 - t).abs() > tol));
            if fine.is_empty() {
                break;
            }
            let fine_vals = self.evaluate_nodes(&fine, cfg)?;
            all.extend(fine.into_iter().zip(fine_vals));
            all.sort_by(|a, b| a.0.total_cmp(&b.0));
        }
        let theta: Vec<f64> = all.iter().map(|a| a.0).collect();
        let with = all.iter().map(|a| a.1.0).collect();
        let without = all.iter().map(|a| a.1.1).collect();
        Ok((
            ThetaPosterior::Grid(GridPosterior::new(theta.clone(), with)?),
            ThetaPosterior::Grid(GridPosterior::new(theta, without)?),
        ))
    }

    /// Both posteriors: grid quadrature for one-dimensional `θ`, adaptive Metropolis otherwise.
    pub fn posteriors(&self, cfg: &CalibrationConfig) -> Result<(ThetaPosterior, ThetaPosterior)> {
        let bounds = self.res.model.prior.bounds();
        if bounds.len() == 1 {
            return self.grid_posteriors(bounds[0], cfg);
        }
        let starts = self
            .res
            .model
            .prior
            .sample(cfg.mcmc.chains, derive_seed(cfg.seed, 4));
        let init_sd: Vec<f64> = bounds.iter().map(|(lo, hi)| (hi - lo) / 20.0).collect();
        let post = |which: usize| {
            adaptive_metropolis(
                |t: &[f64]| {
                    self.log_posteriors(t, Par::Seq)
                        .map(|v| if which == 0 { v.0 } else { v.1 })
                },
                &starts,
                &init_sd,
                &cfg.mcmc,
                derive_seed(cfg.seed, 5 + which as u64),
            )
        };
        Ok((
            ThetaPosterior::Mcmc(post(0)?),
            ThetaPosterior::Mcmc(post(1)?),
        ))
    }
}

/// Grid nodes a posterior's mass region must hold before the zoom stops refining it.
pub const MIN_LIVE_NODES: usize = 12;

/// Number of evaluated nodes where posterior `which` has mass (log density within 30 of max).
fn live_count(all: &[(f64, (f64, f64))], which: usize) -> usize {
    let logd = |a: &(f64, (f64, f64))| if which == 0 { a.1.0 } else { a.1.1 };
    let max = all.iter().map(logd).fold(f64::NEG_INFINITY, f64::max);
    all.iter().filter(|a| logd(a) >= max - 30.0).count()
}

/// `n` uniform nodes covering where posterior `which` (0: with, 1: without discrepancy) of the
/// sorted evaluated nodes `all` has mass (log density within 30 of the maximum), padded by
/// the spacing to the neighbouring evaluated nodes and clipped to `[lo, hi]`.
fn zoom_nodes(all: &[(f64, (f64, f64))], which: usize, n: usize, (lo, hi): (f64, f64)) -> Vec<f64> {
    let logd = |a: &(f64, (f64, f64))| if which == 0 { a.1.0 } else { a.1.1 };
    let max = all.iter().map(logd).fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() {
        return Vec::new();
    }
    let live: Vec<usize> = (0..all.len())
        .filter(|&i| logd(&all[i]) >= max - 30.0)
        .collect();
    let (first, last) = (live[0], live[live.len() - 1]);
    let a = if first > 0 { all[first - 1].0 } else { lo };
    let b = if last + 1 < all.len() {
        all[last + 1].0
    } else {
        hi
    };
    let (a, b) = (a.max(lo), b.min(hi));
    (0..n)
        .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
        .collect()
}

/// Standard normal CDF via `erfc` (W. J. Cody-style rational approximation from Numerical
/// Recipes' `erfcc`, fractional error < 1.2e-7 — ample for credible bands).
fn normal_cdf(z: f64) -> f64 {
    let x = -z / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.5 * x.abs());
    let y = t
        * (-x * x - 1.265_512_23
            + t * (1.000_023_68
                + t * (0.374_091_96
                    + t * (0.096_784_18
                        + t * (-0.186_288_06
                            + t * (0.278_868_07
                                + t * (-1.135_203_98
                                    + t * (1.488_515_87
                                        + t * (-0.822_152_23 + t * 0.170_872_77)))))))))
            .exp();
    0.5 * if x >= 0.0 { y } else { 2.0 - y }
}

/// Quantile `p` of the Gaussian mixture `Σ w_j N(m_j, s²)` by bisection.
fn mixture_quantile(means: &[f64], weights: &[f64], s: f64, p: f64) -> f64 {
    let s = s.max(1e-12 * (1.0 + means.iter().fold(0.0f64, |a, m| a.max(m.abs()))));
    let cdf = |v: f64| -> f64 {
        means
            .iter()
            .zip(weights)
            .map(|(m, w)| w * normal_cdf((v - m) / s))
            .sum()
    };
    let lo0 = means.iter().copied().fold(f64::INFINITY, f64::min) - 10.0 * s;
    let hi0 = means.iter().copied().fold(f64::NEG_INFINITY, f64::max) + 10.0 * s;
    let (mut lo, mut hi) = (lo0, hi0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if cdf(mid) < p {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-12 * (1.0 + mid.abs()) {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// A band from mixture component means (`n_comp x n_points`), weights and a common per-point
/// Gaussian standard deviation.
fn mixture_band(comp: &[Vec<f64>], weights: &[f64], gauss_sd: &[f64]) -> Band {
    let n = gauss_sd.len();
    let mut band = Band {
        mean: vec![0.0; n],
        sd: vec![0.0; n],
        lower: vec![0.0; n],
        upper: vec![0.0; n],
    };
    for b in 0..n {
        let ms: Vec<f64> = comp.iter().map(|c| c[b]).collect();
        let mean: f64 = ms.iter().zip(weights).map(|(m, w)| m * w).sum();
        let var_between: f64 = ms
            .iter()
            .zip(weights)
            .map(|(m, w)| w * (m - mean).powi(2))
            .sum();
        band.mean[b] = mean;
        band.sd[b] = (var_between + gauss_sd[b].powi(2)).sqrt();
        band.lower[b] = mixture_quantile(&ms, weights, gauss_sd[b], 0.025);
        band.upper[b] = mixture_quantile(&ms, weights, gauss_sd[b], 0.975);
    }
    band
}

impl Calibration {
    fn check_x(&self, x: &[f64]) -> Result<()> {
        if x.len() != self.input_names.len() {
            return Err(BamudiError::dim(
                "prediction input x",
                self.input_names.len(),
                x.len(),
            ));
        }
        Ok(())
    }

    /// Means and latent variances of the discrepancy coefficients at the rows of `x` (two
    /// `N x K` matrices): the coefficient GPs, plus, in the conditional coefficient mode, the
    /// shift `Σ_k(x, X) w_k` of the posterior-averaged `α̂(θ)` ([`Calibration::alpha_correction`]).
    pub fn alpha_moments(&self, x: &DMatrix<f64>) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        let (mut mean, var) = self.gps.predict(x)?;
        if let Some(w) = &self.alpha_correction {
            for k in 0..mean.ncols() {
                let cross = self.gps.covariance(k, x, &self.x_experiments)?;
                let shift = cross * w.column(k);
                mean.column_mut(k)
                    .iter_mut()
                    .zip(shift.iter())
                    .for_each(|(m, s)| *m += s);
            }
        }
        Ok((mean, var))
    }

    /// [`alpha_moments`](Self::alpha_moments) at one `x`.
    fn alpha_at(&self, x: &[f64]) -> Result<(Vec<f64>, Vec<f64>)> {
        let (m, v) = self.alpha_moments(&DMatrix::from_row_slice(1, x.len(), x))?;
        Ok((
            m.row(0).iter().copied().collect(),
            v.row(0).iter().copied().collect(),
        ))
    }

    /// Module 4 (Eq. 44, 52): the corrected distributed response at `x` (component blocked,
    /// length `C N_u`). The mean is `Σ_j w_j ρ* g_u(x, θ_j) + L μ_α(x)` over the posterior
    /// support of `θ`; the band is the 2.5/97.5% quantiles of the mixture
    /// `Σ_j w_j N(ρ* g_u(x, θ_j) + L μ_α(x), diag(L Σ_α(x) Lᵀ))` with `Σ_α(x)` the GP latent
    /// variances (the coefficient GPs are independent).
    pub fn predict_response<U: UnobservableModel, O: LinearObservableModel>(
        &self,
        model: &MultiLevelModel<U, O>,
        x: &[f64],
    ) -> Result<Band> {
        self.check_x(x)?;
        let (shift, gauss_sd) = self.projected_alpha(&self.parts.l, x)?;
        let mut g = vec![0.0; self.parts.l.nrows()];
        self.theta_mixture(&gauss_sd, |theta| {
            model.unobservable.evaluate(x, theta, &mut g)?;
            Ok(g.iter()
                .zip(shift.iter())
                .map(|(g, s)| self.rho.rho_star * g + s)
                .collect())
        })
    }

    /// Module 4 for the observable outputs at `x`: mixture over `θ` of
    /// `N(ρ* A g_u(x, θ_j) + b(x, θ_j) + B μ_α(x), diag(B Σ_α(x) Bᵀ))`. The band is for the
    /// noise-free output; add `σ_ε²` ([`Calibration::sigma_eps`]) for a new measurement.
    pub fn predict_outputs<U: UnobservableModel, O: LinearObservableModel>(
        &self,
        model: &MultiLevelModel<U, O>,
        x: &[f64],
    ) -> Result<Band> {
        self.check_x(x)?;
        let bm = &self.parts.b;
        let (shift, gauss_sd) = self.projected_alpha(bm, x)?;
        let mut g = vec![0.0; self.parts.l.nrows()];
        let mut off = vec![0.0; bm.nrows()];
        self.theta_mixture(&gauss_sd, |theta| {
            model.unobservable.evaluate(x, theta, &mut g)?;
            model.observable.offset(x, theta, &mut off)?;
            let ag = &self.parts.a * nalgebra::DVector::from_column_slice(&g);
            Ok((0..bm.nrows())
                .map(|p| self.rho.rho_star * ag[p] + off[p] + shift[p])
                .collect())
        })
    }

    /// The reconstructed discrepancy `L μ_α(x)` with a 95% band `± 1.96 sd` from the GP
    /// variances (Eq. 37; Fig. 15).
    pub fn predict_discrepancy(&self, x: &[f64]) -> Result<Band> {
        self.check_x(x)?;
        let (shift, sd) = self.projected_alpha(&self.parts.l, x)?;
        let mean: Vec<f64> = shift.iter().copied().collect();
        let lower = mean
            .iter()
            .zip(&sd)
            .map(|(m, s)| m - 1.959_964 * s)
            .collect();
        let upper = mean
            .iter()
            .zip(&sd)
            .map(|(m, s)| m + 1.959_964 * s)
            .collect();
        Ok(Band {
            mean,
            sd,
            lower,
            upper,
        })
    }

    /// The GP coefficient moments at `x` projected through `m` (`L` or `B = A L`): the mean
    /// `m μ_α(x)` and the per-row standard deviation `sqrt(diag(m Σ_α(x) mᵀ))` (independent
    /// coefficient GPs, so `Σ_α` is diagonal).
    fn projected_alpha(
        &self,
        m: &DMatrix<f64>,
        x: &[f64],
    ) -> Result<(nalgebra::DVector<f64>, Vec<f64>)> {
        let (mu, var) = self.alpha_at(x)?;
        let shift = m * nalgebra::DVector::from_vec(mu);
        let sd = (0..m.nrows())
            .map(|r| {
                (0..m.ncols())
                    .map(|k| m[(r, k)].powi(2) * var[k])
                    .sum::<f64>()
                    .sqrt()
            })
            .collect();
        Ok((shift, sd))
    }

    /// The band of the mixture over the `θ` posterior support whose component means are
    /// `component(θ_j)`, with the common per-point Gaussian spread `gauss_sd`.
    fn theta_mixture(
        &self,
        gauss_sd: &[f64],
        mut component: impl FnMut(&[f64]) -> Result<Vec<f64>>,
    ) -> Result<Band> {
        let support = self.posterior.support(400);
        let comp = support
            .iter()
            .map(|(theta, _)| component(theta))
            .collect::<Result<Vec<_>>>()?;
        let weights: Vec<f64> = support.iter().map(|s| s.1).collect();
        Ok(mixture_band(&comp, &weights, gauss_sd))
    }
}

impl Calibration {
    /// Saves the whole calibration (estimator, GP models, posteriors) as JSON, so a later run
    /// can predict (Module 4) or report without re-calibrating.
    ///
    /// ```no_run
    /// # fn f(cal: &bamudi::Calibration) -> bamudi::Result<()> {
    /// cal.save(std::path::Path::new("results/calibration.json"))?;
    /// let back = bamudi::Calibration::load(std::path::Path::new("results/calibration.json"))?;
    /// # Ok(()) }
    /// ```
    pub fn save(&self, path: &std::path::Path) -> Result<()> {
        let text = serde_json::to_string(self).map_err(|e| BamudiError::Serde {
            context: path.display().to_string(),
            reason: e.to_string(),
        })?;
        std::fs::write(path, text).map_err(|e| BamudiError::Io {
            path: path.display().to_string(),
            source: e,
        })
    }

    /// Loads a calibration saved by [`save`](Self::save).
    ///
    /// ```
    /// let err = bamudi::Calibration::load(std::path::Path::new("/nonexistent.json")).unwrap_err();
    /// assert!(err.to_string().contains("/nonexistent.json"));
    /// ```
    pub fn load(path: &std::path::Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| BamudiError::Io {
            path: path.display().to_string(),
            source: e,
        })?;
        serde_json::from_str(&text).map_err(|e| BamudiError::Serde {
            context: path.display().to_string(),
            reason: e.to_string(),
        })
    }
}
