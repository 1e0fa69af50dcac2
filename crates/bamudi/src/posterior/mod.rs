//! Module 3 of BA-MUDI (paper Sec. 3.4): the posterior of `θ`.
//!
//! The likelihood is Eq. 40 over all `N_e x N_o` observations with the analytic covariance of
//! Eq. 51 (`likelihood`); its mean at a candidate `θ` is Eq. 50 with the coefficients the
//! `CoefficientStrategy` of the configured mode gives (`coefficients`). One-dimensional `θ`
//! gets exact grid quadrature, more dimensions adaptive Metropolis (`grid`, `mcmc`); the
//! "without discrepancy" posterior (`δ = 0`, `ρ` integrated, `σ_ε` profiled: the strongest
//! calibration without a discrepancy, `no_discrepancy`; Fig. 16) comes with it.

pub(crate) mod average;
pub(crate) mod coefficients;
pub(crate) mod conditional;
pub(crate) mod grid;
pub(crate) mod likelihood;
pub(crate) mod marginal;
pub(crate) mod mcmc;
pub(crate) mod mode;
pub(crate) mod no_discrepancy;
pub(crate) mod rho;
pub(crate) mod theta;

pub(crate) mod evaluate;

pub use average::ModelAverage;
pub use conditional::RhoProfile;
pub(crate) use evaluate::{ThetaLikelihood, ThetaResiduals};
pub use likelihood::FactorReport;
pub use marginal::{CoefficientPrior, MarginalFit, MarginalNode, ToleranceEstimate};
pub use mode::ConditionalFit;
pub use no_discrepancy::{NoDiscrepancyFit, NoDiscrepancyNode};
pub use theta::{GridPosterior, GridWarning, SupportPolicy, ThetaPosterior, ThetaSummary};

use crate::error::Result;
use crate::surrogate::training::XContext;
use crate::surrogate::{Module2, Problem};
use coefficients::{CoefficientStrategy, Coefficients};
use conditional::{ConditionalCoefficients, ModelRows};
use likelihood::{FactoredCovariance, assemble_covariance};
use mlmodel::{LinearObservableModel, UnobservableModel};
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::Deserialize;

/// The result of Module 3.
#[derive(Debug, Clone, Deserialize)]
#[serde(try_from = "mode::Read")]
pub struct Module3 {
    /// `ρ*` used in Modules 3-4 (the conditional mode's profile value, Eq. 30's, or the
    /// marginal mode's posterior mean).
    pub rho_star: f64,
    /// `σ_ε` used (output units).
    pub sigma_eps: f64,
    /// Whether `σ_ε` was estimated rather than configured.
    pub sigma_eps_estimated: bool,
    /// Factorisation of the Eq.-51 covariance.
    pub covariance: FactorReport,
    /// Posterior of `θ` with the discrepancy model (Eq. 38-43).
    pub posterior: ThetaPosterior,
    /// Posterior of `θ` without discrepancy (`δ = 0`, `ρ` integrated over its prior, `σ_ε`
    /// profiled; `no_discrepancy`; Fig. 16).
    pub posterior_no_discrepancy: ThetaPosterior,
    /// The no-discrepancy calibration at its posterior's support points (`ρ` per point), for
    /// its predictions (baseline (b); `None` when
    /// [`no_discrepancy_fit`](crate::CalibrationParams::no_discrepancy_fit) is off, and in
    /// files written before it existed).
    pub no_discrepancy: Option<NoDiscrepancyFit>,
    /// What the coefficient mode fitted besides `θ`'s posterior.
    pub mode: ModeFit,
}

/// What a coefficient mode ([`CoefficientMode`](crate::CoefficientMode)) fitted besides
/// `θ`'s posterior: each mode's own result, one variant per mode.
#[derive(Debug, Clone)]
pub enum ModeFit {
    /// The paper's Module 3: Module 2's coefficient GPs as they are; nothing more is fitted.
    PriorMarginal,
    /// The coefficients conditioned on `θ`: the `ρ` profile, the refitted GPs and the
    /// posterior-averaged coefficient targets.
    ConditionalOnTheta(Box<ConditionalFit>),
    /// The coefficients integrated out.
    Marginal(Box<MarginalModeFit>),
}

/// What the marginal mode ([`CoefficientMode::Marginal`](crate::CoefficientMode::Marginal))
/// fitted.
#[derive(Debug, Clone)]
pub struct MarginalModeFit {
    /// The coefficient priors, amplitude, `ρ`'s posterior and the support points Module 4 uses.
    pub fit: MarginalFit,
    /// The models with and without a discrepancy weighed by their evidence, for Module 4's
    /// predictions (`average`; `Some` with
    /// [`DiscrepancyPresence::Weighed`](crate::params::DiscrepancyPresence::Weighed) on a grid
    /// posterior). The gap's posterior stays [`Module3::posterior`].
    pub averaged: Option<ModelAverage>,
}

impl Module3 {
    /// `P(M_0 | y)`, the posterior probability of no discrepancy, when the two models were
    /// weighed ([`Self::averaged`]); `None` otherwise.
    pub fn probability_without(&self) -> Option<f64> {
        self.averaged().map(|a| a.probability_without)
    }
    /// The marginal mode's fit (`None` in the other modes).
    pub fn marginal(&self) -> Option<&MarginalFit> {
        match &self.mode {
            ModeFit::Marginal(m) => Some(&m.fit),
            _ => None,
        }
    }
    /// The models with and without a discrepancy weighed by their evidence (the marginal mode
    /// with [`DiscrepancyPresence::Weighed`](crate::params::DiscrepancyPresence::Weighed);
    /// `None` otherwise).
    pub fn averaged(&self) -> Option<&ModelAverage> {
        match &self.mode {
            ModeFit::Marginal(m) => m.averaged.as_ref(),
            _ => None,
        }
    }
    /// The conditional mode's fit (`None` in the other modes).
    pub fn conditional(&self) -> Option<&ConditionalFit> {
        match &self.mode {
            ModeFit::ConditionalOnTheta(c) => Some(c),
            _ => None,
        }
    }
}

/// How Module 3 treats the discrepancy coefficients: through a [`CoefficientStrategy`] on
/// Module 2's estimates (the paper's mode and the conditional one), or integrated out
/// ([`marginal`]).
pub(crate) enum Method<'a, U, O> {
    /// Module 2's coefficient GPs, adapted by the strategy.
    Modular(Box<dyn CoefficientStrategy<U, O>>),
    /// The coefficients integrated out under their GP prior (the mode's).
    Marginal(&'a crate::params::MarginalPrior),
}

/// The method of a coefficient mode.
pub(crate) fn method<U, O>(mode: &crate::params::CoefficientMode) -> Method<'_, U, O>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    match mode {
        crate::params::CoefficientMode::Marginal(prior) => Method::Marginal(prior),
        other => Method::Modular(coefficients::strategy(other)),
    }
}

/// Module 3, first part: the strategy adapts Module 2's coefficients (the conditional mode's
/// `ρ` profile search and GP refit).
pub(crate) fn adapt_coefficients<U, O>(
    p: &Problem<'_, U, O>,
    m2: &Module2,
    ctx: &[XContext],
    strategy: &dyn CoefficientStrategy<U, O>,
) -> Result<Coefficients>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    strategy.adapt(p, m2, ctx)
}

/// Module 3, second part: `σ_ε`, the Eq.-51 covariance and both `θ` posteriors.
pub(crate) fn posterior<U, O>(
    p: &Problem<'_, U, O>,
    m2: &Module2,
    ctx: &[XContext],
    strategy: &dyn CoefficientStrategy<U, O>,
    mut c: Coefficients,
) -> Result<Module3>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let cc = strategy.at_theta(p, m2, ctx, &c)?;
    let (sigma_eps, sigma_eps_estimated) = match p.cfg.sigma_eps {
        Some(s) => (s, false),
        None => (strategy.estimate_sigma(p, ctx, &c, cc.as_ref())?, true),
    };
    let v = assemble_covariance(&p.parts.b, &c.moments.covs, sigma_eps * sigma_eps)?;
    let factor = FactoredCovariance::new(&v, "Eq. 51 covariance V")?;
    drop(v);
    let lik = ThetaLikelihood {
        res: ThetaResiduals {
            p,
            rho: c.rho_star,
            shift: &c.moments.mean * p.parts.b.transpose(),
            conditional: cc.as_ref(),
        },
        factor: &factor,
    };
    let bounds = p.model.prior.bounds();
    let starts = |n, seed| p.model.prior.sample(n, seed);
    let (post, post_without) = grid::posteriors(&lik, &bounds, starts, p.cfg, p.observer)?;
    let correction = match &cc {
        None => None,
        Some(cc) => Some(lik.res.posterior_mean_delta(cc, &post)?),
    };
    drop(lik);
    drop(cc);
    let mode = match (correction, c.profile) {
        (None, None) => ModeFit::PriorMarginal,
        (None, Some(_)) => {
            return Err(crate::error::BamudiError::Calibration(
                "a rho profile came without the conditional coefficients".into(),
            ));
        }
        (Some(d), Some(rho_profile)) => {
            let w = ConditionalCoefficients::weights(&d, &c.moments.noise_var);
            c.alpha_hat += &d;
            ModeFit::ConditionalOnTheta(Box::new(ConditionalFit {
                rho_profile,
                refit_gps: c.refit,
                alpha_hat: c.alpha_hat,
                alpha_correction: w,
            }))
        }
        (Some(_), None) => {
            return Err(crate::error::BamudiError::Calibration(
                "the conditional coefficients came without their rho profile".into(),
            ));
        }
    };
    Ok(Module3 {
        rho_star: c.rho_star,
        sigma_eps,
        sigma_eps_estimated,
        covariance: factor.report(),
        no_discrepancy: match p.cfg.no_discrepancy_fit {
            true => Some(NoDiscrepancyFit::new(p, &post_without)?),
            false => None,
        },
        posterior: post,
        posterior_no_discrepancy: post_without,
        mode,
    })
}

/// `A g_u(x_i, θ)` and `b(x_i, θ)` at every experiment (`N_e x N_o` each; rows in parallel).
pub(crate) fn model_rows<U, O>(p: &Problem<'_, U, O>, theta: &[f64]) -> Result<ModelRows>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let (n_e, n_o) = (p.exps.len(), p.exps.y.ncols());
    let per_row = (0..n_e)
        .into_par_iter()
        .map(|i| p.model.model_row(&p.x_row(i), theta))
        .collect::<mlmodel::Result<Vec<_>>>()?;
    Ok(ModelRows {
        theta: theta.to_vec(),
        ag: DMatrix::from_fn(n_e, n_o, |i, q| per_row[i][q]),
        b: DMatrix::from_fn(n_e, n_o, |i, q| per_row[i][n_o + q]),
    })
}
