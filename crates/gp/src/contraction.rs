//! The posterior covariance against fixed points, contracted with fixed weights:
//! `x ↦ Σ(x, X₂) w` (Eq. A4), reduced once so that each new `x` costs `m₂ + n` kernel
//! evaluations instead of a triangular solve with `m₂` right-hand sides.
//!
//! With `V = L⁻¹ k(X, ·)` and `U = L_A⁻¹ (h − (L⁻¹H)ᵀ V)` (the vectors of
//! [`GpModel::posterior_cov`]), `Σ(x, X₂) w = s_y² [k(x, X₂) w − V(x)ᵀ V₂ w + U(x)ᵀ U₂ w]`.
//! Writing `s = L_A⁻ᵀ U₂ w` and `c = L⁻ᵀ (V₂ w + L⁻¹H s)` gives
//! `Σ(x, X₂) w = s_y² [k(x, X₂) w − k(X, x)ᵀ c + h(x)ᵀ s]`: `s` and `c` are computed once.
//! The two routes differ by rounding only (`contraction_matches_the_dense_covariance`).

use crate::GpError;
use crate::linalg::small_backward_solve;
use crate::model::GpModel;
use crate::validate::{check_per_row, check_points};
use faer::linalg::triangular_solve::solve_upper_triangular_in_place;
use faer::{Mat, Par};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// `x ↦ Σ(x, X₂) w` for the model it was made from ([`GpModel::covariance_contraction`]).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CovarianceContraction {
    /// Row-major standardised `X₂`.
    x2_std: Vec<f64>,
    /// The weights `w` (one per row of `X₂`).
    w: Vec<f64>,
    /// `c = L⁻ᵀ (V₂ w + L⁻¹H s)` (training points).
    c: Vec<f64>,
    /// `s = L_A⁻ᵀ U₂ w` (trend coefficients).
    s: Vec<f64>,
    /// Bits of the model's standardised restricted log likelihood, signal variance and output
    /// scale (outputs scaled by a constant standardise to the same first two), so that
    /// applying the contraction to another model is refused.
    model_key: [u64; 3],
}

impl GpModel {
    /// Reduces `x ↦ Σ(x, X₂) w` for the rows of `x2` (`m₂ × d`) and weights `w` (`m₂`): see
    /// [`CovarianceContraction::apply`].
    ///
    /// ```
    /// # use nalgebra::{DMatrix, DVector};
    /// # let x = DMatrix::from_fn(10, 1, |i, _| i as f64);
    /// # let y: Vec<f64> = (0..10).map(|i| (i as f64 / 2.0).cos()).collect();
    /// let model = gp::GpParams::new().restarts(0).fit(&x, &y)?;
    /// let w = [0.3, -1.0, 2.0];
    /// let x2 = DMatrix::from_column_slice(3, 1, &[1.0, 4.5, 7.0]);
    /// let reduced = model.covariance_contraction(&x2, &w)?;
    /// let xs = DMatrix::from_column_slice(2, 1, &[2.5, 12.0]);
    /// let dense = model.posterior_cov(&xs, &x2)? * DVector::from_column_slice(&w);
    /// let fast = reduced.apply(&model, &xs)?;
    /// assert!((fast - dense).amax() < 1e-10);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn covariance_contraction(
        &self,
        x2: &DMatrix<f64>,
        w: &[f64],
    ) -> Result<CovarianceContraction, GpError> {
        check_points(x2, self.d, "x2")?;
        check_per_row(x2, w, "w")?;
        let x2_std = self.scaling.standardize_rows(x2, 0..x2.nrows());
        let (_, v2, u2) = self.latent_parts(&x2_std);
        let weighted = |m: &Mat<f64>| -> Vec<f64> {
            (0..m.nrows())
                .map(|i| (0..m.ncols()).map(|j| m[(i, j)] * w[j]).sum())
                .collect()
        };
        let mut s = weighted(&u2);
        small_backward_solve(&self.a_chol, self.p, &mut s);
        let mut c = Mat::<f64>::from_fn(self.n, 1, |i, _| {
            let trend: f64 = (0..self.p)
                .map(|k| self.linv_h[i + k * self.n] * s[k])
                .sum();
            trend
        });
        for (i, v) in weighted(&v2).into_iter().enumerate() {
            c[(i, 0)] += v;
        }
        solve_upper_triangular_in_place(self.chol_ref().transpose(), c.as_mut(), Par::Seq);
        Ok(CovarianceContraction {
            x2_std,
            w: w.to_vec(),
            c: (0..self.n).map(|i| c[(i, 0)]).collect(),
            s,
            model_key: self.contraction_key(),
        })
    }

    fn contraction_key(&self) -> [u64; 3] {
        [
            self.lml_std.to_bits(),
            self.sf2.to_bits(),
            self.scaling.y_scale.to_bits(),
        ]
    }

    /// `Σ_j k(a, b_j) w_j`: the standardised signal covariance of the standardised point `a`
    /// with the row-major standardised points `b`, weighted.
    fn weighted_signal_cov(&self, a: &[f64], b: &[f64], w: &[f64]) -> f64 {
        b.chunks_exact(self.d)
            .zip(w)
            .map(|(b, w)| {
                let r2 = crate::kernel::scaled_sq_dist(a, b, &self.inv_ls2);
                self.sf2 * self.kernel.correlation(r2) * w
            })
            .sum()
    }
}

impl CovarianceContraction {
    /// `Σ(x, X₂) w` at the rows of `x` (`m × d`), original output units² times the weights'
    /// units: equal to `model.posterior_cov(x, x2) * w` up to rounding. `model` must be the
    /// one that made the contraction.
    pub fn apply(&self, model: &GpModel, x: &DMatrix<f64>) -> Result<DVector<f64>, GpError> {
        if model.contraction_key() != self.model_key || model.n != self.c.len() {
            return Err(GpError::InvalidParameter {
                name: "model",
                reason: "the covariance contraction was made from another GP model".into(),
            });
        }
        check_points(x, model.d, "x")?;
        let ys2 = model.scaling.y_scale.powi(2);
        let mut h = vec![0.0; model.p];
        Ok(DVector::from_fn(x.nrows(), |r, _| {
            let a = model.scaling.standardize_rows(x, r..r + 1);
            let prior = model.weighted_signal_cov(&a, &self.x2_std, &self.w);
            let data = model.weighted_signal_cov(&a, &model.x_std, &self.c);
            model.mean.basis_into(&a, &mut h);
            let trend: f64 = h.iter().zip(&self.s).map(|(h, s)| h * s).sum();
            (prior - data + trend) * ys2
        }))
    }
}
