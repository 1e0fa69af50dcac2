//! The exact linear-Gaussian conditional-mean estimator (see [`super`]).

use super::{CoefficientEstimator, EstimatorData, FittedEstimator};
use crate::error::{BamudiError, Result};
use crate::surrogate::training::{LinearParts, XContext};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// The exact linear-Gaussian conditional-mean estimator (see the module docs).
///
/// ```
/// use bamudi::internals::ExactLinearEstimator;
/// use bamudi::surrogate::CoefficientEstimator;
/// use bamudi::internals::XContext;
/// use nalgebra::DMatrix;
/// // one output, one coefficient, B = [2]: y = 2 α  =>  α̂ = y / 2 when noise-free
/// let est = ExactLinearEstimator::new(DMatrix::from_element(1, 1, 2.0), 0.0).unwrap();
/// let ctx = vec![XContext { mean_ag: vec![0.0], mean_offset: vec![0.0], alpha_half_width: vec![1.0], response_rms: 1.0 }];
/// let a = est.predict(1.0, &DMatrix::zeros(1, 1), &DMatrix::from_element(1, 1, 1.0), &ctx).unwrap();
/// assert!((a[(0, 0)] - 0.5).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ExactLinearEstimator {
    b: DMatrix<f64>,
    noise_var: f64,
}

impl ExactLinearEstimator {
    /// From `B = A L` and the training-output noise standard deviation `σ_t`.
    pub fn new(b: DMatrix<f64>, noise_sd: f64) -> Result<Self> {
        if !(noise_sd.is_finite() && noise_sd >= 0.0) {
            return Err(BamudiError::config("sampling.noise_sd", "must be >= 0"));
        }
        Ok(Self {
            b,
            noise_var: noise_sd * noise_sd,
        })
    }

    /// From the linear parts of a model.
    pub(crate) fn from_parts(parts: &LinearParts, noise_sd: f64) -> Result<Self> {
        Self::new(parts.b.clone(), noise_sd)
    }

    /// The conditional mean for a general Gaussian prior `α ~ N(m, Σ_α)` and residual
    /// `r = y − ρ A ḡ − b̄` (the formula of the module docs).
    ///
    /// ```
    /// use bamudi::internals::ExactLinearEstimator;
    /// use nalgebra::{DMatrix, DVector};
    /// let est = ExactLinearEstimator::new(DMatrix::identity(2, 2), 1.0).unwrap();
    /// // prior variance 1, noise variance 1: posterior mean = half the residual
    /// let a = est.conditional_mean(&DVector::zeros(2), &DMatrix::identity(2, 2), &DVector::from_vec(vec![2.0, -4.0])).unwrap();
    /// assert!((a[0] - 1.0).abs() < 1e-12 && (a[1] + 2.0).abs() < 1e-12);
    /// ```
    pub fn conditional_mean(
        &self,
        m: &DVector<f64>,
        cov: &DMatrix<f64>,
        resid: &DVector<f64>,
    ) -> Result<DVector<f64>> {
        // With Σ_α = L Lᵀ and G = B L = U S Vᵀ (thin SVD):
        // Σ_α Bᵀ (B Σ_α Bᵀ + σ² I)⁺ = L V diag(s / (s² + σ²)) Uᵀ,
        // which avoids squaring the condition number of B; singular values below
        // 1e-12 s_max are treated as zero (the pseudo-inverse).
        let l = cov
            .clone()
            .cholesky()
            .ok_or_else(|| BamudiError::NotPositiveDefinite {
                what: "training covariance of alpha".into(),
            })?
            .l();
        let g = &self.b * &l;
        let svd = g.svd(true, true);
        let (u, vt) = match (svd.u, svd.v_t) {
            (Some(u), Some(vt)) => (u, vt),
            _ => {
                return Err(BamudiError::Numerical {
                    context: "exact estimator".into(),
                    reason: "SVD failed".into(),
                });
            }
        };
        let s = svd.singular_values;
        let tol = 1e-12 * s.max();
        let innovation = resid - &self.b * m;
        let mut ut_r = u.transpose() * innovation;
        for (i, v) in ut_r.iter_mut().enumerate() {
            let si = s[i];
            *v *= if si > tol {
                si / (si * si + self.noise_var)
            } else {
                0.0
            };
        }
        Ok(m + l * (vt.transpose() * ut_r))
    }
}

impl CoefficientEstimator for ExactLinearEstimator {
    fn name(&self) -> &'static str {
        "exact_linear"
    }
    fn predict(
        &self,
        rho: f64,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
        ctx: &[XContext],
    ) -> Result<DMatrix<f64>> {
        if ctx.len() != y.nrows() || x.nrows() != y.nrows() {
            return Err(BamudiError::dim(
                "exact estimator: contexts/x vs y rows",
                y.nrows(),
                ctx.len(),
            ));
        }
        let k = self.b.ncols();
        let mut out = DMatrix::zeros(y.nrows(), k);
        for (i, c) in ctx.iter().enumerate() {
            // uniform α_k on ±h_k: mean 0, variance h_k² / 3
            let cov = DMatrix::from_diagonal(&DVector::from_iterator(
                k,
                c.alpha_half_width.iter().map(|h| h * h / 3.0),
            ));
            let resid = DVector::from_fn(y.ncols(), |p, _| {
                y[(i, p)] - rho * c.mean_ag[p] - c.mean_offset[p]
            });
            let a = self.conditional_mean(&DVector::zeros(k), &cov, &resid)?;
            out.row_mut(i).copy_from(&a.transpose());
        }
        Ok(out)
    }
}

/// Fits the exact estimator: no training, `B` and the sampling rule's output noise `σ_t`.
pub(super) fn fit(data: &EstimatorData<'_>) -> Result<FittedEstimator> {
    Ok(FittedEstimator::ExactLinear(
        ExactLinearEstimator::from_parts(data.parts, data.noise_sd)?,
    ))
}
