//! Stationary covariance functions (paper Eq. 33-35) and their derivatives with respect to the
//! log hyper-parameters.
//!
//! All kernels are written in terms of the *scaled squared distance*
//! `r² = Σ_i (x_i − x'_i)² / ℓ_i²` (isotropic kernels share one `ℓ`). Eq. (34) of the paper
//! prints the norm `‖x − x'‖₂` unsquared in the exponent; that is a typo — the squared-exponential
//! kernel uses the squared distance, consistent with the appendix correlation function Eq. (A2)
//! (`γ_i = 1 / (2ℓ_i²)`). This crate uses the squared distance throughout.

use serde::{Deserialize, Serialize};

/// √5, used by the Matérn 5/2 kernel.
const SQRT5: f64 = 2.236_067_977_499_79;

/// The signal part `k₁` of the covariance function `k = k₁ + k₂` (Eq. 33); the white-noise part
/// `k₂ = σ_n² δ` (Eq. 35) is added by the model on the training diagonal.
///
/// With `ard: true` every input column has its own length scale (automatic relevance
/// determination, Eq. A2); with `ard: false` one length scale is shared (Eq. 34).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Kernel {
    /// Squared exponential `σ_f² exp(−r²/2)` (Eq. 34 with the squared distance, Eq. A2).
    SquaredExponential {
        /// One length scale per input column if `true`.
        ard: bool,
    },
    /// Matérn ν = 5/2: `σ_f² (1 + √5 r + 5r²/3) exp(−√5 r)`; twice differentiable sample paths,
    /// the alternative the paper suggests after Eq. (34).
    Matern52 {
        /// One length scale per input column if `true`.
        ard: bool,
    },
}

impl Default for Kernel {
    /// Squared exponential with ARD length scales.
    fn default() -> Self {
        Kernel::SquaredExponential { ard: true }
    }
}

impl Kernel {
    /// Whether each input column has its own length scale.
    ///
    /// ```
    /// use gp::Kernel;
    /// assert!(Kernel::Matern52 { ard: true }.is_ard());
    /// ```
    pub fn is_ard(&self) -> bool {
        match *self {
            Kernel::SquaredExponential { ard } | Kernel::Matern52 { ard } => ard,
        }
    }

    /// Number of length scales for inputs of dimension `dim` (`dim` if ARD, else 1).
    ///
    /// ```
    /// use gp::Kernel;
    /// assert_eq!(Kernel::SquaredExponential { ard: true }.n_length_scales(3), 3);
    /// assert_eq!(Kernel::SquaredExponential { ard: false }.n_length_scales(3), 1);
    /// ```
    pub fn n_length_scales(&self, dim: usize) -> usize {
        if self.is_ard() { dim } else { 1 }
    }

    /// Unit-variance correlation `c(r²)` as a function of the scaled squared distance.
    ///
    /// ```
    /// use gp::Kernel;
    /// let se = Kernel::SquaredExponential { ard: false };
    /// assert_eq!(se.correlation(0.0), 1.0);
    /// assert!((se.correlation(2.0) - (-1.0f64).exp()).abs() < 1e-15);
    /// ```
    #[inline]
    pub fn correlation(&self, r2: f64) -> f64 {
        match self {
            Kernel::SquaredExponential { .. } => (-0.5 * r2).exp(),
            Kernel::Matern52 { .. } => {
                let r = r2.sqrt();
                (1.0 + SQRT5 * r + 5.0 / 3.0 * r2) * (-SQRT5 * r).exp()
            }
        }
    }

    /// Correlation `c(r²)` and the length-scale factor `g(r²)` such that
    /// `∂c/∂ln ℓ_i = g(r²) (x_i − x'_i)² / ℓ_i²` (for an isotropic kernel the sum over `i`
    /// gives `g r²`). `g = c` for the squared exponential and
    /// `g = (5/3)(1 + √5 r) exp(−√5 r)` for Matérn 5/2 (finite at `r = 0`).
    ///
    /// ```
    /// use gp::Kernel;
    /// let m = Kernel::Matern52 { ard: true };
    /// let (c, g) = m.correlation_and_factor(0.0);
    /// assert_eq!((c, g), (1.0, 5.0 / 3.0));
    /// ```
    #[inline]
    pub fn correlation_and_factor(&self, r2: f64) -> (f64, f64) {
        match self {
            Kernel::SquaredExponential { .. } => {
                let c = (-0.5 * r2).exp();
                (c, c)
            }
            Kernel::Matern52 { .. } => {
                let r = r2.sqrt();
                let e = (-SQRT5 * r).exp();
                let c = (1.0 + SQRT5 * r + 5.0 / 3.0 * r2) * e;
                let g = 5.0 / 3.0 * (1.0 + SQRT5 * r) * e;
                (c, g)
            }
        }
    }

    /// Covariance `k₁(x, x')` for signal variance `exp(log_signal_variance)` and length scales
    /// `exp(log_length_scales)` (length `n_length_scales(x.len())`), with its gradient with
    /// respect to `[ln σ_f², ln ℓ_1, …]`. Inputs are in whatever units the length scales are in.
    ///
    /// Panics if the slice lengths disagree (this is a low-level building block; the model
    /// validates its inputs before calling it).
    ///
    /// ```
    /// use gp::Kernel;
    /// let k = Kernel::SquaredExponential { ard: true };
    /// let (v, grad) = k.value_and_gradient(&[0.0, 0.0], &[1.0, 0.0], 0.0, &[0.0, 0.0]);
    /// assert!((v - (-0.5f64).exp()).abs() < 1e-15);
    /// assert_eq!(grad.len(), 3);
    /// assert!((grad[0] - v).abs() < 1e-15); // ∂k/∂ln σ_f² = k
    /// ```
    pub fn value_and_gradient(
        &self,
        x: &[f64],
        x_prime: &[f64],
        log_signal_variance: f64,
        log_length_scales: &[f64],
    ) -> (f64, Vec<f64>) {
        assert_eq!(x.len(), x_prime.len(), "x and x' must have the same length");
        assert_eq!(
            log_length_scales.len(),
            self.n_length_scales(x.len()),
            "wrong number of length scales"
        );
        let sf2 = log_signal_variance.exp();
        let terms: Vec<f64> = x
            .iter()
            .zip(x_prime)
            .enumerate()
            .map(|(i, (a, b))| {
                let ls = if self.is_ard() {
                    log_length_scales[i]
                } else {
                    log_length_scales[0]
                };
                (a - b).powi(2) * (-2.0 * ls).exp()
            })
            .collect();
        let r2: f64 = terms.iter().sum();
        let (c, g) = self.correlation_and_factor(r2);
        let mut grad = Vec::with_capacity(1 + log_length_scales.len());
        grad.push(sf2 * c);
        if self.is_ard() {
            grad.extend(terms.iter().map(|t| sf2 * g * t));
        } else {
            grad.push(sf2 * g * r2);
        }
        (sf2 * c, grad)
    }
}

/// Scaled squared distance between rows `a` and `b` with inverse squared length scales
/// `inv_ls2` (one per column, already expanded for isotropic kernels).
#[inline]
pub(crate) fn scaled_sq_dist(a: &[f64], b: &[f64], inv_ls2: &[f64]) -> f64 {
    let mut r2 = 0.0;
    for ((p, q), w) in a.iter().zip(b).zip(inv_ls2) {
        let d = p - q;
        r2 += d * d * w;
    }
    r2
}
