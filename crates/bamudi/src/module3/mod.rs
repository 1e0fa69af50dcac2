//! Module 3 of BA-MUDI (paper Sec. 3.4): the posterior of `θ`.
//!
//! The likelihood is Eq. 40 over all `N_e x N_o` observations with the analytic covariance of
//! Eq. 51 ([`likelihood`]); its mean at a candidate `θ` is Eq. 50 with the coefficients the
//! [`CoefficientStrategy`] of the configured mode gives ([`coefficients`]). One-dimensional `θ`
//! gets exact grid quadrature, more dimensions adaptive Metropolis ([`grid`], [`mcmc`]); the
//! "without discrepancy" posterior (`δ = 0`, `ρ` integrated, `σ_ε` profiled: the strongest
//! calibration without a discrepancy, [`no_discrepancy`]; Fig. 16) comes with it.

pub mod average;
pub mod coefficients;
pub mod conditional;
pub mod grid;
pub mod likelihood;
pub mod marginal;
pub mod mcmc;
pub mod no_discrepancy;
pub mod posterior;
pub(crate) mod rho;

use crate::error::Result;
use crate::module2::gps::CoefficientGps;
use crate::module2::training::XContext;
use crate::module2::{Module2, Problem};
use crate::observe::{Observer, Stage, tick};
use coefficients::{CoefficientStrategy, Coefficients};
use conditional::{ConditionalCoefficients, ModelRows, RhoProfile};
use likelihood::{FactorReport, FactoredCovariance, assemble_covariance};
use mlmodel::{LinearObservableModel, UnobservableModel};
use nalgebra::DMatrix;
use no_discrepancy::NoDiscrepancyFit;
use posterior::{SupportPolicy, ThetaPosterior};
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
    /// `x` becomes `μ_k(x) + Σ_k(x, X) w_k` ([`ConditionalCoefficients::weights`]).
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
    /// profiled; [`no_discrepancy`]; Fig. 16).
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
    /// predictions ([`average`]; `Some` with
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
pub enum Method<U, O> {
    /// Module 2's coefficient GPs, adapted by the strategy.
    Modular(Box<dyn CoefficientStrategy<U, O>>),
    /// The coefficients integrated out under their GP prior.
    Marginal,
}

/// The method of a coefficient mode.
pub fn method<U, O>(mode: crate::params::CoefficientMode) -> Method<U, O>
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
pub fn adapt_coefficients<U, O>(
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
pub fn posterior<U, O>(
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
pub fn model_rows<U, O>(p: &Problem<'_, U, O>, theta: &[f64]) -> Result<ModelRows>
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

/// Residuals of the Module-3 mean (Eq. 50) against the data at a candidate `θ`.
pub struct ThetaResiduals<'a, 'p, U, O> {
    /// The problem (model, data, `A`, `L`, `B`).
    pub p: &'a Problem<'p, U, O>,
    /// `ρ*`.
    pub rho: f64,
    /// `B μ_α(x_i)` per experiment (`N_e x N_o`) from the coefficient GPs.
    pub shift: DMatrix<f64>,
    /// The re-estimator of the coefficients at each `θ` (conditional mode), if any.
    pub conditional: Option<&'a ConditionalCoefficients<'a>>,
}

impl<U: UnobservableModel, O: LinearObservableModel> ThetaResiduals<'_, '_, U, O> {
    /// Stacked residuals `y − E_o(θ)` with the discrepancy (Eq. 41/50), and the log likelihood
    /// without it ([`no_discrepancy`]).
    pub fn residuals(&self, theta: &[f64]) -> Result<(Vec<f64>, f64)> {
        let (exps, bm) = (self.p.exps, &self.p.parts.b);
        let (n_e, n_o) = (exps.len(), exps.y.ncols());
        let ModelRows { ag, b, .. } = model_rows(self.p, theta)?;
        let extra = match self.conditional {
            None => None,
            Some(c) => Some(c.smooth(&c.delta(self.rho, &ag, &b)?) * bm.transpose()),
        };
        let mut with = Vec::with_capacity(n_e * n_o);
        let (mut a, mut c) = (Vec::with_capacity(n_e * n_o), Vec::with_capacity(n_e * n_o));
        for i in 0..n_e {
            for q in 0..n_o {
                let y = exps.y[(i, q)];
                let shift = self.shift[(i, q)] + extra.as_ref().map_or(0.0, |e| e[(i, q)]);
                with.push(y - (self.rho * ag[(i, q)] + b[(i, q)] + shift));
                a.push(ag[(i, q)]);
                c.push(y - b[(i, q)]);
            }
        }
        let without =
            no_discrepancy::fit_at(&a, &c, self.p.cfg.sampling.rho_range, self.p.cfg.sigma_eps)
                .log_lik;
        Ok((with, without))
    }

    /// `E_θ[α̂(θ)] − α̂` over the posterior support ([`SupportPolicy::default`]).
    fn posterior_mean_delta(
        &self,
        cc: &ConditionalCoefficients<'_>,
        posterior: &ThetaPosterior,
    ) -> Result<DMatrix<f64>> {
        let parts = posterior
            .support(&SupportPolicy::default())
            .par_iter()
            .map(|(theta, w)| {
                let rows = model_rows(self.p, theta)?;
                Ok(cc.delta(self.rho, &rows.ag, &rows.b)? * *w)
            })
            .collect::<Result<Vec<_>>>()?;
        let zero = DMatrix::zeros(self.p.exps.len(), self.p.parts.b.ncols());
        Ok(parts.into_iter().fold(zero, |acc, d| acc + d))
    }
}

/// Everything the Module-3 log densities need.
pub struct ThetaLikelihood<'a, 'p, U, O> {
    /// The residual model.
    pub res: ThetaResiduals<'a, 'p, U, O>,
    /// Factored `V`.
    pub factor: &'a FactoredCovariance,
}

impl<U: UnobservableModel, O: LinearObservableModel> grid::LogPosteriors
    for ThetaLikelihood<'_, '_, U, O>
{
    /// Unnormalised log posteriors (with, without discrepancy) at `θ`; `-∞` outside the prior.
    fn log_posteriors(&self, theta: &[f64]) -> Result<(f64, f64)> {
        let lp = self.res.p.model.prior.ln_pdf(theta);
        if !lp.is_finite() {
            return Ok((f64::NEG_INFINITY, f64::NEG_INFINITY));
        }
        let (with, without) = self.res.residuals(theta)?;
        Ok((lp + self.factor.log_density(&with)?, lp + without))
    }

    /// The residuals of every node in parallel, then one blocked solve with the factor of `V`
    /// for all of them ([`FactoredCovariance::log_densities`]); the same values as
    /// [`log_posteriors`](Self::log_posteriors) node by node, up to round-off.
    fn log_posteriors_at_nodes(
        &self,
        nodes: &[f64],
        observer: &dyn Observer,
    ) -> Result<Vec<(f64, f64)>> {
        let per_node = nodes
            .par_iter()
            .map(|t| {
                let lp = self.res.p.model.prior.ln_pdf(&[*t]);
                let r = if lp.is_finite() {
                    self.res
                        .residuals(&[*t])
                        .map(|(with, without)| Some((lp, with, lp + without)))
                } else {
                    Ok(None)
                };
                tick(observer, Stage::Module3);
                r
            })
            .collect::<Result<Vec<_>>>()?;
        let inside: Vec<&(f64, Vec<f64>, f64)> = per_node.iter().flatten().collect();
        let n_s = self.factor.size();
        if let Some(node) = inside.iter().find(|node| node.1.len() != n_s) {
            return Err(crate::error::BamudiError::dim(
                "residual vs covariance size",
                n_s,
                node.1.len(),
            ));
        }
        let stacked = DMatrix::from_fn(n_s, inside.len(), |s, c| inside[c].1[s]);
        // one value per column of `stacked`, so the iterator below never runs dry
        let mut with = self.factor.log_densities(&stacked)?.into_iter();
        Ok(per_node
            .iter()
            .map(|node| match node {
                Some((lp, _, iid)) => (lp + with.next().unwrap_or(f64::NAN), *iid),
                None => (f64::NEG_INFINITY, f64::NEG_INFINITY),
            })
            .collect())
    }
}
