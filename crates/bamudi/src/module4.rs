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
//! change ([`crate::module3::Module3::alpha_correction`]). Where the unobservable response
//! vanishes ([`mlmodel::UnobservableModel::response_vanishes`], e.g. a gate with no head) the
//! discrepancy, which corrects that response, is zero.

use crate::calibration::Calibration;
use crate::error::{BamudiError, Result};
use crate::module3::posterior::SupportPolicy;
use mlmodel::{LinearObservableModel, MultiLevelModel, UnobservableModel};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

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

/// Module-4 predictions of a calibration on its model (see the module docs).
pub struct Predictor<'a, U, O> {
    cal: &'a Calibration,
    model: &'a MultiLevelModel<U, O>,
    support: Vec<(Vec<f64>, f64)>,
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
        Ok(Predictor {
            cal: self,
            model,
            support: self.module3().posterior.support(&SupportPolicy::default()),
        })
    }
}

impl<U: UnobservableModel, O: LinearObservableModel> Predictor<'_, U, O> {
    /// Uses `policy` for the `θ` posterior's support points (fewer points: faster mixtures).
    pub fn support_policy(mut self, policy: &SupportPolicy) -> Self {
        self.support = self.cal.module3().posterior.support(policy);
        self
    }

    /// The support points `(θ_j, w_j)` of the mixtures.
    pub fn support(&self) -> &[(Vec<f64>, f64)] {
        &self.support
    }

    /// Means and latent variances of the discrepancy coefficients at the rows of `x` (two
    /// `N x K` matrices), zero at rows where the response vanishes.
    pub fn alpha_moments(&self, x: &DMatrix<f64>) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        self.check_x(x.ncols())?;
        let (mut mean, mut var) = self.cal.alpha_moments(x)?;
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
    pub fn response(&self, x: &[f64]) -> Result<Band> {
        let (shift, gauss_sd) = self.projected_alpha(&self.cal.parts().l, x)?;
        let rho = self.cal.rho_star();
        let mut g = vec![0.0; self.cal.parts().l.nrows()];
        self.theta_mixture(&gauss_sd, |theta| {
            self.model.unobservable.evaluate(x, theta, &mut g)?;
            Ok(g.iter()
                .zip(shift.iter())
                .map(|(g, s)| rho * g + s)
                .collect())
        })
    }

    /// The noise-free observable outputs at `x` (Eq. 44); add `σ_ε²` for a new measurement.
    pub fn outputs(&self, x: &[f64]) -> Result<Band> {
        let (shift, gauss_sd) = self.projected_alpha(&self.cal.parts().b, x)?;
        self.theta_mixture(&gauss_sd, |theta| {
            let m = self.model_outputs(x, theta)?;
            Ok((0..m.len()).map(|q| m[q] + shift[q]).collect())
        })
    }

    /// The reconstructed discrepancy `L μ_α(x)` with a 95 % band `± 1.96 sd` from the GP
    /// variances (Eq. 37; Fig. 15).
    pub fn discrepancy(&self, x: &[f64]) -> Result<Band> {
        let (shift, sd) = self.projected_alpha(&self.cal.parts().l, x)?;
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

    /// Mean and variance of the noise-free outputs at every row of `x` (`N x N_o` each): the
    /// Eq.-44 mixture's moments (between-`θ` variance plus the GP part), without quantiles, for
    /// many rows at once (rows in parallel).
    pub fn output_moments(&self, x: &DMatrix<f64>) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        let (mu, var_alpha) = self.alpha_moments(x)?;
        let bm = &self.cal.parts().b;
        let rows = (0..x.nrows())
            .into_par_iter()
            .map(|i| {
                let xi: Vec<f64> = x.row(i).iter().copied().collect();
                let shift = bm * mu.row(i).transpose();
                let gauss_var = projected_variance(bm, var_alpha.row(i).iter().copied());
                let comps = self.components(&xi, &shift)?;
                Ok(mixture_moments(&comps, &self.weights(), &gauss_var))
            })
            .collect::<Result<Vec<_>>>()?;
        let n_o = bm.nrows();
        let mean = DMatrix::from_fn(x.nrows(), n_o, |i, q| rows[i].0[q]);
        let var = DMatrix::from_fn(x.nrows(), n_o, |i, q| rows[i].1[q]);
        Ok((mean, var))
    }

    /// Eq. 50 at a given `θ` per row: `ρ* A g_u(x_i, θ_i) + b(x_i, θ_i) + B μ_α(x_i)`
    /// (`N x N_o`; the coefficients' posterior-averaged shift is used at every `θ`).
    pub fn outputs_at_theta(&self, x: &DMatrix<f64>, theta: &[Vec<f64>]) -> Result<DMatrix<f64>> {
        if theta.len() != x.nrows() {
            return Err(BamudiError::dim(
                "theta values vs rows",
                x.nrows(),
                theta.len(),
            ));
        }
        let (mu, _) = self.alpha_moments(x)?;
        let bm = &self.cal.parts().b;
        let rows = (0..x.nrows())
            .into_par_iter()
            .map(|i| {
                let xi: Vec<f64> = x.row(i).iter().copied().collect();
                Ok(self.model_outputs(&xi, &theta[i])? + bm * mu.row(i).transpose())
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(DMatrix::from_fn(x.nrows(), bm.nrows(), |i, q| rows[i][q]))
    }

    /// `ρ* A g_u(x, θ) + b(x, θ)` (output units).
    fn model_outputs(&self, x: &[f64], theta: &[f64]) -> Result<DVector<f64>> {
        let parts = self.cal.parts();
        let mut g = vec![0.0; parts.l.nrows()];
        let mut off = vec![0.0; parts.b.nrows()];
        self.model.unobservable.evaluate(x, theta, &mut g)?;
        self.model.observable.offset(x, theta, &mut off)?;
        let ag = &parts.a * DVector::from_column_slice(&g);
        let rho = self.cal.rho_star();
        Ok(DVector::from_fn(parts.b.nrows(), |q, _| {
            rho * ag[q] + off[q]
        }))
    }

    /// The mixture components `ρ* A g_u(x, θ_j) + b(x, θ_j) + shift` at the support points.
    fn components(&self, x: &[f64], shift: &DVector<f64>) -> Result<Vec<Vec<f64>>> {
        self.support
            .iter()
            .map(|(theta, _)| {
                let m = self.model_outputs(x, theta)?;
                Ok((0..m.len()).map(|q| m[q] + shift[q]).collect())
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

    /// The coefficient moments at `x` projected through `m` (`L` or `B = A L`): the mean
    /// `m μ_α(x)` and the per-row standard deviation `sqrt(diag(m Σ_α(x) mᵀ))`.
    fn projected_alpha(&self, m: &DMatrix<f64>, x: &[f64]) -> Result<(DVector<f64>, Vec<f64>)> {
        let (mu, var) = self.alpha_moments(&DMatrix::from_row_slice(1, x.len(), x))?;
        let shift = m * mu.row(0).transpose();
        let sd = projected_variance(m, var.row(0).iter().copied())
            .into_iter()
            .map(f64::sqrt)
            .collect();
        Ok((shift, sd))
    }

    /// The band of the mixture over the support whose component means are `component(θ_j)`,
    /// with the common per-point Gaussian spread `gauss_sd`.
    fn theta_mixture(
        &self,
        gauss_sd: &[f64],
        mut component: impl FnMut(&[f64]) -> Result<Vec<f64>>,
    ) -> Result<Band> {
        let comp = self
            .support
            .iter()
            .map(|(theta, _)| component(theta))
            .collect::<Result<Vec<_>>>()?;
        Ok(mixture_band(&comp, &self.weights(), gauss_sd))
    }
}

/// `diag(m diag(var) mᵀ)`: the variance of `m α` for independent coefficients.
fn projected_variance(m: &DMatrix<f64>, var: impl Iterator<Item = f64> + Clone) -> Vec<f64> {
    (0..m.nrows())
        .map(|r| {
            var.clone()
                .enumerate()
                .map(|(k, v)| m[(r, k)].powi(2) * v)
                .sum::<f64>()
        })
        .collect()
}

/// Mean and variance per point of `Σ_j w_j N(comp_j, gauss_var)`.
fn mixture_moments(comp: &[Vec<f64>], weights: &[f64], gauss_var: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let n = gauss_var.len();
    let mut mean = vec![0.0; n];
    let mut var = vec![0.0; n];
    for b in 0..n {
        let ms: Vec<f64> = comp.iter().map(|c| c[b]).collect();
        let m: f64 = ms.iter().zip(weights).map(|(v, w)| v * w).sum();
        let between: f64 = ms
            .iter()
            .zip(weights)
            .map(|(v, w)| w * (v - m).powi(2))
            .sum();
        mean[b] = m;
        var[b] = between + gauss_var[b];
    }
    (mean, var)
}

/// A band from mixture component means (`n_comp x n_points`), weights and a common per-point
/// Gaussian standard deviation.
fn mixture_band(comp: &[Vec<f64>], weights: &[f64], gauss_sd: &[f64]) -> Band {
    let gauss_var: Vec<f64> = gauss_sd.iter().map(|s| s.powi(2)).collect();
    let (mean, var) = mixture_moments(comp, weights, &gauss_var);
    let n = gauss_sd.len();
    let (mut lower, mut upper) = (vec![0.0; n], vec![0.0; n]);
    for b in 0..n {
        let ms: Vec<f64> = comp.iter().map(|c| c[b]).collect();
        lower[b] = mixture_quantile(&ms, weights, gauss_sd[b], 0.025);
        upper[b] = mixture_quantile(&ms, weights, gauss_sd[b], 0.975);
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mixture_of_one_component_is_the_normal_band() {
        let band = mixture_band(&[vec![1.0]], &[1.0], &[2.0]);
        // ±1.959964 sd; bisection to 1e-12 relative
        assert!((band.upper[0] - (1.0 + 2.0 * 1.959_964)).abs() < 1e-5);
        assert!((band.lower[0] - (1.0 - 2.0 * 1.959_964)).abs() < 1e-5);
        assert!((band.sd[0] - 2.0).abs() < 1e-15);
    }

    #[test]
    fn mixture_variance_is_within_plus_between() {
        // two equal components at ±1 with unit spread: variance 1 + 1
        let (m, v) = mixture_moments(&[vec![-1.0], vec![1.0]], &[0.5, 0.5], &[1.0]);
        assert!(m[0].abs() < 1e-15 && (v[0] - 2.0).abs() < 1e-15);
    }
}
