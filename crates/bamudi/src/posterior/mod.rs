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
pub(crate) mod no_discrepancy;
pub(crate) mod rho;
pub(crate) mod theta;

pub(crate) mod evaluate;

pub use average::ModelAverage;
pub use conditional::RhoProfile;
pub(crate) use evaluate::{ThetaLikelihood, ThetaResiduals};
pub use likelihood::FactorReport;
pub use marginal::{CoefficientPrior, MarginalFit, MarginalNode, ToleranceEstimate};
pub use no_discrepancy::{NoDiscrepancyFit, NoDiscrepancyNode};
pub use theta::{GridPosterior, GridWarning, SupportPolicy, ThetaPosterior, ThetaSummary};

use crate::error::Result;
use crate::surrogate::gps::CoefficientGps;
use crate::surrogate::training::XContext;
use crate::surrogate::{Module2, Problem};
use coefficients::{CoefficientStrategy, Coefficients};
use conditional::{ConditionalCoefficients, ModelRows};
use likelihood::{FactoredCovariance, assemble_covariance};
use mlmodel::{LinearObservableModel, UnobservableModel};
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The result of Module 3.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Module3 {
    /// `ρ*` used in Modules 3-4 (the conditional mode's profile value, or Eq. 30's).
    pub rho_star: f64,
    /// The conditional mode's profile search for `ρ` (the Eq.-30 value is kept inside it).
    pub rho_profile: Option<RhoProfile>,
    /// The GPs refitted by the conditional mode, when they replace Module 2's.
    pub refit_gps: Option<CoefficientGps>,
    /// The conditional mode's posterior-averaged GP targets `E_θ[α̂(θ)]` (`N_e x K`).
    pub alpha_hat: Option<DMatrix<f64>>,
    /// The conditional mode's smoother weights (`N_e x K`) of `E_θ[α̂(θ)] − α̂`: the GP mean at
    /// `x` becomes `μ_k(x) + Σ_k(x, X) w_k` (`ConditionalCoefficients::weights`).
    pub alpha_correction: Option<DMatrix<f64>>,
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
    #[serde(default)]
    pub no_discrepancy: Option<NoDiscrepancyFit>,
    /// The marginal mode's fit (coefficient priors, amplitude, `ρ`'s posterior, the support
    /// points Module 4 uses).
    #[serde(default)]
    pub marginal: Option<marginal::MarginalFit>,
    /// The models with and without a discrepancy weighed by their evidence, for Module 4's
    /// predictions (`average`; `Some` with
    /// [`DiscrepancyPresence::Weighed`](crate::params::DiscrepancyPresence::Weighed) on a grid
    /// posterior in the marginal mode). The gap's posterior stays [`Self::posterior`].
    #[serde(default)]
    pub averaged: Option<average::ModelAverage>,
}

impl Module3 {
    /// `P(M_0 | y)`, the posterior probability of no discrepancy, when the two models were
    /// weighed ([`Self::averaged`]); `None` otherwise.
    pub fn probability_without(&self) -> Option<f64> {
        self.averaged.as_ref().map(|a| a.probability_without)
    }
}

/// How Module 3 treats the discrepancy coefficients: through a [`CoefficientStrategy`] on
/// Module 2's estimates (the paper's mode and the conditional one), or integrated out
/// ([`marginal`]).
pub(crate) enum Method<U, O> {
    /// Module 2's coefficient GPs, adapted by the strategy.
    Modular(Box<dyn CoefficientStrategy<U, O>>),
    /// The coefficients integrated out under their GP prior.
    Marginal,
}

/// The method of a coefficient mode.
pub(crate) fn method<U, O>(mode: crate::params::CoefficientMode) -> Method<U, O>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    match mode {
        crate::params::CoefficientMode::Marginal => Method::Marginal,
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
    let (alpha_hat, alpha_correction) = match correction {
        None => (None, None),
        Some(d) => {
            let w = ConditionalCoefficients::weights(&d, &c.moments.noise_var);
            c.alpha_hat += &d;
            (Some(c.alpha_hat), Some(w))
        }
    };
    Ok(Module3 {
        rho_star: c.rho_star,
        rho_profile: c.profile,
        refit_gps: c.refit,
        alpha_hat,
        alpha_correction,
        sigma_eps,
        sigma_eps_estimated,
        covariance: factor.report(),
        no_discrepancy: match p.cfg.no_discrepancy_fit {
            true => Some(NoDiscrepancyFit::new(p, &post_without)?),
            false => None,
        },
        posterior: post,
        posterior_no_discrepancy: post_without,
        marginal: None,
        averaged: None,
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
