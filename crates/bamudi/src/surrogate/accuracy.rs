//! How well a fitted estimator of Eq. 29 recovers the coefficients on data it was not trained
//! on (the paper's Fig. 12): a fresh set drawn from the training distribution (Eq. 27) with its
//! own seed, the estimator's `α̂` against the `α` that generated each sample.

use super::Module2;
use super::estimator::CoefficientEstimator;
use super::training::{LinearParts, TrainingSpec, generate_linear, x_context};
use crate::error::Result;
use crate::observe::Silent;
use crate::params::CalibrationConfig;
use mlmodel::{LinearObservableModel, MultiLevelModel, UnobservableModel};
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Per-coefficient accuracy of the estimator on held-out samples.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct EstimatorAccuracy {
    /// Held-out samples.
    pub n: usize,
    /// Coefficient of determination `1 − SSE/SST` per coefficient.
    pub r2: Vec<f64>,
    /// RMSE per coefficient divided by the sd of the true coefficient.
    pub relative_rmse: Vec<f64>,
}

impl EstimatorAccuracy {
    /// Mean `R²` over the coefficients.
    pub fn mean_r2(&self) -> f64 {
        self.r2.iter().sum::<f64>() / self.r2.len().max(1) as f64
    }
}

/// Scores the estimator of `m2` on `n` fresh samples drawn with `seed` (not the training
/// seed) from the training distribution of `cfg`.
pub fn estimator_accuracy<U, O>(
    model: &MultiLevelModel<U, O>,
    parts: &LinearParts,
    m2: &Module2,
    cfg: &CalibrationConfig,
    n: usize,
    seed: u64,
) -> Result<EstimatorAccuracy>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let spec = TrainingSpec {
        theta_rule: &m2.theta_rule,
        rule: &cfg.sampling,
        bounds: &m2.x_bounds,
        size: n,
        seed,
    };
    let set = generate_linear(model, parts, &spec, &Silent)?;
    let x_row = |i: usize| -> Vec<f64> { set.x.row(i).iter().copied().collect() };
    // The samples of one pool input are consecutive rows with the same `x`: its context
    // (`n_nodes + 1` model evaluations) is computed once for all of them.
    let firsts: Vec<usize> = (0..set.len())
        .filter(|&i| {
            let same = |(a, b): (&f64, &f64)| a.to_bits() == b.to_bits();
            i == 0 || !set.x.row(i).iter().zip(set.x.row(i - 1).iter()).all(same)
        })
        .collect();
    let contexts = firsts
        .par_iter()
        .map(|&i| x_context(model, parts, &m2.theta_rule, &cfg.sampling, &x_row(i)))
        .collect::<Vec<_>>()
        .into_iter()
        .collect::<Result<Vec<_>>>()?;
    let predicted = (0..set.len())
        .into_par_iter()
        .map(|i| {
            let ctx = &contexts[firsts.partition_point(|&f| f <= i) - 1];
            let x = x_row(i);
            let xm = DMatrix::from_row_slice(1, x.len(), &x);
            let ym = DMatrix::from_fn(1, set.mu_o.ncols(), |_, q| set.mu_o[(i, q)]);
            let a = m2
                .estimator
                .predict(set.rho[i], &xm, &ym, std::slice::from_ref(ctx))?;
            Ok(a.row(0).iter().copied().collect::<Vec<f64>>())
        })
        .collect::<Vec<_>>()
        .into_iter()
        .collect::<Result<Vec<_>>>()?;
    let k = set.alpha.ncols();
    let (mut r2, mut rel) = (Vec::with_capacity(k), Vec::with_capacity(k));
    for c in 0..k {
        let truth = set.alpha.column(c);
        let mean = truth.mean();
        let sst: f64 = truth.iter().map(|v| (v - mean).powi(2)).sum();
        let sse: f64 = (0..set.len())
            .map(|i| (predicted[i][c] - truth[i]).powi(2))
            .sum();
        r2.push(1.0 - sse / sst.max(f64::MIN_POSITIVE));
        rel.push((sse / sst.max(f64::MIN_POSITIVE)).sqrt());
    }
    Ok(EstimatorAccuracy {
        n: set.len(),
        r2,
        relative_rmse: rel,
    })
}
