//! Module 3 with the discrepancy coefficients conditioned on `θ`
//! ([`CoefficientMode::ConditionalOnTheta`](crate::CoefficientMode::ConditionalOnTheta); not in
//! the paper).
//!
//! Module 2 estimates `α̂_i = f_ML(ρ*, x_i, y_i)` with `θ` marginalised over its prior
//! (Eq. 25/27): the estimator has learnt the map from what the *prior-averaged* model
//! `ρ A ḡ(x) + b̄(x) + B α` would produce back to `α`. When `θ` is fixed, the same
//! observations correspond to the prior-averaged output
//! `y − ρ*(A g(x, θ) − A ḡ(x)) − (b(x, θ) − b̄(x))`; feeding that to the estimator gives
//! `α̂_i(θ)`. The coefficient GPs are then re-conditioned on `α̂(θ)` with their
//! hyper-parameters held. A GP posterior mean at the training inputs is linear in the targets,
//! `μ = S α̂`, and for a GP with white noise `σ_n²` and a GLS trend the smoother is the latent
//! posterior covariance over the noise variance, `S = Σ(X, X) / σ_n²` (likewise
//! `S(x*) = Σ(x*, X) / σ_n²` at a new input), so the shift costs one `N_e x N_e` product per
//! coefficient. [`ConditionalCoefficients::new`] checks that identity on the Module-2 fit.

use crate::data::Experiments;
use crate::error::{BamudiError, Result};
use crate::optim::Brent;
use crate::params::RhoSearch;
use crate::surrogate::estimator::{CoefficientEstimator, FittedEstimator};
use crate::surrogate::gps::CoefficientGps;
use crate::surrogate::training::XContext;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Grid points of the profile search for `ρ` (before Brent's refinement).
const PROFILE_RHO_POINTS: usize = 21;

/// The model's `A g_u(x_i, θ)` and `b(x_i, θ)` rows at one `θ` (`N_e x N_o` each).
#[derive(Debug, Clone)]
pub struct ModelRows {
    /// `θ`.
    pub theta: Vec<f64>,
    /// `A g_u(x_i, θ)`, row `i`.
    pub ag: DMatrix<f64>,
    /// `b(x_i, θ)`, row `i`.
    pub b: DMatrix<f64>,
}

/// The profile search for `ρ` of the conditional mode: Eq. 30 with `θ` profiled (minimised
/// over candidate values) instead of marginalised, and with the GP-smoothed coefficients, so
/// that the fit is judged on what a smooth discrepancy cannot explain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RhoProfile {
    /// `ρ*` of Eq. 30 (`θ` marginalised over its prior), kept for the report; the calibration
    /// uses [`rho_star`](Self::rho_star).
    pub rho_star_eq30: f64,
    /// Grid values of `ρ`.
    pub rho: Vec<f64>,
    /// At each grid `ρ`: the smallest root-mean-square residual over the `θ` candidates (output
    /// units).
    pub rms: Vec<f64>,
    /// The `θ` candidate attaining it.
    pub theta_at_min: Vec<Vec<f64>>,
    /// The minimiser (grid, refined by Brent's method).
    pub rho_star: f64,
    /// The `θ` candidate at `rho_star`.
    pub theta_star: Vec<f64>,
    /// The residual at `rho_star` (output units).
    pub rms_at_star: f64,
    /// The same residual after the coefficient GPs were refitted to `α̂(ρ*, θ*)` (equal to
    /// `rms_at_star` until the calibration refits them; 0 when read from a file written
    /// before this field existed, when the refit was always kept).
    #[serde(default)]
    pub rms_after_refit: f64,
}

impl RhoProfile {
    /// Whether the calibration kept the GPs refitted to `α̂(ρ*, θ*)`: it does when they
    /// fit at least as well (`rms_after_refit <= rms_at_star`), otherwise the Module-2 GPs
    /// stay.
    ///
    /// ```
    /// # let mut p: bamudi::posterior::RhoProfile = serde_json::from_str(r#"{"rho_star_eq30": 1.0, "rho": [], "rms": [],
    /// #   "theta_at_min": [], "rho_star": 1.0, "theta_star": [90.0], "rms_at_star": 1.0}"#).unwrap();
    /// p.rms_after_refit = 2.4;
    /// assert!(!p.refit_kept());
    /// ```
    pub fn refit_kept(&self) -> bool {
        self.rms_after_refit <= self.rms_at_star
    }
}

/// Smallest relative tolerance of the smoother identity check `S α̂ = μ_α` (the GP mean is
/// computed by a different route, triangular solves, so agreement is to rounding of a
/// 500-point system).
const SMOOTHER_CHECK_RTOL: f64 = 1e-6;
/// Largest relative tolerance: a smoother less accurate than this is refused.
const SMOOTHER_CHECK_RTOL_MAX: f64 = 1e-3;

/// Tolerance of the smoother check for `n` points, signal variance `sf2` and noise variance
/// `sn2`. `Σ = σ_f² R − VᵀV + UᵀU` cancels terms of size `σ_f²` down to about `σ_n²`, so
/// its rounding, about `n ε σ_f²` per entry (dot products of length `n`), becomes
/// `n ε σ_f²/σ_n²` relative in `S = Σ/σ_n²`; a GP that nearly interpolates its targets
/// (`σ_f²/σ_n² ~ 1e8` was seen on a close-loop record) exceeds 1e-6 for that reason alone.
/// Sixteen times the estimate, clamped to [`SMOOTHER_CHECK_RTOL`, `SMOOTHER_CHECK_RTOL_MAX`].
fn smoother_tolerance(n: usize, sf2: f64, sn2: f64) -> f64 {
    let rounding = 16.0 * n as f64 * f64::EPSILON * sf2 / sn2;
    if rounding.is_nan() {
        return SMOOTHER_CHECK_RTOL;
    }
    rounding.clamp(SMOOTHER_CHECK_RTOL, SMOOTHER_CHECK_RTOL_MAX)
}

/// The coefficient GPs' means, latent covariances and noise and signal variances at the
/// experiments (what Eq. 51 and the conditional smoother need).
#[derive(Debug, Clone)]
pub struct GpMoments {
    /// GP means at the experiments (`N_e x K`).
    pub mean: DMatrix<f64>,
    /// Latent posterior covariance between the experiments, per coefficient (`N_e x N_e`).
    pub covs: Vec<DMatrix<f64>>,
    /// White-noise variance per coefficient.
    pub noise_var: Vec<f64>,
    /// Signal variance per coefficient.
    pub signal_var: Vec<f64>,
}

impl GpMoments {
    /// The moments of `gps` at the rows of `x`.
    pub fn of(gps: &CoefficientGps, x: &DMatrix<f64>) -> Result<Self> {
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
}

/// What re-estimating the coefficients at a given `θ` needs (see the module docs).
pub struct ConditionalCoefficients<'a> {
    estimator: &'a FittedEstimator,
    ctx: &'a [XContext],
    x: &'a DMatrix<f64>,
    y: &'a DMatrix<f64>,
    alpha_hat: &'a DMatrix<f64>,
    smoothers: Vec<DMatrix<f64>>,
}

impl<'a> ConditionalCoefficients<'a> {
    /// `alpha_hat` (`N_e x K`) are the Module-2 estimates at `ρ*` and `moments` those of the
    /// GPs fitted to them ([`GpMoments::of`]) at the experiments. Fails if the moment lists
    /// differ in length, a noise variance is not positive or the smoother does not reproduce
    /// the GP means (within a tolerance from the rounding of `Σ`).
    pub fn new(
        estimator: &'a FittedEstimator,
        ctx: &'a [XContext],
        exps: &'a Experiments,
        alpha_hat: &'a DMatrix<f64>,
        moments: &GpMoments,
    ) -> Result<Self> {
        let covs = &moments.covs;
        for (what, len) in [
            ("noise", moments.noise_var.len()),
            ("signal", moments.signal_var.len()),
        ] {
            if len != covs.len() {
                return Err(BamudiError::dim(
                    format!("coefficient GP {what} variances vs covariances"),
                    covs.len(),
                    len,
                ));
            }
        }
        let smoothers = covs
            .iter()
            .enumerate()
            .map(|(k, c)| smoother(k, c, alpha_hat, moments))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            estimator,
            ctx,
            x: &exps.x,
            y: &exps.y,
            alpha_hat,
            smoothers,
        })
    }

    /// `α̂(ρ, θ)` (`N_e x K`): the estimator applied to the observations shifted to the
    /// prior-averaged model, given the model rows at `θ`.
    pub fn alpha(&self, rho: f64, ag: &DMatrix<f64>, b: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        let shifted = DMatrix::from_fn(self.y.nrows(), self.y.ncols(), |i, p| {
            let c = &self.ctx[i];
            self.y[(i, p)] - rho * (ag[(i, p)] - c.mean_ag[p]) - (b[(i, p)] - c.mean_offset[p])
        });
        self.estimator.predict(rho, self.x, &shifted, self.ctx)
    }

    /// `α̂(ρ, θ) − α̂` (`N_e x K`), the change of the GP targets.
    pub fn delta(&self, rho: f64, ag: &DMatrix<f64>, b: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        Ok(self.alpha(rho, ag, b)? - self.alpha_hat)
    }

    /// Root-mean-square of `y − ρ A g(θ) − b(θ) − B S α̂(ρ, θ)` over all experiments and
    /// outputs (output units); `bm` is `B = A L`.
    pub fn rms(&self, rho: f64, rows: &ModelRows, bm: &DMatrix<f64>) -> Result<f64> {
        let fitted = self.smooth(&self.alpha(rho, &rows.ag, &rows.b)?) * bm.transpose();
        let r = self.y - rows.ag.scale(rho) - &rows.b - fitted;
        let ms = r.iter().map(|v| v * v).sum::<f64>() / r.len().max(1) as f64;
        if !ms.is_finite() {
            return Err(BamudiError::Numerical {
                context: format!(
                    "conditional residual at rho = {rho}, theta = {:?}",
                    rows.theta
                ),
                reason: "non-finite".into(),
            });
        }
        Ok(ms.sqrt())
    }

    /// The smallest [`rms`](Self::rms) over the candidate rows, with its index.
    pub fn best_theta(
        &self,
        rho: f64,
        rows: &[ModelRows],
        bm: &DMatrix<f64>,
    ) -> Result<(f64, usize)> {
        let vals = rows
            .par_iter()
            .map(|r| self.rms(rho, r, bm))
            .collect::<Result<Vec<_>>>()?;
        Ok(vals
            .into_iter()
            .enumerate()
            .map(|(i, v)| (v, i))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap_or((f64::INFINITY, 0)))
    }

    /// The profile search for `ρ` over `[search.lo, search.hi]` (see [`RhoProfile`]).
    pub fn profile_rho(
        &self,
        rows: &[ModelRows],
        bm: &DMatrix<f64>,
        search: &RhoSearch,
        rho_star_eq30: f64,
    ) -> Result<RhoProfile> {
        if rows.is_empty() {
            return Err(BamudiError::config(
                "theta candidates",
                "none to profile over",
            ));
        }
        let n = PROFILE_RHO_POINTS;
        let grid: Vec<f64> = (0..n)
            .map(|i| search.lo + (search.hi - search.lo) * i as f64 / (n - 1) as f64)
            .collect();
        let evals = grid
            .iter()
            .map(|r| self.best_theta(*r, rows, bm))
            .collect::<Result<Vec<_>>>()?;
        let best = (0..n)
            .min_by(|a, b| evals[*a].0.total_cmp(&evals[*b].0))
            .unwrap_or(0);
        let (mut rho_star, mut at_star) = (grid[best], evals[best]);
        if search.refine {
            let (lo, hi) = (grid[best.saturating_sub(1)], grid[(best + 1).min(n - 1)]);
            let (p, _) = brent((lo, hi), rho_star, 1e-10)
                .minimise("rho profile", |r| self.best_theta(r, rows, bm).map(|e| e.0))?;
            let e = self.best_theta(p, rows, bm)?;
            if e.0 < at_star.0 {
                (rho_star, at_star) = (p, e);
            }
        }
        Ok(RhoProfile {
            rho_star_eq30,
            rho: grid,
            rms: evals.iter().map(|e| e.0).collect(),
            theta_at_min: evals.iter().map(|e| rows[e.1].theta.clone()).collect(),
            rho_star,
            theta_star: rows[at_star.1].theta.clone(),
            rms_at_star: at_star.0,
            rms_after_refit: at_star.0,
        })
    }

    /// Refines the profile optimum for a scalar `θ`, which the candidate grid resolves only to
    /// its spacing (on the miter gate one coarse step of the gap moves the bottom gauges by
    /// several microstrain, and `ρ` then absorbs the rest): `θ` by Brent's method on
    /// `theta_bracket` (the neighbours of the best candidate), with `ρ` re-minimised at every
    /// trial `θ` by Brent's method within two grid steps of `profile.rho_star` (inside
    /// `[search.lo, search.hi]`). `rows_at(θ)` computes the model rows. Updates `rho_star`,
    /// `theta_star` and `rms_at_star` when the refined point fits better and returns its rows
    /// (or `None` when the grid optimum stands).
    pub fn refine_scalar_theta(
        &self,
        profile: &mut RhoProfile,
        theta_bracket: (f64, f64),
        rows_at: impl Fn(f64) -> Result<ModelRows>,
        bm: &DMatrix<f64>,
        search: &RhoSearch,
    ) -> Result<Option<ModelRows>> {
        let [theta0] = profile.theta_star[..] else {
            return Err(BamudiError::dim(
                "theta (scalar refinement)",
                1,
                profile.theta_star.len(),
            ));
        };
        let step = (search.hi - search.lo) / (PROFILE_RHO_POINTS - 1) as f64;
        let rho_bracket = (
            (profile.rho_star - 2.0 * step).max(search.lo),
            (profile.rho_star + 2.0 * step).min(search.hi),
        );
        let best_rho = |rows: &ModelRows| {
            brent(rho_bracket, profile.rho_star, 1e-10)
                .minimise("rho at a trial theta", |r| self.rms(r, rows, bm))
        };
        // the best trial (rms, θ, ρ, rows), so that its contact solves are not repeated
        let best = std::cell::RefCell::new(None::<(f64, f64, f64, ModelRows)>);
        brent(theta_bracket, theta0, 1e-4).minimise("theta refinement", |t| {
            let rows = rows_at(t)?;
            let (rho, rms) = best_rho(&rows)?;
            let mut b = best.borrow_mut();
            if b.as_ref().is_none_or(|(r, ..)| rms < *r) {
                *b = Some((rms, t, rho, rows));
            }
            Ok(rms)
        })?;
        let Some((rms, theta, rho, rows)) = best.into_inner() else {
            return Ok(None);
        };
        if rms >= profile.rms_at_star {
            return Ok(None);
        }
        profile.rho_star = rho;
        profile.theta_star = vec![theta];
        profile.rms_at_star = rms;
        Ok(Some(rows))
    }

    /// The change of the GP means at the experiments for a change `delta` of the targets:
    /// column `k` is `S_k delta_k`.
    pub fn smooth(&self, delta: &DMatrix<f64>) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(delta.nrows(), delta.ncols());
        for (k, s) in self.smoothers.iter().enumerate() {
            out.set_column(k, &(s * delta.column(k)));
        }
        out
    }

    /// The smoother weights `delta_k / σ_n,k²` per coefficient, so that the GP mean shift at a
    /// new input is `Σ_k(x*, X) w_k` (stored by [`crate::Calibration`] for Module 4).
    pub fn weights(delta: &DMatrix<f64>, noise_var: &[f64]) -> DMatrix<f64> {
        DMatrix::from_fn(delta.nrows(), delta.ncols(), |i, k| {
            delta[(i, k)] / noise_var[k]
        })
    }
}

/// The conditional mode's Brent searches: relative tolerance 1e-6, at most 40 iterations.
fn brent(bracket: (f64, f64), start: f64, abs_tol: f64) -> Brent {
    Brent {
        bracket,
        start,
        rel_tol: 1e-6,
        abs_tol,
        max_iters: 40,
    }
}

/// The smoother `S_k = Σ_k / σ_n,k²` of coefficient `k`, checked against the GP mean.
fn smoother(
    k: usize,
    cov: &DMatrix<f64>,
    alpha_hat: &DMatrix<f64>,
    moments: &GpMoments,
) -> Result<DMatrix<f64>> {
    let nv = moments.noise_var[k];
    if nv.is_nan() || nv <= 0.0 {
        return Err(BamudiError::Gp {
            coefficient: k,
            reason: format!(
                "white-noise variance {nv} is not positive: the conditional coefficient \
                 mode needs the GP smoother Σ/σ_n²"
            ),
        });
    }
    let s = cov / nv;
    let rtol = smoother_tolerance(s.nrows(), moments.signal_var[k], nv);
    check_smoother(k, &s, alpha_hat, &moments.mean, rtol)?;
    Ok(s)
}

fn check_smoother(
    k: usize,
    s: &DMatrix<f64>,
    alpha_hat: &DMatrix<f64>,
    mu_alpha: &DMatrix<f64>,
    rtol: f64,
) -> Result<()> {
    let target: DVector<f64> = alpha_hat.column(k).into_owned();
    let got = s * &target;
    let mu = mu_alpha.column(k);
    let scale = mu.amax().max(target.amax()).max(f64::MIN_POSITIVE);
    let err = (got - mu).amax();
    if err > rtol * scale {
        return Err(BamudiError::Gp {
            coefficient: k,
            reason: format!(
                "the smoother Σ/σ_n² reproduces the GP mean only to {:.2e} (relative to {scale:.3e}; \
                 tolerance {rtol:.1e} from the rounding of Σ); the conditional coefficient mode \
                 needs it (was jitter added to the GP?)",
                err / scale
            ),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smoother_tolerance_grows_with_the_signal_to_noise_ratio_and_is_clamped() {
        // a well-conditioned GP keeps the strict floor
        assert_eq!(smoother_tolerance(240, 1.0, 1e-2), SMOOTHER_CHECK_RTOL);
        // the close-loop case: 240 points, σ_f²/σ_n² = 1e8 -> 16·240·2.2e-16·1e8 ≈ 8.5e-5
        let t = smoother_tolerance(240, 1e8, 1.0);
        assert!((t - 16.0 * 240.0 * f64::EPSILON * 1e8).abs() < 1e-12 && t > 4.55e-6);
        // a hopeless ratio is refused rather than accepted at any accuracy
        assert_eq!(smoother_tolerance(240, 1e16, 1.0), SMOOTHER_CHECK_RTOL_MAX);
    }

    #[test]
    fn smoother_check_reports_the_coefficient_and_the_tolerance() {
        let s = DMatrix::<f64>::identity(3, 3);
        let alpha = DMatrix::from_column_slice(3, 1, &[1.0, 2.0, 3.0]);
        let off = DMatrix::from_column_slice(3, 1, &[1.0, 2.0, 3.001]);
        assert!(check_smoother(0, &s, &alpha, &alpha, 1e-6).is_ok());
        // 1e-3 / 3 relative: refused at 1e-6, accepted at 1e-3
        match check_smoother(0, &s, &alpha, &off, 1e-6) {
            Err(BamudiError::Gp {
                coefficient: 0,
                reason,
            }) => assert!(reason.contains("1.0e-6")),
            other => panic!("expected a Gp error, got {other:?}"),
        }
        assert!(check_smoother(0, &s, &alpha, &off, 1e-3).is_ok());
    }
}
