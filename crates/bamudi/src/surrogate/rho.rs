//! Module 2, online phase: `ρ*` by Eq. 30-31 and `α̂` at the experiments (Eq. 32).

use super::estimator::CoefficientEstimator;
use super::training::{LinearParts, XContext};
use crate::error::{BamudiError, Result};
use crate::optim::Brent;
use crate::params::RhoSearch;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Predicted outputs of Eq. 31 for a linear `g_o`: row `i` is
/// `ρ A ḡ(x_i) + b̄(x_i) + B α̂_i` (θ averaged over its prior).
pub fn predicted_outputs(
    rho: f64,
    alpha: &DMatrix<f64>,
    ctx: &[XContext],
    parts: &LinearParts,
) -> DMatrix<f64> {
    let ba = alpha * parts.b.transpose();
    DMatrix::from_fn(alpha.nrows(), parts.b.nrows(), |i, p| {
        rho * ctx[i].mean_ag[p] + ctx[i].mean_offset[p] + ba[(i, p)]
    })
}

/// The Eq.-30 objective and its pieces at one `ρ`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RhoPoint {
    /// `ρ`.
    pub rho: f64,
    /// `J(ρ) = Σ_i ‖y_i − y_pred_i(ρ)‖₂` (Eq. 30).
    pub objective: f64,
    /// `S(ρ) = Σ_i ‖y_i − y_pred_i(ρ)‖₂²`.
    pub sum_squares: f64,
}

/// Evaluates the objective at one `ρ`.
pub fn rho_objective(
    est: &dyn CoefficientEstimator,
    rho: f64,
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    ctx: &[XContext],
    parts: &LinearParts,
) -> Result<RhoPoint> {
    let alpha = est.predict(rho, x, y, ctx)?;
    let pred = predicted_outputs(rho, &alpha, ctx, parts);
    let mut objective = 0.0;
    let mut sum_squares = 0.0;
    for i in 0..y.nrows() {
        let s: f64 = (0..y.ncols())
            .map(|p| (y[(i, p)] - pred[(i, p)]).powi(2))
            .sum();
        objective += s.sqrt();
        sum_squares += s;
    }
    if !objective.is_finite() {
        return Err(BamudiError::Numerical {
            context: format!("rho objective at rho = {rho}"),
            reason: "non-finite".into(),
        });
    }
    Ok(RhoPoint {
        rho,
        objective,
        sum_squares,
    })
}

/// Result of the `ρ` search, with the curve for a plot like the paper's Fig. 13.
///
/// `likelihood` is a normalised, likelihood-like curve: the Gaussian profile likelihood with
/// the noise variance profiled out, `L(ρ) ∝ S(ρ)^(−N_s/2)` (`N_s = N_e N_o`), scaled so that its
/// trapezoid integral over the grid is one. It peaks near (not exactly at) the Eq.-30 optimum,
/// which minimises the sum of norms rather than of squares.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RhoCurve {
    /// Grid evaluations.
    pub grid: Vec<RhoPoint>,
    /// Normalised likelihood-like curve on the grid (see the type docs).
    pub likelihood: Vec<f64>,
    /// `ρ*` (grid optimum, refined by Brent's method if enabled).
    pub rho_star: f64,
    /// Objective at `ρ*`.
    pub objective_at_star: f64,
}

/// Minimises Eq. 30 over `ρ`: grid search, then Brent's method on the two grid cells around
/// the best grid point.
pub fn estimate_rho(
    est: &dyn CoefficientEstimator,
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    ctx: &[XContext],
    parts: &LinearParts,
    search: &RhoSearch,
) -> Result<RhoCurve> {
    let n = search.points;
    let grid = (0..n)
        .map(|i| {
            let rho = search.lo + (search.hi - search.lo) * i as f64 / (n - 1) as f64;
            rho_objective(est, rho, x, y, ctx, parts)
        })
        .collect::<Result<Vec<_>>>()?;
    let best = grid
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.objective.total_cmp(&b.1.objective))
        .map(|(i, _)| i)
        .unwrap_or(0);
    let mut rho_star = grid[best].rho;
    let mut objective_at_star = grid[best].objective;
    if search.refine {
        let brent = Brent {
            bracket: (
                grid[best.saturating_sub(1)].rho,
                grid[(best + 1).min(n - 1)].rho,
            ),
            start: rho_star,
            rel_tol: 1e-8,
            abs_tol: 1e-10,
            max_iters: 100,
        };
        let (p, c) = brent.minimise("refinement of rho (Eq. 30)", |rho| {
            rho_objective(est, rho, x, y, ctx, parts).map(|p| p.objective)
        })?;
        if c < objective_at_star {
            rho_star = p;
            objective_at_star = c;
        }
    }
    let n_s = (y.nrows() * y.ncols()) as f64;
    let s_min = grid
        .iter()
        .map(|p| p.sum_squares)
        .fold(f64::INFINITY, f64::min)
        .max(f64::MIN_POSITIVE);
    let mut likelihood: Vec<f64> = grid
        .iter()
        .map(|p| (-0.5 * n_s * (p.sum_squares / s_min).ln()).exp())
        .collect();
    let h = (search.hi - search.lo) / (n - 1) as f64;
    let area: f64 =
        h * (likelihood.iter().sum::<f64>() - 0.5 * (likelihood[0] + likelihood[n - 1]));
    if area > 0.0 {
        likelihood.iter_mut().for_each(|v| *v /= area);
    }
    Ok(RhoCurve {
        grid,
        likelihood,
        rho_star,
        objective_at_star,
    })
}
