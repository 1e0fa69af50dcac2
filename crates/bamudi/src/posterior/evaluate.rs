//! The Module-3 residuals and log densities at a candidate `θ`.

use super::conditional::{ConditionalCoefficients, ModelRows};
use super::likelihood::FactoredCovariance;
use super::theta::{SupportPolicy, ThetaPosterior};
use super::{grid, model_rows, no_discrepancy};
use crate::error::Result;
use crate::observe::{Observer, Stage, tick};
use crate::surrogate::Problem;
use mlmodel::{LinearObservableModel, UnobservableModel};
use nalgebra::DMatrix;
use rayon::prelude::*;

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
    /// without it (`no_discrepancy`).
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
    pub(crate) fn posterior_mean_delta(
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
    /// [`log_posteriors`](grid::LogPosteriors::log_posteriors) node by node, up to round-off.
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
