//! How Module 3 sets the discrepancy coefficients at a candidate `θ`: the paper's (the
//! Module-2 coefficients, marginal over the prior, at every `θ`) or conditioned on `θ` (see
//! [`super::conditional`]). Each [`CoefficientMode`] is a [`CoefficientStrategy`]; Module 3
//! calls the strategy at its four decision points and never branches on the mode itself.

use super::conditional::{ConditionalCoefficients, GpMoments, ModelRows, RhoProfile};
use super::grid::coarse_nodes;
use super::model_rows;
use crate::error::{BamudiError, Result};
use crate::params::CoefficientMode;
use crate::surrogate::gps::CoefficientGps;
use crate::surrogate::rho::predicted_outputs;
use crate::surrogate::training::XContext;
use crate::surrogate::{Module2, Problem, coefficient_gps, seed_index};
use mlmodel::{LinearObservableModel, UnobservableModel};
use nalgebra::DMatrix;
use numerics::random::derive_seed;
use rayon::prelude::*;

/// The coefficients Module 3 works with, after the strategy has adapted Module 2's.
pub struct Coefficients {
    /// `ρ*` used by Modules 3-4.
    pub rho_star: f64,
    /// The GPs refitted by the strategy, when they replace Module 2's.
    pub refit: Option<CoefficientGps>,
    /// The GP targets (Module 2's `α̂`, or the refit's).
    pub alpha_hat: DMatrix<f64>,
    /// The GPs' moments at the experiments.
    pub moments: GpMoments,
    /// The strategy's `ρ` search, when it ran one.
    pub profile: Option<RhoProfile>,
    /// Model rows the strategy evaluated (reused for `σ_ε`).
    pub candidates: Vec<ModelRows>,
}

/// One coefficient mode of Module 3.
pub trait CoefficientStrategy<U, O>: Sync {
    /// Adapts Module 2's `ρ*`, GPs and targets before the posterior.
    fn adapt(&self, p: &Problem<'_, U, O>, m2: &Module2, ctx: &[XContext]) -> Result<Coefficients>;
    /// The re-estimator of the coefficients at each `θ` (`None`: the coefficients do not
    /// depend on `θ`).
    fn at_theta<'a>(
        &self,
        p: &'a Problem<'_, U, O>,
        m2: &'a Module2,
        ctx: &'a [XContext],
        c: &'a Coefficients,
    ) -> Result<Option<ConditionalCoefficients<'a>>>;
    /// `σ_ε` when the configuration leaves it to be estimated.
    fn estimate_sigma(
        &self,
        p: &Problem<'_, U, O>,
        ctx: &[XContext],
        c: &Coefficients,
        cc: Option<&ConditionalCoefficients<'_>>,
    ) -> Result<f64>;
}

/// The strategy of a mode.
pub fn strategy<U, O>(mode: &CoefficientMode) -> Box<dyn CoefficientStrategy<U, O>>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    match mode {
        CoefficientMode::ConditionalOnTheta => Box::new(ConditionalOnTheta),
        // the marginal mode has no strategy of its own ([`super::method`] routes it apart)
        CoefficientMode::PriorMarginal | CoefficientMode::Marginal(_) => Box::new(PriorMarginal),
    }
}

/// The paper's Module 3: Module 2's coefficients at every `θ`.
pub struct PriorMarginal;

impl<U: UnobservableModel, O: LinearObservableModel> CoefficientStrategy<U, O> for PriorMarginal {
    fn adapt(&self, p: &Problem<'_, U, O>, m2: &Module2, _: &[XContext]) -> Result<Coefficients> {
        Ok(Coefficients {
            rho_star: m2.rho.rho_star,
            refit: None,
            alpha_hat: m2.alpha_hat.clone(),
            moments: GpMoments::of(&m2.gps, &p.exps.x)?,
            profile: None,
            candidates: Vec::new(),
        })
    }
    fn at_theta<'a>(
        &self,
        _: &'a Problem<'_, U, O>,
        _: &'a Module2,
        _: &'a [XContext],
        _: &'a Coefficients,
    ) -> Result<Option<ConditionalCoefficients<'a>>> {
        Ok(None)
    }
    /// The root-mean-square residual of the Module-2 corrected prediction at `ρ*` with the
    /// GP-mean coefficients and `θ` averaged over its prior,
    /// `σ̂² = Σ_i ‖y_i − ρ* A ḡ(x_i) − b̄(x_i) − B μ_α(x_i)‖² / (N_e N_o)`. It is conservative
    /// (too large): the residual also carries the prior-averaging of `θ` and the GP smoothing
    /// error.
    fn estimate_sigma(
        &self,
        p: &Problem<'_, U, O>,
        ctx: &[XContext],
        c: &Coefficients,
        _: Option<&ConditionalCoefficients<'_>>,
    ) -> Result<f64> {
        let y = &p.exps.y;
        let pred = predicted_outputs(c.rho_star, &c.moments.mean, ctx, &p.parts);
        let ss: f64 = (y - pred).iter().map(|r| r * r).sum();
        Ok((ss / (y.nrows() * y.ncols()) as f64).sqrt())
    }
}

/// Coefficients conditioned on `θ` (not in the paper; [`super::conditional`]): `ρ*` by the
/// profile search, the GPs refitted to `α̂(ρ*, θ*)` when that fits at least as well.
pub struct ConditionalOnTheta;

impl<U: UnobservableModel, O: LinearObservableModel> CoefficientStrategy<U, O>
    for ConditionalOnTheta
{
    fn adapt(&self, p: &Problem<'_, U, O>, m2: &Module2, ctx: &[XContext]) -> Result<Coefficients> {
        let moments = GpMoments::of(&m2.gps, &p.exps.x)?;
        let mut candidates = theta_candidates(p)
            .par_iter()
            .map(|theta| model_rows(p, theta))
            .collect::<Result<Vec<_>>>()?;
        let cc = ConditionalCoefficients::new(&m2.estimator, ctx, p.exps, &m2.alpha_hat, &moments)?;
        let mut profile = cc.profile_rho(&candidates, &p.parts.b, &p.cfg.rho, m2.rho.rho_star)?;
        if let Some(bracket) = neighbour_bracket(p, &profile.theta_star) {
            let rows_at = |t: f64| model_rows(p, &[t]);
            let refined =
                cc.refine_scalar_theta(&mut profile, bracket, rows_at, &p.parts.b, &p.cfg.rho)?;
            candidates.extend(refined);
        }
        let best = candidates
            .iter()
            .find(|r| r.theta == profile.theta_star)
            .ok_or_else(|| BamudiError::Numerical {
                context: "rho profile".into(),
                reason: "best theta candidate not found".into(),
            })?;
        let base = cc.alpha(profile.rho_star, &best.ag, &best.b)?;
        drop(cc);
        let refit = coefficient_gps(p, &base)?;
        let refit_moments = GpMoments::of(&refit, &p.exps.x)?;
        profile.rms_after_refit =
            ConditionalCoefficients::new(&m2.estimator, ctx, p.exps, &base, &refit_moments)?.rms(
                profile.rho_star,
                best,
                &p.parts.b,
            )?;
        Ok(keep_better_fit(
            m2,
            profile,
            candidates,
            (refit, refit_moments, base),
            moments,
        ))
    }
    fn at_theta<'a>(
        &self,
        p: &'a Problem<'_, U, O>,
        m2: &'a Module2,
        ctx: &'a [XContext],
        c: &'a Coefficients,
    ) -> Result<Option<ConditionalCoefficients<'a>>> {
        ConditionalCoefficients::new(&m2.estimator, ctx, p.exps, &c.alpha_hat, &c.moments).map(Some)
    }
    /// The smallest root-mean-square residual of the conditional fit over the candidate `θ`.
    fn estimate_sigma(
        &self,
        p: &Problem<'_, U, O>,
        _: &[XContext],
        c: &Coefficients,
        cc: Option<&ConditionalCoefficients<'_>>,
    ) -> Result<f64> {
        let cc = cc.ok_or_else(|| BamudiError::Numerical {
            context: "conditional sigma_eps".into(),
            reason: "no conditional coefficient model".into(),
        })?;
        Ok(cc.best_theta(c.rho_star, &c.candidates, &p.parts.b)?.0)
    }
}

/// The refit is kept only if it fits at least as well: `B` mixes the coefficients, and a refit
/// that interpolates some of them and smooths others can fit worse than the Module-2 GPs.
fn keep_better_fit(
    m2: &Module2,
    profile: RhoProfile,
    candidates: Vec<ModelRows>,
    (refit, refit_moments, base): (CoefficientGps, GpMoments, DMatrix<f64>),
    moments: GpMoments,
) -> Coefficients {
    let rho_star = profile.rho_star;
    if profile.refit_kept() {
        return Coefficients {
            rho_star,
            refit: Some(refit),
            alpha_hat: base,
            moments: refit_moments,
            profile: Some(profile),
            candidates,
        };
    }
    log::info!(
        "GP refit at rho* = {:.4}, theta = {:?} fits worse ({:.4} vs {:.4} RMS); keeping the \
         Module-2 GPs",
        profile.rho_star,
        profile.theta_star,
        profile.rms_after_refit,
        profile.rms_at_star
    );
    Coefficients {
        rho_star,
        refit: None,
        alpha_hat: m2.alpha_hat.clone(),
        moments,
        profile: Some(profile),
        candidates,
    }
}

/// Candidate `θ` values of the profile search and the conditional-mode `σ_ε` estimate: the
/// coarse grid of the one-dimensional posterior, or 16 prior draws.
fn theta_candidates<U: UnobservableModel, O: LinearObservableModel>(
    p: &Problem<'_, U, O>,
) -> Vec<Vec<f64>> {
    let bounds = p.model.prior.bounds();
    if bounds.len() == 1 {
        let (lo, hi) = bounds[0];
        let n0 = coarse_nodes(p.cfg);
        (0..n0)
            .map(|i| vec![lo + (hi - lo) * i as f64 / (n0 - 1) as f64])
            .collect()
    } else {
        let seed = derive_seed(p.cfg.seed, seed_index::THETA_CANDIDATES);
        p.model.prior.sample(16, seed)
    }
}

/// For a scalar `θ`: the interval between the coarse candidates next to `theta` (inside the
/// prior support), where the conditional mode refines the profile optimum.
fn neighbour_bracket<U: UnobservableModel, O: LinearObservableModel>(
    p: &Problem<'_, U, O>,
    theta: &[f64],
) -> Option<(f64, f64)> {
    let bounds = p.model.prior.bounds();
    let ([(lo, hi)], [t]) = (&bounds[..], theta) else {
        return None;
    };
    let h = (hi - lo) / (coarse_nodes(p.cfg) - 1) as f64;
    Some(((t - h).max(*lo), (t + h).min(*hi)))
}
