//! Prior mean `h(x)ᵀβ` of the universal-kriging model (paper Eq. A1).

use serde::{Deserialize, Serialize};

/// Regression functions `h(x)` of the prior mean `h(x)ᵀβ` (Eq. A1). The coefficients `β` are
/// never hyper-parameters of the optimiser: for every kernel setting they are the generalised
/// least-squares estimate `β̂ = (Hᵀ K⁻¹ H)⁻¹ Hᵀ K⁻¹ y` (below Eq. A4), and the predictive
/// covariance carries the extra term of Eq. (A4) for their estimation uncertainty.
///
/// The basis is evaluated on the *standardised* inputs; this changes only the parametrisation
/// of `β`, not the fitted model (the reported coefficients are converted back to original units).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Mean {
    /// No regression part. Because outputs are standardised, the prior mean is the training
    /// sample mean in original units (a plug-in value, as in scikit-learn's `normalize_y=True`;
    /// its uncertainty is not propagated).
    Zero,
    /// Unknown constant `β₀` (ordinary kriging).
    #[default]
    Constant,
    /// Unknown constant plus one slope per input column (universal kriging with a linear trend).
    Linear,
}

impl Mean {
    /// Number of regression coefficients `p` for inputs of dimension `dim`.
    ///
    /// ```
    /// use gp::Mean;
    /// assert_eq!(Mean::Zero.n_coefficients(2), 0);
    /// assert_eq!(Mean::Constant.n_coefficients(2), 1);
    /// assert_eq!(Mean::Linear.n_coefficients(2), 3);
    /// ```
    pub fn n_coefficients(&self, dim: usize) -> usize {
        match self {
            Mean::Zero => 0,
            Mean::Constant => 1,
            Mean::Linear => 1 + dim,
        }
    }

    /// Writes `h(x)` for one input row into `out` (length `n_coefficients(x.len())`).
    ///
    /// ```
    /// use gp::Mean;
    /// let mut h = [0.0; 3];
    /// Mean::Linear.basis_into(&[2.0, -1.0], &mut h);
    /// assert_eq!(h, [1.0, 2.0, -1.0]);
    /// ```
    pub fn basis_into(&self, x: &[f64], out: &mut [f64]) {
        match self {
            Mean::Zero => {}
            Mean::Constant => out[0] = 1.0,
            Mean::Linear => {
                out[0] = 1.0;
                out[1..].copy_from_slice(x);
            }
        }
    }
}
