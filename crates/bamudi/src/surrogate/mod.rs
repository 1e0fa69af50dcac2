//! Module 2 of BA-MUDI (paper Sec. 3.3): learn the discrepancy coefficients.
//!
//! Offline, a training set `(ρ, x, α) ↦ μ_o` with `θ` marginalised over its prior (Eq. 27,
//! `training`) and an estimator `α = f_ML(ρ, x, y)` fitted on it (Eq. 29, `estimator`);
//! online, `ρ*` (Eq. 30-31, `rho`), `α̂` at the experiments (Eq. 32) and one GP per
//! coefficient (Eq. 33-37, `gps`). Each step is a function of a [`Problem`]; the executor in
//! `calibration` runs them in order, times them and collects a [`Module2`].

pub(crate) mod accuracy;
pub(crate) mod artefact;
pub(crate) mod estimator;
pub(crate) mod gps;
pub(crate) mod problem;
pub(crate) mod rho;
pub(crate) mod training;

pub use accuracy::{EstimatorAccuracy, estimator_accuracy};
pub use artefact::Surrogate;
pub use estimator::{CoefficientEstimator, FittedEstimator, LstmSettings};
pub use gps::CoefficientGps;
pub(crate) use problem::Problem;

use crate::data::Experiments;
use crate::error::{BamudiError, Result};
use crate::params::CalibrationConfig;
use estimator::{EstimatorData, FitEstimator};
use mlmodel::{LinearObservableModel, MultiLevelModel, QuadratureRule, UnobservableModel};
use nalgebra::DMatrix;
use numerics::random::derive_seed;
use rayon::prelude::*;
use rho::{RhoCurve, estimate_rho};
use serde::{Deserialize, Serialize};
use training::{TrainingSet, TrainingSpec, XContext};

/// Indices of the seeds derived from the master seed, one per random step (fixed: a
/// calibration with the same master seed draws the same numbers in every version).
pub(crate) mod seed_index {
    /// Monte-Carlo marginalisation nodes of `θ`.
    pub const THETA_RULE: u64 = 1;
    /// The Eq.-27 training set.
    pub const TRAINING_SET: u64 = 2;
    /// GP hyper-parameter restarts.
    pub const GPS: u64 = 3;
    /// MCMC start points.
    pub const MCMC_STARTS: u64 = 4;
    /// MCMC chains (with and without discrepancy: this and the next index).
    pub const MCMC_CHAINS: u64 = 5;
    /// The learnt estimator's initialisation and shuffling.
    pub const ESTIMATOR: u64 = 6;
    /// Prior draws standing in for a `θ` grid when `dim θ > 1`.
    pub const THETA_CANDIDATES: u64 = 8;
}

/// The result of Module 2.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Module2 {
    /// Input box used for the training set.
    pub x_bounds: Vec<(f64, f64)>,
    /// Nodes/weights that marginalise `θ`.
    pub theta_rule: QuadratureRule,
    /// Distinct `x` values in the training set (0 for the exact estimator, which needs none).
    pub training_pool_size: usize,
    /// The fitted estimator of Eq. 29.
    pub estimator: FittedEstimator,
    /// The `ρ` search (Eq. 30) with its curve.
    pub rho: RhoCurve,
    /// `α̂` at the experiments (Eq. 32), `N_e x K`.
    pub alpha_hat: DMatrix<f64>,
    /// The coefficient GPs (Eq. 33-37).
    pub gps: CoefficientGps,
    /// A digest of the experiment outputs it was fitted to (`None` in files saved before it
    /// was recorded), checked before Module 3 runs on it ([`Surrogate`]).
    #[serde(default)]
    pub(crate) outputs_digest: Option<u64>,
}

/// The Eq.-27 training set, when the configured estimator needs one.
pub(crate) fn training_set<U, O>(p: &Problem<'_, U, O>) -> Result<Option<TrainingSet>>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    if !p.cfg.estimator.needs_training_set() {
        return Ok(None);
    }
    let spec = TrainingSpec {
        theta_rule: &p.theta_rule,
        rule: &p.cfg.sampling,
        bounds: &p.x_bounds,
        size: p.cfg.training_size,
        seed: derive_seed(p.cfg.seed, seed_index::TRAINING_SET),
    };
    training::generate_linear(p.model, &p.parts, &spec, p.observer).map(Some)
}

/// The configured estimator fitted (Eq. 29).
pub(crate) fn fit_estimator<U, O>(
    p: &Problem<'_, U, O>,
    training: Option<&TrainingSet>,
) -> Result<FittedEstimator> {
    p.cfg.estimator.fit(&EstimatorData {
        parts: &p.parts,
        noise_sd: p.cfg.sampling.noise_sd,
        training,
        seed: derive_seed(p.cfg.seed, seed_index::ESTIMATOR),
        observer: p.observer,
    })
}

/// The prior-averaged contexts (Eq. 31) at every experiment, in parallel.
pub(crate) fn contexts<U, O>(p: &Problem<'_, U, O>) -> Result<Vec<XContext>>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    (0..p.exps.len())
        .into_par_iter()
        .map(|i| {
            let x = p.x_row(i);
            training::x_context(p.model, &p.parts, &p.theta_rule, &p.cfg.sampling, &x)
        })
        .collect()
}

/// `ρ*` (Eq. 30) and `α̂` at the experiments (Eq. 32).
pub(crate) fn rho_and_alpha<U, O>(
    p: &Problem<'_, U, O>,
    estimator: &FittedEstimator,
    ctx: &[XContext],
) -> Result<(RhoCurve, DMatrix<f64>)> {
    let (x, y) = (&p.exps.x, &p.exps.y);
    let rho = estimate_rho(estimator, x, y, ctx, &p.parts, &p.cfg.rho)?;
    let alpha_hat = estimator.predict(rho.rho_star, x, y, ctx)?;
    Ok((rho, alpha_hat))
}

/// One GP per coefficient fitted to `alpha` (Eq. 33-37), with the configured restarts.
pub(crate) fn coefficient_gps<U, O>(
    p: &Problem<'_, U, O>,
    alpha: &DMatrix<f64>,
) -> Result<CoefficientGps> {
    let seed = derive_seed(p.cfg.seed, seed_index::GPS);
    CoefficientGps::fit(&p.exps.x, alpha, p.cfg.gp_restarts, seed)
}

pub(crate) fn check_data<U: UnobservableModel, O: LinearObservableModel>(
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

/// The configured input box, or the experiments' bounding box (a constant input is widened
/// by half its magnitude, at least 0.5, each way).
pub(crate) fn input_box(cfg: &CalibrationConfig, exps: &Experiments) -> Vec<(f64, f64)> {
    match &cfg.sampling.x_bounds {
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
    }
}
