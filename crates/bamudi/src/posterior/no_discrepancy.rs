//! The strongest calibration without a discrepancy: the baseline every before/after of the
//! project is measured against ("baseline (b)").
//!
//! The model is the multi-level model with `δ = 0` and everything else fitted:
//! `y = ρ A g(x, θ) + b(x, θ) + ε`, `ε ~ N(0, σ² I)`, with
//!
//! * `ρ` integrated over its uniform prior (the sampling rule's `rho_range`) in closed form
//!   (the exponent is quadratic in `ρ`; [`super::rho`]), and
//! * `σ²` profiled at each `θ`: its maximum-likelihood value `min_ρ |c − ρ a|² / (N_s − 1)`
//!   (`a = A g(θ)`, `c = y − b(θ)`, stacked). Holding the discrepancy model's *estimated*
//!   `σ_ε` instead would claim that a model without a discrepancy fits to the gauges' noise,
//!   and make its `θ` posterior as narrow as a fit that does. A noise the user states
//!   (`CalibrationParams::sigma_eps`) is held: it is a fact about the instrument, not a fit,
//!   and it makes this the calibration a peer without a discrepancy (KOH without `δ`,
//!   surmise's calibrators) runs on the same likelihood.
//!
//! Its `θ` posterior is [`super::Module3::posterior_no_discrepancy`] (Fig. 16's comparison);
//! its predictions are `ρ g(x, θ)` mixed over that posterior
//! ([`crate::Predictor::no_discrepancy_response`]). Earlier versions held `ρ = 1` and the
//! discrepancy model's `σ_ε`: the weakest possible baseline, which flattered every ratio
//! against it.

use super::model_rows;
use super::rho::{ThetaTerms, truncated_moments};
use super::theta::{SupportPolicy, ThetaPosterior};
use crate::error::Result;
use crate::surrogate::Problem;
use mlmodel::{LinearObservableModel, UnobservableModel};
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The no-discrepancy fit at one `θ`: the log likelihood with `ρ` integrated and `σ²`
/// profiled, and `ρ`'s conditional mean and variance.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FitAt {
    pub(crate) log_lik: f64,
    pub(crate) rho_mean: f64,
    pub(crate) rho_var: f64,
    pub(crate) sigma2: f64,
}

/// [`FitAt`] from the stacked columns `a = A g(θ)` and `c = y − b(θ)` (`N_s` each), with the
/// noise sd `known_sigma` the user stated, or profiled (`None`).
pub(crate) fn fit_at(
    a: &[f64],
    c: &[f64],
    rho_range: (f64, f64),
    known_sigma: Option<f64>,
) -> FitAt {
    let n_s = a.len();
    let dot = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(x, y)| x * y).sum::<f64>();
    let (aa, ac, cc) = (dot(a, a), dot(a, c), dot(c, c));
    let ssr = match aa > 1e-300 {
        true => cc - ac * ac / aa,
        false => cc,
    };
    let sigma2 = match known_sigma {
        Some(s) => s * s,
        None => (ssr / (n_s.max(2) - 1) as f64).max(1e-300),
    };
    let gram = DMatrix::from_row_slice(2, 2, &[aa, ac, ac, cc]) / sigma2;
    let terms = ThetaTerms::new(&gram, n_s as f64 * sigma2.ln(), n_s, rho_range);
    let (rho_mean, rho_var) = truncated_moments(terms.rho_hat, terms.q2, rho_range);
    FitAt {
        log_lik: terms.log_lik,
        rho_mean,
        rho_var,
        sigma2,
    }
}

/// The no-discrepancy calibration as Module 4 uses it: the support points of its `θ`
/// posterior with `ρ`'s conditional moments and the profiled noise at each.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoDiscrepancyFit {
    /// Support points.
    pub nodes: Vec<NoDiscrepancyNode>,
}

/// One support point of the no-discrepancy `θ` posterior.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoDiscrepancyNode {
    /// `θ`.
    pub theta: Vec<f64>,
    /// Posterior weight.
    pub weight: f64,
    /// `E[ρ | θ, y]`.
    pub rho_mean: f64,
    /// `Var(ρ | θ, y)`.
    pub rho_var: f64,
    /// The profiled noise sd at this `θ` (output units): how far the no-discrepancy model
    /// stays from the data.
    pub sigma_eps: f64,
}

impl NoDiscrepancyFit {
    /// The fit at the support points ([`SupportPolicy::default`]) of `posterior`, the
    /// no-discrepancy `θ` posterior of `p`'s data.
    pub(crate) fn new<U, O>(p: &Problem<'_, U, O>, posterior: &ThetaPosterior) -> Result<Self>
    where
        U: UnobservableModel,
        O: LinearObservableModel,
    {
        let rho_range = p.cfg.sampling.rho_range;
        let nodes = posterior
            .support(&SupportPolicy::default())
            .par_iter()
            .map(|(theta, weight)| {
                let (a, c) = stacked_rows(p, theta)?;
                let f = fit_at(&a, &c, rho_range, p.cfg.sigma_eps);
                Ok(NoDiscrepancyNode {
                    theta: theta.clone(),
                    weight: *weight,
                    rho_mean: f.rho_mean,
                    rho_var: f.rho_var,
                    sigma_eps: f.sigma2.sqrt(),
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { nodes })
    }

    /// Mean and sd of `ρ` over the mixture of the nodes' conditionals.
    ///
    /// ```
    /// use bamudi::posterior::{NoDiscrepancyFit, NoDiscrepancyNode};
    /// let node = |theta: f64, weight: f64, rho_mean: f64| NoDiscrepancyNode {
    ///     theta: vec![theta], weight, rho_mean, rho_var: 0.0, sigma_eps: 1.0,
    /// };
    /// let fit = NoDiscrepancyFit { nodes: vec![node(1.0, 0.5, 0.7), node(2.0, 0.5, 0.9)] };
    /// let (mean, sd) = fit.rho();
    /// assert!((mean - 0.8).abs() < 1e-12 && (sd - 0.1).abs() < 1e-12);
    /// ```
    pub fn rho(&self) -> (f64, f64) {
        let w: f64 = self.nodes.iter().map(|n| n.weight).sum::<f64>().max(1e-300);
        let mean = self
            .nodes
            .iter()
            .map(|n| n.weight * n.rho_mean)
            .sum::<f64>()
            / w;
        let second = self
            .nodes
            .iter()
            .map(|n| n.weight * (n.rho_var + n.rho_mean * n.rho_mean))
            .sum::<f64>()
            / w;
        (mean, (second - mean * mean).max(0.0).sqrt())
    }
}

/// `a = A g(x_i, θ)` and `c = y − b(x_i, θ)` stacked experiment-major (`N_s` each).
pub(crate) fn stacked_rows<U, O>(
    p: &Problem<'_, U, O>,
    theta: &[f64],
) -> Result<(Vec<f64>, Vec<f64>)>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let rows = model_rows(p, theta)?;
    let (n_e, n_o) = (p.exps.len(), p.exps.y.ncols());
    let mut a = Vec::with_capacity(n_e * n_o);
    let mut c = Vec::with_capacity(n_e * n_o);
    for i in 0..n_e {
        for q in 0..n_o {
            a.push(rows.ag[(i, q)]);
            c.push(p.exps.y[(i, q)] - rows.b[(i, q)]);
        }
    }
    Ok((a, c))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On data that are `ρ a` exactly plus a known residual orthogonal to `a`, the fit finds
    /// that `ρ` (well inside its prior), the profiled noise is the residual's mean square over
    /// `N_s − 1`, and `ρ`'s variance is `σ²/|a|²`.
    #[test]
    fn the_fit_recovers_rho_and_profiles_the_noise() {
        let a = [10.0, 20.0, 0.0, -10.0];
        let r = [0.5, 0.0, 1.0, 0.5]; // aᵀr = 5 + 0 + 0 − 5 = 0
        let c: Vec<f64> = a.iter().zip(&r).map(|(a, r)| 0.7 * a + r).collect();
        let f = fit_at(&a, &c, (0.0, 2.0), None);
        let ssr: f64 = r.iter().map(|v| v * v).sum();
        assert!((f.sigma2 - ssr / 3.0).abs() < 1e-12, "{}", f.sigma2);
        // ρ's posterior is N(0.7, σ²/600) truncated to [0, 2]: sd 0.029, 24 sd inside either
        // bound, so its moments are the untruncated ones to rounding
        assert!((f.rho_mean - 0.7).abs() < 1e-9, "{}", f.rho_mean);
        assert!(
            (f.rho_var / (f.sigma2 / 600.0) - 1.0).abs() < 1e-9,
            "{}",
            f.rho_var
        );
    }

    /// A noise sd the user states is held, not profiled: `ρ`'s variance is then `s²/|a|²`
    /// whatever the residual, and the log likelihood drops by the residual's `½ ssr/s²`.
    #[test]
    fn a_stated_noise_is_held() {
        let a = [10.0, 20.0, 0.0, -10.0];
        let r = [0.5, 0.0, 1.0, 0.5];
        let c: Vec<f64> = a.iter().zip(&r).map(|(a, r)| 0.7 * a + r).collect();
        let held = fit_at(&a, &c, (0.0, 2.0), Some(0.1));
        assert!((held.sigma2 - 0.01).abs() < 1e-15, "{}", held.sigma2);
        assert!((held.rho_var / (0.01 / 600.0) - 1.0).abs() < 1e-9);
        // the same data with a residual half as large: ½ (ssr − ssr/4)/s² more log likelihood
        let c2: Vec<f64> = a.iter().zip(&r).map(|(a, r)| 0.7 * a + 0.5 * r).collect();
        let closer = fit_at(&a, &c2, (0.0, 2.0), Some(0.1));
        let ssr: f64 = r.iter().map(|v| v * v).sum();
        let gain = closer.log_lik - held.log_lik;
        assert!((gain - 0.5 * 0.75 * ssr / 0.01).abs() < 1e-6, "{gain}");
    }
}
