//! Covariate selection for the data-driven term by the multi-task lasso (`linfa-elasticnet`):
//! one group penalty per covariate across all gauges, so a covariate enters for every gauge or
//! for none, with the penalty chosen by blocked cross-validation in time.

use super::generic::Candidate;
use crate::closeloop::effect::FitContext;
use crate::closeloop::stats::ols;
use linfa::prelude::*;
use linfa_elasticnet::MultiTaskElasticNet;
use nalgebra::DMatrix;
use ndarray::{Array2, Axis, ShapeBuilder};

/// Penalties on the path: `λ_max` (no covariate enters) down to `1e-3 λ_max`, log spaced.
const PATH: usize = 12;
/// Contiguous blocks of the calibration rows for the cross-validation (time order kept: a
/// random split of autocorrelated rows would leak).
const FOLDS: usize = 5;

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
    let none = cv_error(&x, &y, &[]);
    let (best, err) = path
        .iter()
        .map(|&l| (l, cv_error(&x, &y, &selected(&x, &y, l, max))))
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

/// Mean squared held-out error of the least-squares refit (intercept + `cols`) over
/// [`FOLDS`] contiguous blocks.
fn cv_error(x: &Array2<f64>, y: &Array2<f64>, cols: &[usize]) -> f64 {
    let n = x.nrows();
    let design = |rows: &[usize]| {
        DMatrix::from_fn(rows.len(), cols.len() + 1, |i, j| match j {
            0 => 1.0,
            _ => x[[rows[i], cols[j - 1]]],
        })
    };
    let target = |rows: &[usize]| DMatrix::from_fn(rows.len(), y.ncols(), |i, g| y[[rows[i], g]]);
    let mut sse = 0.0;
    for k in 0..FOLDS {
        let (lo, hi) = (k * n / FOLDS, (k + 1) * n / FOLDS);
        let test: Vec<usize> = (lo..hi).collect();
        let train: Vec<usize> = (0..lo).chain(hi..n).collect();
        let coef = ols(&design(&train), &target(&train));
        sse += (target(&test) - design(&test) * coef).norm_squared();
    }
    sse / (n * y.ncols()) as f64
}
