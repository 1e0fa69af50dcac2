//! Module 2, Sec. 3.3.3: one Gaussian process per discrepancy coefficient (Eq. 33-37), with a
//! squared-exponential ARD kernel plus white noise (the noise absorbs the estimator's error
//! in `α̂`), a constant mean, and hyper-parameters by maximum marginal likelihood.

use crate::error::{BamudiError, Result};
use nalgebra::DMatrix;
use numerics::random::derive_seed;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The `K` coefficient GPs `α̂_k(x) ~ N(μ_k(x), σ_k²(x))` (Eq. 36).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CoefficientGps {
    /// One model per coefficient, in stacked-`α` order.
    pub models: Vec<gp::GpModel>,
}

impl CoefficientGps {
    /// Fits the GPs to `α̂` (`N_e x K`) at the experiment inputs `x` (`N_e x d`), in parallel.
    pub fn fit(x: &DMatrix<f64>, alpha: &DMatrix<f64>, restarts: usize, seed: u64) -> Result<Self> {
        if x.nrows() != alpha.nrows() {
            return Err(BamudiError::dim(
                "GP data: rows of x vs alpha",
                x.nrows(),
                alpha.nrows(),
            ));
        }
        let models = (0..alpha.ncols())
            .into_par_iter()
            .map(|k| {
                let y: Vec<f64> = alpha.column(k).iter().copied().collect();
                gp::GpParams::new()
                    .kernel(gp::Kernel::SquaredExponential { ard: true })
                    .mean(gp::Mean::Constant)
                    .estimate_noise(true)
                    .restarts(restarts)
                    .seed(derive_seed(seed, k as u64))
                    .fit(x, &y)
                    .map_err(|e| BamudiError::Gp {
                        coefficient: k,
                        reason: e.to_string(),
                    })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { models })
    }

    /// Number of coefficients `K`.
    pub fn len(&self) -> usize {
        self.models.len()
    }

    /// True when there are no coefficients.
    pub fn is_empty(&self) -> bool {
        self.models.is_empty()
    }

    /// Latent means and variances at the rows of `x`: two `N x K` matrices.
    pub fn predict(&self, x: &DMatrix<f64>) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        let mut mean = DMatrix::zeros(x.nrows(), self.len());
        let mut var = DMatrix::zeros(x.nrows(), self.len());
        for (k, m) in self.models.iter().enumerate() {
            let p = m.predict(x).map_err(|e| BamudiError::Gp {
                coefficient: k,
                reason: e.to_string(),
            })?;
            mean.set_column(k, &p.mean);
            var.set_column(k, &p.variance);
        }
        Ok((mean, var))
    }

    /// Latent posterior covariance `Cov_k(x1, x2)` of coefficient `k` (Eq. A4).
    pub fn covariance(
        &self,
        k: usize,
        x1: &DMatrix<f64>,
        x2: &DMatrix<f64>,
    ) -> Result<DMatrix<f64>> {
        self.models[k]
            .posterior_cov(x1, x2)
            .map_err(|e| BamudiError::Gp {
                coefficient: k,
                reason: e.to_string(),
            })
    }

    /// White-noise variances `σ_2²` of Eq. 35, per coefficient.
    pub(crate) fn noise_variances(&self) -> Vec<f64> {
        self.models
            .iter()
            .map(gp::GpModel::noise_variance)
            .collect()
    }
}
