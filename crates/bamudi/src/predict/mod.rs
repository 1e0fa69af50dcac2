//! Module 4 of BA-MUDI (paper Sec. 3.5, Eq. 44 and 52): predictions of the corrected
//! distributed response and of the observable outputs at new inputs, with bands.
//!
//! There is one predictor, [`Predictor`], built by [`Calibration::predictor`]; it checks once
//! that the model it is given is the one that was calibrated, and it stands for the `θ`
//! posterior by the points of one documented [`SupportPolicy`]. Every mixture below is over
//! those points `θ_j` with weights `w_j`:
//!
//! * response (Eq. 52): `Σ_j w_j N(ρ* g_u(x, θ_j) + L μ_α(x), diag(L Σ_α(x) Lᵀ))`;
//! * outputs (Eq. 44): `Σ_j w_j N(ρ* A g_u(x, θ_j) + b(x, θ_j) + B μ_α(x), diag(B Σ_α(x) Bᵀ))`,
//!   the noise-free output (add `σ_ε²` for a new measurement);
//!
//! with `μ_α`, `Σ_α` the coefficient GPs' latent means and variances (independent GPs, so
//! `Σ_α` is diagonal), shifted in the conditional mode by the posterior-averaged coefficient
//! change ([`crate::posterior::ConditionalFit::alpha_correction`]).
//!
//! With declared build tolerances (marginal mode; `nuisance`) the
//! deviations `η` enter every prediction as they entered the data: each component's mean gains
//! `J(x) η̂` (outputs) or `R(x) η̂` (response, `R = ρ (g⁺ − g⁻) / 2`), its variance
//! `diag(J M⁻¹ Jᵀ) + 2 diag(B C Jᵀ)` (with `L`, `R` for the response), `M⁻¹ = Var(η | y)` and
//! `C = Cov(α(x), η | y)`. Like Module 3, the columns are taken at the posterior mode `θ̄` for
//! every support point and `η̂` is Module 3's posterior mean there. Where the unobservable response
//! vanishes ([`mlmodel::UnobservableModel::response_vanishes`], e.g. a gate with no head) the
//! discrepancy, which corrects that response, is zero.

mod draws;

pub use draws::{DrawPaths, ResponseDraw, empirical_band};

use crate::calibration::Calibration;
use crate::error::{BamudiError, Result};
use crate::posterior::marginal::nuisance::{ToleranceColumns, columns_at};
use crate::posterior::marginal::{MarginalFit, MarginalNode, MarginalState, NodeTerms};
use crate::posterior::theta::SupportPolicy;
use mlmodel::{LinearObservableModel, MultiLevelModel, UnobservableModel};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Mixture components (mean and variance per point) and their weights.
type Mixture = (Vec<(Vec<f64>, Vec<f64>)>, Vec<f64>);

/// Below this posterior probability the calibration without a discrepancy is left out of the
/// mixtures ([`Predictor::probability_without`]): it would move a mean by less than `1e-9` of
/// the two models' difference, and evaluating its points costs one model run each.
pub const NEGLIGIBLE_MODEL_WEIGHT: f64 = 1e-9;

/// A distributed or output prediction with its 95 % credible band.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Band {
    /// Posterior predictive mean.
    pub mean: Vec<f64>,
    /// Posterior predictive standard deviation.
    pub sd: Vec<f64>,
    /// 2.5 % quantile.
    pub lower: Vec<f64>,
    /// 97.5 % quantile.
    pub upper: Vec<f64>,
}

/// Module-4 predictions of a calibration on its model (see the module docs), made by
/// [`Calibration::predictor`]; an example: [`crate::calibrate`].
pub struct Predictor<'a, U, O> {
    cal: &'a Calibration,
    model: &'a MultiLevelModel<U, O>,
    support: Vec<(Vec<f64>, f64)>,
    marginal: Option<MarginalView<'a>>,
}

/// The marginal mode's state and its support nodes (grouped to the support policy).
struct MarginalView<'a> {
    fit: &'a MarginalFit,
    state: std::sync::Arc<MarginalState>,
    nodes: Vec<MarginalNode>,
    /// The nodes' projected residual columns ([`MarginalState::node_terms`]).
    terms: NodeTerms,
    /// `ρ`'s conditional mean at each node.
    rhos: Vec<f64>,
}

/// The coefficients' posterior at one input, per support point: mean and its derivative in
/// `ρ` (`K` each), `ρ`'s mean and variance; and one covariance (`K x K`).
struct CoefAt {
    mean: Vec<DVector<f64>>,
    slope: Vec<DVector<f64>>,
    rho: Vec<(f64, f64)>,
    cov: DMatrix<f64>,
    /// The declared tolerances' deviations (marginal mode; `None` when none were declared).
    tolerance: Option<ToleranceAt>,
}

/// The declared tolerances' deviations `η` given the data: mean (`P`; Module 3's, at the
/// posterior mode `θ̄`), covariance `M⁻¹` (`P x P`) and covariance with the coefficients at the
/// input (`K x P`, [`MarginalState::tolerance_cross`]).
struct ToleranceAt {
    mean: DVector<f64>,
    cov: DMatrix<f64>,
    cross: DMatrix<f64>,
}

impl Calibration {
    /// The Module-4 predictor on `model`, which must be the calibrated model: same input and
    /// output names, response length, discrepancy basis size and matrix `A` (checked here,
    /// once). The `θ` posterior is represented by [`SupportPolicy::default`].
    pub fn predictor<'a, U, O>(
        &'a self,
        model: &'a MultiLevelModel<U, O>,
    ) -> Result<Predictor<'a, U, O>>
    where
        U: UnobservableModel,
        O: LinearObservableModel,
    {
        self.check_model(model)?;
        let mut p = Predictor {
            cal: self,
            model,
            support: Vec::new(),
            marginal: None,
        };
        p.set_support(&SupportPolicy::default())?;
        Ok(p)
    }
}

impl<U: UnobservableModel, O: LinearObservableModel> Predictor<'_, U, O> {
    /// Uses `policy` for the `θ` posterior's support points (fewer points: faster mixtures).
    pub fn support_policy(mut self, policy: &SupportPolicy) -> Result<Self> {
        self.set_support(policy)?;
        Ok(self)
    }

    fn set_support(&mut self, policy: &SupportPolicy) -> Result<()> {
        let m3 = self.cal.module3();
        match m3.marginal() {
            None => self.support = m3.posterior.support(policy),
            Some(fit) => {
                // one test of "tolerances declared" for every entry point below
                if fit.tolerances.is_empty() != fit.tolerance_columns.is_none() {
                    return Err(BamudiError::Calibration(
                        "the marginal fit has tolerance estimates without their columns, or the \
                         reverse (an edited calibration file?)"
                            .into(),
                    ));
                }
                let nodes = fit.grouped_nodes(policy.max_nodes);
                self.support = nodes.iter().map(|n| (n.theta.clone(), n.weight)).collect();
                let state = self.cal.marginal_state()?;
                let terms = state.node_terms(&nodes)?;
                let rhos = nodes.iter().map(|n| n.rho_mean).collect();
                self.marginal = Some(MarginalView {
                    fit,
                    state,
                    nodes,
                    terms,
                    rhos,
                });
            }
        }
        Ok(())
    }

    /// The support points `(θ_j, w_j)` of the mixtures.
    pub fn support(&self) -> &[(Vec<f64>, f64)] {
        &self.support
    }

    /// The model the predictions are made with.
    pub fn model(&self) -> &MultiLevelModel<U, O> {
        self.model
    }

    /// Means and latent variances of the discrepancy coefficients at the rows of `x` (two
    /// `N x K` matrices; the marginal mode's means are averaged over the `θ` posterior), zero
    /// at rows where the response vanishes. The discrepancy model's, also when the two models
    /// were weighed ([`Self::discrepancy`] is the weighed correction).
    pub(crate) fn alpha_moments(&self, x: &DMatrix<f64>) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        self.check_x(x.ncols())?;
        let (mut mean, mut var) = match &self.marginal {
            None => self.cal.alpha_moments(x)?,
            Some(_) => self.marginal_alpha_moments(x)?,
        };
        for i in 0..x.nrows() {
            let xi: Vec<f64> = x.row(i).iter().copied().collect();
            if self.model.unobservable.response_vanishes(&xi) {
                mean.row_mut(i).fill(0.0);
                var.row_mut(i).fill(0.0);
            }
        }
        Ok((mean, var))
    }

    /// The corrected distributed response at `x` (Eq. 52; component blocked, length `C N_u`).
    ///
    /// When the models with and without a discrepancy were weighed
    /// (`average`), the band is their mixture: this calibration's components
    /// with weight `P(M_1 | y)`, the no-discrepancy fit's with `P(M_0 | y)`.
    pub fn response(&self, x: &[f64]) -> Result<Band> {
        let (comps, w) = self.response_mixture(x)?;
        Ok(mixture_band(&comps, &w))
    }

    /// Mean and variance of the corrected distributed response at `x`: the moments of
    /// [`Self::response`]'s mixture (its `mean`, and the variance whose square root is its
    /// `sd`, bit for bit) without the band's quantiles, two mixture-quantile searches per
    /// point that took about half of `response`'s time in the paper-size profile: for callers
    /// that want only the mean, such as an error score. Checked against `response` in the
    /// crate tests (`response_moments_are_the_bands_moments`).
    ///
    /// ```
    /// use bamudi::Predictor;
    /// use mlmodel::{LinearObservableModel, UnobservableModel};
    /// /// The RMS error of the corrected response against a known truth at `x`.
    /// fn rmse<U: UnobservableModel, O: LinearObservableModel>(
    ///     p: &Predictor<'_, U, O>,
    ///     x: &[f64],
    ///     truth: &[f64],
    /// ) -> bamudi::Result<f64> {
    ///     let (mean, _var) = p.response_moments(x)?; // no quantile searches
    ///     let sq: f64 = mean.iter().zip(truth).map(|(m, t)| (m - t).powi(2)).sum();
    ///     Ok((sq / mean.len() as f64).sqrt())
    /// }
    /// ```
    pub fn response_moments(&self, x: &[f64]) -> Result<(Vec<f64>, Vec<f64>)> {
        let (comps, w) = self.response_mixture(x)?;
        Ok(mixture_moments(&comps, &w))
    }

    /// The components and weights of [`Self::response`]'s mixture.
    fn response_mixture(&self, x: &[f64]) -> Result<Mixture> {
        let at = self.coef_at(x)?;
        let comps = self.response_components_at(x, &at)?;
        let mut g = vec![0.0; self.model.unobservable.response_len()];
        let spread = || projected_variance(self.basis().0, &at.cov);
        self.with_model_without(comps, spread, |theta| {
            self.model.unobservable.evaluate(x, theta, &mut g)?;
            Ok((DVector::from_column_slice(&g), DVector::zeros(g.len())))
        })
    }

    /// `P(M_0 | y)`, the weight of the calibration without a discrepancy in this predictor's
    /// mixtures (`average`): `0` unless the two models were weighed, and
    /// below [`NEGLIGIBLE_MODEL_WEIGHT`].
    pub fn probability_without(&self) -> f64 {
        match self.cal.module3().averaged() {
            Some(a) if a.probability_without >= NEGLIGIBLE_MODEL_WEIGHT => a.probability_without,
            _ => 0.0,
        }
    }

    /// Model 1's components `comps` (the support's weights) joined, when the two models were
    /// weighed, by model 0's (the no-discrepancy fit's points; `parts` gives the model's parts
    /// at a `θ`), each model's weights scaled by its posterior probability. Model 0's
    /// components keep the spread of the discrepancy model 1 cannot exclude (`spread`: the
    /// variance of its correction at `x`, mostly the directions the gauges do not see): the
    /// evidence says the data need no correction, not that the model is exact.
    fn with_model_without(
        &self,
        comps: Vec<(Vec<f64>, Vec<f64>)>,
        spread: impl FnOnce() -> Vec<f64>,
        parts: impl FnMut(&[f64]) -> Result<(DVector<f64>, DVector<f64>)>,
    ) -> Result<Mixture> {
        let mut w = self.weights();
        let p0 = self.probability_without();
        if p0 == 0.0 {
            return Ok((comps, w));
        }
        let (mut c0, w0) = self.no_discrepancy_components(parts)?;
        let spread = spread();
        for c in &mut c0 {
            c.1.iter_mut().zip(&spread).for_each(|(v, s)| *v += s);
        }
        w.iter_mut().for_each(|v| *v *= 1.0 - p0);
        w.extend(w0.iter().map(|v| v * p0));
        let mut comps = comps;
        comps.extend(c0);
        Ok((comps, w))
    }

    /// The response mixture's components at `x` (mean and variance per point, per support
    /// point).
    fn response_components_at(&self, x: &[f64], at: &CoefAt) -> Result<Vec<(Vec<f64>, Vec<f64>)>> {
        let cols = self.tolerance_columns(x, at)?;
        let l = self.basis().0;
        let mut g = vec![0.0; l.nrows()];
        let tol = cols.as_ref().map(|c| &c.response);
        self.components(at, l, tol, |theta| {
            self.model.unobservable.evaluate(x, theta, &mut g)?;
            Ok((DVector::from_column_slice(&g), DVector::zeros(g.len())))
        })
    }

    /// The noise-free observable outputs at `x` (Eq. 44); add `σ_ε²` for a new measurement.
    pub fn outputs(&self, x: &[f64]) -> Result<Band> {
        let at = self.coef_at(x)?;
        let cols = self.tolerance_columns(x, &at)?;
        let tol = cols.as_ref().map(|c| &c.observed);
        let comps =
            self.components(&at, self.basis().1, tol, |theta| self.model_parts(x, theta))?;
        let spread = || projected_variance(self.basis().1, &at.cov);
        let (comps, w) =
            self.with_model_without(comps, spread, |theta| self.model_parts(x, theta))?;
        Ok(mixture_band(&comps, &w))
    }

    /// The reconstructed discrepancy `L μ_α(x)` (posterior-averaged in the marginal mode) with
    /// a 95 % band `± 1.96 sd` from the coefficients' covariance (Eq. 37; Fig. 15). When the
    /// two models were weighed ([`Self::probability_without`] `= p0`), the correction is zero
    /// with probability `p0`, keeping its spread `v` (as in [`Self::response`]): mean
    /// `(1 − p0) m`, variance `v + p0 (1 − p0) m²`.
    pub fn discrepancy(&self, x: &[f64]) -> Result<Band> {
        let at = self.coef_at(x)?;
        let l = self.basis().0;
        let w = self.weights();
        let mu = at
            .mean
            .iter()
            .zip(&w)
            .fold(DVector::zeros(at.cov.nrows()), |acc, (m, w)| acc + m * *w);
        let m1: Vec<f64> = (l * mu).iter().copied().collect();
        let q = 1.0 - self.probability_without();
        let mean: Vec<f64> = m1.iter().map(|m| q * m).collect();
        let sd: Vec<f64> = projected_variance(l, &at.cov)
            .into_iter()
            .zip(&m1)
            .map(|(v, m)| match q == 1.0 {
                true => v.sqrt(),
                false => (v + q * (1.0 - q) * m * m).max(0.0).sqrt(),
            })
            .collect();
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

    /// The strongest prediction without a discrepancy at `x`: `ρ g_u(x, θ)` mixed over the
    /// no-discrepancy calibration's `θ` posterior with `ρ`'s conditional moments at each point
    /// (`no_discrepancy`; baseline (b) of every before/after). An error for
    /// a calibration saved before that fit was kept.
    pub fn no_discrepancy_response(&self, x: &[f64]) -> Result<Band> {
        self.check_x(x.len())?;
        let mut g = vec![0.0; self.model.unobservable.response_len()];
        self.no_discrepancy_mixture(|theta| {
            self.model.unobservable.evaluate(x, theta, &mut g)?;
            Ok((DVector::from_column_slice(&g), DVector::zeros(g.len())))
        })
    }

    /// The noise-free outputs of the no-discrepancy calibration at `x`: `ρ A g_u(x, θ) +
    /// b(x, θ)` mixed as in [`no_discrepancy_response`](Self::no_discrepancy_response).
    pub fn no_discrepancy_outputs(&self, x: &[f64]) -> Result<Band> {
        self.check_x(x.len())?;
        self.no_discrepancy_mixture(|theta| self.model_parts(x, theta))
    }

    /// The mixture `Σ_j w_j N(ρ_j u_j + v_j, var(ρ_j) u_j²)` over the no-discrepancy fit's
    /// points, `(u_j, v_j) = parts(θ_j)`.
    fn no_discrepancy_mixture(
        &self,
        parts: impl FnMut(&[f64]) -> Result<(DVector<f64>, DVector<f64>)>,
    ) -> Result<Band> {
        let (comps, w) = self.no_discrepancy_components(parts)?;
        Ok(mixture_band(&comps, &w))
    }

    /// The no-discrepancy fit's points (an error for a calibration saved without it).
    fn no_discrepancy_nodes(
        &self,
    ) -> Result<&[crate::posterior::no_discrepancy::NoDiscrepancyNode]> {
        self.cal
            .module3()
            .no_discrepancy
            .as_ref()
            .map(|f| f.nodes.as_slice())
            .ok_or_else(|| {
                BamudiError::Calibration(
                    "this calibration has no no-discrepancy fit (`no_discrepancy_fit = false`, or \
                     saved by an older version): calibrate again with it to compare against it"
                        .into(),
                )
            })
    }

    /// The components and weights of [`Self::no_discrepancy_mixture`].
    fn no_discrepancy_components(
        &self,
        mut parts: impl FnMut(&[f64]) -> Result<(DVector<f64>, DVector<f64>)>,
    ) -> Result<Mixture> {
        let nodes = self.no_discrepancy_nodes()?;
        let comps = nodes
            .iter()
            .map(|n| {
                let (u, v) = parts(&n.theta)?;
                let mean = (0..u.len()).map(|q| n.rho_mean * u[q] + v[q]).collect();
                let var = u.iter().map(|u| n.rho_var * u * u).collect();
                Ok((mean, var))
            })
            .collect::<Result<Vec<_>>>()?;
        let w: Vec<f64> = nodes.iter().map(|n| n.weight).collect();
        Ok((comps, w))
    }

    /// Mean and variance of the noise-free outputs at every row of `x` (`N x N_o` each): the
    /// Eq.-44 mixture's moments, without quantiles, for many rows at once (rows in parallel).
    pub fn output_moments(&self, x: &DMatrix<f64>) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        self.check_x(x.ncols())?;
        let bm = self.basis().1;
        let rows = (0..x.nrows())
            .into_par_iter()
            .map(|i| {
                let xi: Vec<f64> = x.row(i).iter().copied().collect();
                let at = self.coef_at(&xi)?;
                let cols = self.tolerance_columns(&xi, &at)?;
                let tol = cols.as_ref().map(|c| &c.observed);
                let comps = self.components(&at, bm, tol, |theta| self.model_parts(&xi, theta))?;
                let spread = || projected_variance(bm, &at.cov);
                let (comps, w) =
                    self.with_model_without(comps, spread, |theta| self.model_parts(&xi, theta))?;
                Ok(mixture_moments(&comps, &w))
            })
            .collect::<Result<Vec<_>>>()?;
        let n_o = bm.nrows();
        let mean = DMatrix::from_fn(x.nrows(), n_o, |i, q| rows[i].0[q]);
        let var = DMatrix::from_fn(x.nrows(), n_o, |i, q| rows[i].1[q]);
        Ok((mean, var))
    }

    /// Eq. 50 at a given `θ` per row: `ρ A g_u(x_i, θ_i) + b(x_i, θ_i) + B μ_α(x_i)`
    /// (`N x N_o`; the coefficients' posterior-averaged mean and `ρ`'s posterior mean are
    /// used at every `θ`). The discrepancy model's, also when the two models were weighed
    /// ([`Self::probability_without`]): a caller that sets it against the mixed
    /// [`Self::output_moments`] should calibrate with `presence = "assumed"` (the close loop's
    /// gate calibrator fits no model without a discrepancy, so nothing is weighed there).
    pub fn outputs_at_theta(&self, x: &DMatrix<f64>, theta: &[Vec<f64>]) -> Result<DMatrix<f64>> {
        if theta.len() != x.nrows() {
            return Err(BamudiError::dim(
                "theta values vs rows",
                x.nrows(),
                theta.len(),
            ));
        }
        let (mu, _) = self.alpha_moments(x)?;
        let bm = self.basis().1;
        let rho = self.cal.rho_star();
        let rows = (0..x.nrows())
            .into_par_iter()
            .map(|i| {
                let xi: Vec<f64> = x.row(i).iter().copied().collect();
                let (ag, off) = self.model_parts(&xi, &theta[i])?;
                let shift = self.tolerance_output_shift(&xi)?;
                Ok(ag * rho + off + bm * mu.row(i).transpose() + shift)
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(DMatrix::from_fn(x.nrows(), bm.nrows(), |i, q| rows[i][q]))
    }

    /// Mean outputs at every row of `x` for each of `thetas` (one `n x N_o` matrix per `θ`):
    /// [`Self::outputs_at_theta`] with every row at the same `θ`, the coefficients' posterior at
    /// `x` (which does not depend on `θ`) computed once for all of them.
    pub fn outputs_at_thetas(
        &self,
        x: &DMatrix<f64>,
        thetas: &[Vec<f64>],
    ) -> Result<Vec<DMatrix<f64>>> {
        let (mu, _) = self.alpha_moments(x)?;
        let bm = self.basis().1;
        let rho = self.cal.rho_star();
        let n = x.nrows();
        let shifts = (0..n)
            .into_par_iter()
            .map(|i| self.tolerance_output_shift(&x.row(i).iter().copied().collect::<Vec<_>>()))
            .collect::<Result<Vec<_>>>()?;
        let cells = (0..n * thetas.len())
            .into_par_iter()
            .map(|k| {
                let (j, i) = (k / n, k % n);
                let xi: Vec<f64> = x.row(i).iter().copied().collect();
                let (ag, off) = self.model_parts(&xi, &thetas[j])?;
                Ok(ag * rho + off + bm * mu.row(i).transpose() + &shifts[i])
            })
            .collect::<Result<Vec<_>>>()?;
        Ok((0..thetas.len())
            .map(|j| DMatrix::from_fn(n, bm.nrows(), |i, q| cells[j * n + i][q]))
            .collect())
    }

    /// `A g_u(x, θ)` and `b(x, θ)` (output units).
    fn model_parts(&self, x: &[f64], theta: &[f64]) -> Result<(DVector<f64>, DVector<f64>)> {
        let row = self.model.model_row(x, theta)?;
        let n_o = row.len() / 2;
        Ok((
            DVector::from_column_slice(&row[..n_o]),
            DVector::from_column_slice(&row[n_o..]),
        ))
    }

    /// The coefficients' posterior at `x` for every support point (zero where the response
    /// vanishes).
    fn coef_at(&self, x: &[f64]) -> Result<CoefAt> {
        self.check_x(x.len())?;
        let n = self.support.len();
        let mut at = match &self.marginal {
            None => {
                let (mu, var) = self
                    .cal
                    .alpha_moments(&DMatrix::from_row_slice(1, x.len(), x))?;
                let mean = mu.row(0).transpose();
                CoefAt {
                    slope: vec![DVector::zeros(mean.len()); n],
                    rho: vec![(self.cal.rho_star(), 0.0); n],
                    cov: DMatrix::from_diagonal(&var.row(0).transpose()),
                    mean: vec![mean; n],
                    tolerance: None,
                }
            }
            Some(view) => self.marginal_coef_at(view, x)?,
        };
        if self.model.unobservable.response_vanishes(x) {
            at.mean
                .iter_mut()
                .chain(at.slope.iter_mut())
                .for_each(|m| m.fill(0.0));
            at.cov.fill(0.0);
            if let Some(t) = &mut at.tolerance {
                t.cross.fill(0.0);
            }
        }
        Ok(at)
    }

    fn marginal_coef_at(&self, view: &MarginalView<'_>, x: &[f64]) -> Result<CoefAt> {
        let ax = self.coefficient_scales(view.fit, x)?;
        let cross = view
            .state
            .cross_cov(view.fit, x, &ax, self.cal.x_experiments());
        let (mean, slope) = view
            .state
            .coefficient_means(&cross, &view.terms, &view.rhos)
            .into_iter()
            .unzip();
        let rho = view.nodes.iter().map(|n| (n.rho_mean, n.rho_var)).collect();
        let cov = view.state.coefficient_cov(view.fit, x, &ax, &cross);
        let tolerance = match view.state.tolerance_cross(&cross) {
            None => None,
            Some((cross, m_inv)) => Some(ToleranceAt {
                mean: tolerance_means(view.fit, m_inv.nrows())?,
                cov: m_inv.clone(),
                cross,
            }),
        };
        Ok(CoefAt {
            mean,
            slope,
            rho,
            cov,
            tolerance,
        })
    }

    /// The declared tolerances' columns at `x` when `at` carries tolerances: taken, as
    /// Module 3 took them, at the posterior mode `θ̄` (and here `ρ`'s posterior mean) for
    /// every support point.
    fn tolerance_columns(&self, x: &[f64], at: &CoefAt) -> Result<Option<ToleranceColumns>> {
        match (self.tolerance_view(), &at.tolerance) {
            (Some(view), Some(_)) => Ok(Some(self.columns_at_mode(view, x)?)),
            _ => Ok(None),
        }
    }

    /// The marginal view when the calibration integrated declared tolerances.
    fn tolerance_view(&self) -> Option<&MarginalView<'_>> {
        self.marginal
            .as_ref()
            .filter(|v| !v.fit.tolerances.is_empty())
    }

    /// The tolerances' columns at `x`, at the posterior mode `θ̄` and `ρ`'s posterior mean.
    fn columns_at_mode(&self, view: &MarginalView<'_>, x: &[f64]) -> Result<ToleranceColumns> {
        columns_at(self.model, x, &view.fit.support_theta, view.fit.rho_mean)
    }

    /// The number of declared tolerances the predictions carry (marginal mode).
    fn n_tolerances(&self) -> usize {
        self.marginal.as_ref().map_or(0, |v| v.fit.tolerances.len())
    }

    /// `J(x) η̂`: the declared tolerances' mean contribution to the outputs at `x` (zero
    /// without tolerances).
    fn tolerance_output_shift(&self, x: &[f64]) -> Result<DVector<f64>> {
        let Some(view) = self.tolerance_view() else {
            return Ok(DVector::zeros(self.basis().1.nrows()));
        };
        let eta = tolerance_means(view.fit, view.fit.tolerances.len())?;
        Ok(self.columns_at_mode(view, x)?.observed * eta)
    }

    /// The coefficients' prior scales `a_k(x)` of the marginal mode, by the rule Module 3 used
    /// (zero where the response vanishes).
    fn coefficient_scales(&self, fit: &MarginalFit, x: &[f64]) -> Result<Vec<f64>> {
        if self.model.unobservable.response_vanishes(x) {
            return Ok(vec![0.0; fit.priors.len()]);
        }
        let (cal, m2) = (self.cal, self.cal.module2());
        // a loaded calibration's fit is its configured mode's (`Calibration::validate`)
        let prior = cal.config().coefficients.marginal_prior().ok_or_else(|| {
            BamudiError::Calibration("a marginal fit in a calibration of another mode".into())
        })?;
        let ctx = crate::surrogate::training::x_context(
            self.model,
            cal.parts(),
            &m2.theta_rule,
            &cal.config().sampling,
            x,
        )?;
        Ok(crate::posterior::marginal::prior_scales(
            &ctx,
            &self.model.basis,
            prior.scales,
        ))
    }

    /// The discrepancy basis `L` and `B` of the predictions: the marginal mode's supported
    /// basis, otherwise the model's.
    fn basis(&self) -> (&DMatrix<f64>, &DMatrix<f64>) {
        match &self.marginal {
            Some(view) => view.state.basis(),
            None => (&self.cal.parts().l, &self.cal.parts().b),
        }
    }

    /// The marginal mode's coefficient means (averaged over the nodes) and variances.
    fn marginal_alpha_moments(&self, x: &DMatrix<f64>) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        let k = self.basis().1.ncols();
        let w = self.weights();
        let rows = (0..x.nrows())
            .into_par_iter()
            .map(|i| {
                let xi: Vec<f64> = x.row(i).iter().copied().collect();
                let at = self.coef_at(&xi)?;
                let mu = at
                    .mean
                    .iter()
                    .zip(&w)
                    .fold(DVector::zeros(k), |a, (m, w)| a + m * *w);
                Ok((mu, at.cov.diagonal()))
            })
            .collect::<Result<Vec<_>>>()?;
        let mean = DMatrix::from_fn(x.nrows(), k, |i, c| rows[i].0[c]);
        let var = DMatrix::from_fn(x.nrows(), k, |i, c| rows[i].1[c]);
        Ok((mean, var))
    }

    /// Mixture components at the support points: mean `ρ_j u_j + v_j + M μ_j` and variance
    /// `diag(M Σ Mᵀ) + var(ρ_j) (u_j + M ∂μ_j/∂ρ)²`, where `(u_j, v_j) = parts(θ_j)` is the
    /// model's response (times `ρ`) and offset at `θ_j`, and `M` is `L` or `B`.
    fn components(
        &self,
        at: &CoefAt,
        m: &DMatrix<f64>,
        tol: Option<&DMatrix<f64>>,
        mut parts: impl FnMut(&[f64]) -> Result<(DVector<f64>, DVector<f64>)>,
    ) -> Result<Vec<(Vec<f64>, Vec<f64>)>> {
        let mut gauss_var = projected_variance(m, &at.cov);
        let mut tol_mean = DVector::zeros(m.nrows());
        if let Some((mean, var)) = tolerance_moments(at, m, tol) {
            tol_mean = mean;
            for (g, v) in gauss_var.iter_mut().zip(var) {
                // a joint Gaussian's marginal variance: non-negative up to rounding
                *g = (*g + v).max(0.0);
            }
        }
        self.support
            .iter()
            .enumerate()
            .map(|(j, (theta, _))| {
                let (u, v) = parts(theta)?;
                let (rho, rho_var) = at.rho[j];
                let shift = m * &at.mean[j] + &tol_mean;
                let slope = &u + m * &at.slope[j];
                let mean = (0..u.len()).map(|q| rho * u[q] + v[q] + shift[q]).collect();
                let var = (0..u.len())
                    .map(|q| gauss_var[q] + rho_var * slope[q] * slope[q])
                    .collect();
                Ok((mean, var))
            })
            .collect()
    }

    fn weights(&self) -> Vec<f64> {
        self.support.iter().map(|s| s.1).collect()
    }

    fn check_x(&self, len: usize) -> Result<()> {
        let want = self.cal.input_names().len();
        if len != want {
            return Err(BamudiError::dim("prediction input x", want, len));
        }
        Ok(())
    }
}

/// The means `η̂` of the `p` declared tolerances of `fit` (Module 3's posterior at `θ̄`).
fn tolerance_means(fit: &MarginalFit, p: usize) -> Result<DVector<f64>> {
    if fit.tolerances.len() != p {
        return Err(BamudiError::dim(
            "tolerance estimates vs tolerance columns of the marginal fit",
            p,
            fit.tolerances.len(),
        ));
    }
    Ok(DVector::from_iterator(
        p,
        fit.tolerances.iter().map(|t| t.mean),
    ))
}

/// What the declared tolerances add to every mixture component through their columns `cols`
/// in `m`'s space (outputs or response): mean `cols η̂`, variance
/// `diag(cols M⁻¹ colsᵀ) + 2 diag(m C colsᵀ)` with `C = Cov(α, η | y)`; `None` without.
fn tolerance_moments(
    at: &CoefAt,
    m: &DMatrix<f64>,
    cols: Option<&DMatrix<f64>>,
) -> Option<(DVector<f64>, Vec<f64>)> {
    let (t, cols) = (at.tolerance.as_ref()?, cols?);
    let own = cols * &t.cov;
    let cross = m * &t.cross;
    let var = (0..cols.nrows())
        .map(|q| own.row(q).dot(&cols.row(q)) + 2.0 * cross.row(q).dot(&cols.row(q)))
        .collect();
    Some((cols * &t.mean, var))
}

/// `diag(m Σ mᵀ)`: the variance of `m α` for coefficients of covariance `Σ`.
fn projected_variance(m: &DMatrix<f64>, cov: &DMatrix<f64>) -> Vec<f64> {
    let diagonal = (0..cov.nrows()).all(|i| (0..cov.ncols()).all(|j| i == j || cov[(i, j)] == 0.0));
    (0..m.nrows())
        .map(|r| {
            if diagonal {
                (0..m.ncols())
                    .map(|k| m[(r, k)].powi(2) * cov[(k, k)])
                    .sum::<f64>()
            } else {
                let row = m.row(r);
                (row * cov * row.transpose())[(0, 0)].max(0.0)
            }
        })
        .collect()
}

/// Mean and variance per point of the mixture `Σ_j w_j N(mean_j, var_j)`.
fn mixture_moments(comps: &[(Vec<f64>, Vec<f64>)], weights: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let n = comps.first().map_or(0, |c| c.0.len());
    let mut mean = vec![0.0; n];
    let mut var = vec![0.0; n];
    for b in 0..n {
        let m: f64 = comps.iter().zip(weights).map(|(c, w)| c.0[b] * w).sum();
        let between: f64 = comps
            .iter()
            .zip(weights)
            .map(|(c, w)| w * (c.0[b] - m).powi(2))
            .sum();
        let within: f64 = comps.iter().zip(weights).map(|(c, w)| w * c.1[b]).sum();
        mean[b] = m;
        var[b] = between + within;
    }
    (mean, var)
}

/// A band from mixture components (mean and variance per point) and their weights.
fn mixture_band(comps: &[(Vec<f64>, Vec<f64>)], weights: &[f64]) -> Band {
    let (mean, var) = mixture_moments(comps, weights);
    let n = mean.len();
    let (mut lower, mut upper) = (vec![0.0; n], vec![0.0; n]);
    for b in 0..n {
        let ms: Vec<f64> = comps.iter().map(|c| c.0[b]).collect();
        let sds: Vec<f64> = comps.iter().map(|c| c.1[b].sqrt()).collect();
        lower[b] = mixture_quantile(&ms, weights, &sds, 0.025);
        upper[b] = mixture_quantile(&ms, weights, &sds, 0.975);
    }
    Band {
        mean,
        sd: var.into_iter().map(f64::sqrt).collect(),
        lower,
        upper,
    }
}

/// Standard normal CDF.
fn normal_cdf(z: f64) -> f64 {
    0.5 * statrs::function::erf::erfc(-z / std::f64::consts::SQRT_2)
}

/// Standard normal density.
fn normal_pdf(z: f64) -> f64 {
    (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt()
}

/// Quantile `p` (`0 < p < 1`) of the Gaussian mixture `Σ w_j N(m_j, s_j²)` (weights summing to
/// one).
///
/// The quantile lies between the smallest and the largest of the components' own `p`-quantiles
/// `m_j + s_j z_p` (at the smallest every component's CDF is at most `p`, at the largest at
/// least `p`), so that bracket is exact and tight; Newton steps on the mixture CDF (its
/// derivative is the mixture density) converge in a few iterations, and a step that leaves the
/// bracket is replaced by bisection, so the search always ends. The band of a 1,018-point
/// response costs two of these per point: the former plain bisection over ±10 sd took about
/// 45 CDF evaluations each and was half of `reproduce-paper`'s samples (docs/benchmarks.md).
fn mixture_quantile(means: &[f64], weights: &[f64], sds: &[f64], p: f64) -> f64 {
    let floor = 1e-12 * (1.0 + means.iter().fold(0.0f64, |a, m| a.max(m.abs())));
    let sds: Vec<f64> = sds.iter().map(|s| s.max(floor)).collect();
    let z_p = std::f64::consts::SQRT_2 * statrs::function::erf::erf_inv(2.0 * p - 1.0);
    let (mut lo, mut hi) = means
        .iter()
        .zip(&sds)
        .map(|(m, s)| m + s * z_p)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), q| {
            (a.min(q), b.max(q))
        });
    // f(v) = mixture CDF − p and its derivative, the mixture density
    let f_and_density = |v: f64| -> (f64, f64) {
        let mut cdf_pdf = (-p, 0.0);
        for ((m, w), s) in means.iter().zip(weights).zip(&sds) {
            let z = (v - m) / s;
            cdf_pdf.0 += w * normal_cdf(z);
            cdf_pdf.1 += w * normal_pdf(z) / s;
        }
        cdf_pdf
    };
    let mut v = 0.5 * (lo + hi);
    for _ in 0..100 {
        let tol = 1e-12 * (1.0 + v.abs());
        if hi - lo <= tol {
            break;
        }
        let (f, density) = f_and_density(v);
        if f == 0.0 {
            return v;
        }
        if f < 0.0 {
            lo = v;
        } else {
            hi = v;
        }
        let newton = v - f / density;
        let next = if newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if (next - v).abs() <= tol {
            return next;
        }
        v = next;
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mixture_of_one_component_is_the_normal_band() {
        let band = mixture_band(&[(vec![1.0], vec![4.0])], &[1.0]);
        // ±1.959964 sd; bisection to 1e-12 relative
        assert!((band.upper[0] - (1.0 + 2.0 * 1.959_964)).abs() < 1e-5);
        assert!((band.lower[0] - (1.0 - 2.0 * 1.959_964)).abs() < 1e-5);
        assert!((band.sd[0] - 2.0).abs() < 1e-15);
    }

    /// The quantile by plain bisection over a wide bracket (the former method): the reference.
    fn bisection_quantile(means: &[f64], weights: &[f64], sds: &[f64], p: f64) -> f64 {
        let cdf = |v: f64| -> f64 {
            let terms = means.iter().zip(weights).zip(sds);
            terms.map(|((m, w), s)| w * normal_cdf((v - m) / s)).sum()
        };
        let (mut lo, mut hi) = (-1e6, 1e6);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if cdf(mid) < p { lo = mid } else { hi = mid }
        }
        0.5 * (lo + hi)
    }

    #[test]
    fn mixture_quantile_equals_bisection_on_awkward_mixtures() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        for case in 0..400 {
            let n = 1 + case % 7;
            // separated modes (means over ±1000 with sds down to 1e-3), near-identical ones, and
            // one dominant component with tiny others: bimodal CDFs with flat stretches
            let spread = [1e3, 1.0, 1e-3][case % 3];
            let means: Vec<f64> = (0..n)
                .map(|_| rng.random_range(-1.0..1.0) * spread)
                .collect();
            let sds: Vec<f64> = (0..n)
                .map(|_| 10f64.powf(rng.random_range(-3.0..1.0)))
                .collect();
            let raw: Vec<f64> = (0..n)
                .map(|_| rng.random_range(1e-3..1.0f64).powi(3))
                .collect();
            let total: f64 = raw.iter().sum();
            let weights: Vec<f64> = raw.iter().map(|w| w / total).collect();
            for p in [0.025, 0.5, 0.975] {
                let got = mixture_quantile(&means, &weights, &sds, p);
                let want = bisection_quantile(&means, &weights, &sds, p);
                // both search to about 1e-12 relative; 1e-9 leaves room for the flat stretches
                // between separated modes, where the CDF changes by less than round-off
                let scale = 1.0 + want.abs() + sds.iter().fold(0.0f64, |a, s| a.max(*s));
                assert!(
                    (got - want).abs() <= 1e-9 * scale,
                    "case {case} p {p}: {got} vs {want} ({means:?}, {sds:?}, {weights:?})"
                );
            }
        }
    }

    #[test]
    fn mixture_variance_is_within_plus_between() {
        // two equal components at ±1 with unit spread: variance 1 + 1
        let (m, v) = mixture_moments(
            &[(vec![-1.0], vec![1.0]), (vec![1.0], vec![1.0])],
            &[0.5, 0.5],
        );
        assert!(m[0].abs() < 1e-15 && (v[0] - 2.0).abs() < 1e-15);
    }
}
