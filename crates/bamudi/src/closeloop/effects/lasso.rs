//! Covariate selection for the data-driven term by the multi-task lasso (`linfa-elasticnet`):
//! one group penalty per covariate across all gauges, so a covariate enters for every gauge or
//! for none, with the penalty chosen by blocked cross-validation in time.

use super::generic::Candidate;
use super::stepwise::{folds, held_out_sse};
use crate::closeloop::effect::FitContext;
use linfa::prelude::*;
use linfa_elasticnet::MultiTaskElasticNet;
use nalgebra::DMatrix;
use ndarray::{Array2, Axis, ShapeBuilder};

/// Penalties on the path: `λ_max` (no covariate enters) down to `1e-3 λ_max`, log spaced.
const PATH: usize = 12;
/// The standardised candidates at the calibration rows (rows x candidates).
fn design(ctx: &FitContext<'_>, cands: &[Candidate]) -> Array2<f64> {
    // column-major: coordinate descent takes one column at a time, and a strided column
    // falls to ndarray's slow generic dot product
    Array2::from_shape_fn((ctx.cal.len(), cands.len()).f(), |(i, j)| {
        cands[j].z(ctx.cal[i])
    })
}

/// The candidates (positions in `cands`) the cross-validated group lasso selects, at most
/// `max` (the largest coefficient groups); `None` when no penalty beats the intercept alone.
pub(super) fn select(
    ctx: &FitContext<'_>,
    r: &DMatrix<f64>,
    cands: &[Candidate],
    max: usize,
) -> Option<Vec<usize>> {
    if cands.is_empty() || max == 0 {
        return None;
    }
    let x = design(ctx, cands);
    let y = Array2::from_shape_fn((ctx.cal.len(), r.ncols()), |(i, g)| r[(ctx.cal[i], g)]);
    let lambda_max = lambda_max(&x, &y);
    let path: Vec<f64> = (0..PATH)
        .map(|k| lambda_max * 10f64.powf(-3.0 * k as f64 / (PATH - 1) as f64))
        .collect();
    // squared error of the least-squares refit on the chosen candidates, over blocked folds
    let cv_error = |chosen: &[usize]| -> f64 {
        folds(ctx.cal)
            .iter()
            .map(|(train, test)| held_out_sse(cands, r, train, test, chosen))
            .sum()
    };
    let none = cv_error(&[]);
    let (best, err) = path
        .iter()
        .map(|&l| (l, cv_error(&selected(&x, &y, l, max))))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    if err >= none {
        return None;
    }
    let chosen = selected(&x, &y, best, max);
    (!chosen.is_empty()).then_some(chosen)
}

/// The smallest penalty at which no covariate enters: `max_j ‖X_jᵀ (Y − Ȳ)‖₂ / n`.
fn lambda_max(x: &Array2<f64>, y: &Array2<f64>) -> f64 {
    let n = x.nrows() as f64;
    let yc = y - &y
        .mean_axis(Axis(0))
        .unwrap_or_else(|| ndarray::Array1::zeros(y.ncols()));
    let xty = x.t().dot(&yc);
    xty.rows()
        .into_iter()
        .map(|row| row.dot(&row).sqrt() / n)
        .fold(0.0, f64::max)
        .max(f64::MIN_POSITIVE)
}

/// The candidate columns with a non-zero coefficient group at penalty `lambda`, largest
/// groups first, at most `max`.
fn selected(x: &Array2<f64>, y: &Array2<f64>, lambda: f64, max: usize) -> Vec<usize> {
    let data = Dataset::new(x.clone(), y.clone());
    let Ok(fit) = MultiTaskElasticNet::<f64>::lasso()
        .penalty(lambda)
        .with_intercept(true)
        .max_iterations(2000)
        .tolerance(1e-6)
        .fit(&data)
    else {
        return Vec::new();
    };
    let mut groups: Vec<(f64, usize)> = fit
        .hyperplane()
        .rows()
        .into_iter()
        .enumerate()
        .map(|(j, row)| (row.dot(&row).sqrt(), j))
        .filter(|(norm, _)| *norm > 1e-12)
        .collect();
    groups.sort_by(|a, b| b.0.total_cmp(&a.0));
    groups.into_iter().take(max).map(|(_, j)| j).collect()
}
