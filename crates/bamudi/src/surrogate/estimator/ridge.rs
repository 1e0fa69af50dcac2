//! Ridge regression (`smartcore`) on quadratic features of the standardised `[ρ, x, y]`.

use super::{CoefficientEstimator, EstimatorData, FittedEstimator, stack_inputs};
use crate::error::{BamudiError, Result};
use crate::params::RidgeParams;
use crate::surrogate::training::{TrainingSet, XContext};
use nalgebra::DMatrix;
use numerics::Standardizer;
use serde::{Deserialize, Serialize};
use smartcore::linalg::basic::arrays::Array;
use smartcore::linalg::basic::matrix::DenseMatrix;
use smartcore::linear::ridge_regression::{RidgeRegression, RidgeRegressionParameters};

/// Quadratic features `[1, z_i, z_i z_j (i <= j)]` of standardised inputs (the constant column
/// is the intercept: `smartcore`'s ridge without normalisation fits none).
fn quadratic_features(z: &DMatrix<f64>) -> DMatrix<f64> {
    let p = z.ncols();
    let n_feat = 1 + p + p * (p + 1) / 2;
    let mut f = DMatrix::zeros(z.nrows(), n_feat);
    for r in 0..z.nrows() {
        f[(r, 0)] = 1.0;
        let mut c = 1;
        for i in 0..p {
            f[(r, c)] = z[(r, i)];
            c += 1;
        }
        for i in 0..p {
            for j in i..p {
                f[(r, c)] = z[(r, i)] * z[(r, j)];
                c += 1;
            }
        }
    }
    f
}

/// Ridge regression (`smartcore`) on quadratic features; coefficients are copied out of the
/// fitted `smartcore` models so the estimator is serialisable.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RidgeEstimator {
    input_scaler: Standardizer,
    output_scaler: Standardizer,
    /// One row of feature weights per coefficient.
    weights: DMatrix<f64>,
    intercepts: Vec<f64>,
}

impl RidgeEstimator {
    /// Fits one ridge model per coefficient on the training set.
    pub fn fit(train: &TrainingSet, lambda: f64) -> Result<Self> {
        let raw = stack_inputs(&train.rho, &train.x, &train.mu_o);
        let input_scaler = Standardizer::fit(&raw);
        let output_scaler = Standardizer::fit(&train.alpha);
        let feats = quadratic_features(&input_scaler.apply(&raw));
        let targets = output_scaler.apply(&train.alpha);
        let err = |reason: String| BamudiError::Estimator {
            estimator: "ridge",
            reason,
        };
        let rows: Vec<Vec<f64>> = (0..feats.nrows())
            .map(|i| feats.row(i).iter().copied().collect())
            .collect();
        let xm = DenseMatrix::from_2d_vec(&rows).map_err(|e| err(e.to_string()))?;
        let mut weights = DMatrix::zeros(targets.ncols(), feats.ncols());
        let mut intercepts = Vec::with_capacity(targets.ncols());
        for k in 0..targets.ncols() {
            let yk: Vec<f64> = targets.column(k).iter().copied().collect();
            let params = RidgeRegressionParameters::default()
                .with_alpha(lambda)
                .with_normalize(false);
            let model: RidgeRegression<f64, f64, DenseMatrix<f64>, Vec<f64>> =
                RidgeRegression::fit(&xm, &yk, params).map_err(|e| err(e.to_string()))?;
            let coef = model.coefficients();
            for j in 0..feats.ncols() {
                weights[(k, j)] = *coef.get((j, 0));
            }
            intercepts.push(*model.intercept());
        }
        Ok(Self {
            input_scaler,
            output_scaler,
            weights,
            intercepts,
        })
    }
}

impl CoefficientEstimator for RidgeEstimator {
    fn name(&self) -> &'static str {
        "ridge"
    }
    fn predict(
        &self,
        rho: f64,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
        _ctx: &[XContext],
    ) -> Result<DMatrix<f64>> {
        let raw = stack_inputs(&vec![rho; x.nrows()], x, y);
        if raw.ncols() != self.input_scaler.mean.len() {
            return Err(BamudiError::dim(
                "ridge estimator inputs",
                self.input_scaler.mean.len(),
                raw.ncols(),
            ));
        }
        let feats = quadratic_features(&self.input_scaler.apply(&raw));
        let mut z = feats * self.weights.transpose();
        for mut row in z.row_iter_mut() {
            for (v, c) in row.iter_mut().zip(&self.intercepts) {
                *v += c;
            }
        }
        Ok(self.output_scaler.invert(&z))
    }
}

/// Fits the ridge estimator on the Eq.-27 training set.
pub(super) fn fit(params: &RidgeParams, data: &EstimatorData<'_>) -> Result<FittedEstimator> {
    let train = data.training("ridge")?;
    Ok(FittedEstimator::Ridge(RidgeEstimator::fit(
        train,
        params.lambda,
    )?))
}
