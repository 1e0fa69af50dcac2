//! `gp`: Gaussian-process regression with ML-II hyper-parameter fitting — squared-exponential
//! and Matérn 5/2 kernels (isotropic or ARD) plus white noise, zero / constant / linear prior
//! mean estimated by generalised least squares (universal kriging).
//!
//! This is the surrogate of Module 3 of BA-MUDI (paper Sec. 3.3.3): one GP per discrepancy
//! coefficient `α̂_k(x)`, trained on noisy LSTM-derived targets, whose predictive means and
//! (cross-)covariances enter the likelihood of the gap length (Eq. 36-37, 50-51).
//!
//! # Model
//! `y(x) = h(x)ᵀβ + f(x) + ε`, `f ~ GP(0, k₁)`, `ε ~ N(0, σ_n²)` i.i.d. (Eq. 33, 35, A1):
//! * [`Kernel::SquaredExponential`]: `k₁ = σ_f² exp(−½ Σ_i (x_i − x'_i)²/ℓ_i²)`.
//!   **Eq. (34) of the paper writes the unsquared norm `‖x − x'‖₂` in the exponent; that is a
//!   typo** (the unsquared version is the exponential/Ornstein-Uhlenbeck kernel). We use the
//!   squared distance, consistent with the appendix Eq. (A2) with `γ_i = 1/(2ℓ_i²)`.
//! * [`Kernel::Matern52`]: `k₁ = σ_f² (1 + √5 r + 5r²/3) e^{−√5 r}`, `r² = Σ_i (x_i − x'_i)²/ℓ_i²`.
//! * `ard: true` gives one length scale per input column, `false` one shared length scale.
//! * White noise `σ_n² δ` (Eq. 35) is estimated ([`GpParams::estimate_noise`]`(true)`, default)
//!   or replaced by a fixed tiny nugget. `δ` is applied per observation (training-matrix
//!   diagonal), so repeated inputs are treated as independent noisy replicates.
//! * [`Mean`]: `Zero`, `Constant` or `Linear` regression functions `h(x)`; `β` is always the GLS
//!   estimate `β̂ = (HᵀK⁻¹H)⁻¹HᵀK⁻¹y`.
//!
//! # Prediction (Eq. A3-A4)
//! [`GpModel::predict`] returns the posterior mean `h(x)ᵀβ̂ + k(x)ᵀK⁻¹(y − Hβ̂)` (Eq. A3) and the
//! latent variance. [`GpModel::posterior_cov`] returns the full joint covariance between two
//! arbitrary point sets (what Eq. 51 needs across experiments):
//! `k(x,x') − k(x)ᵀK⁻¹k(x') + u(x)ᵀ(HᵀK⁻¹H)⁻¹u(x')`, `u(x) = h(x) − HᵀK⁻¹k(x)`. The last term is the
//! extra variance of Eq. (A4) from estimating `β`; it is always included. Here `K` includes the
//! noise, i.e. Eq. (A4) is written with the covariance `σ̂²R` replaced by `k₁ + k₂`, which is the
//! same thing with a nugget. Variances are of the latent `f` (no noise);
//! [`GpModel::predict_observation`] adds `σ_n²`.
//!
//! # Fitting (ML-II)
//! * **Standardisation.** Inputs are centred and scaled per column, outputs centred and scaled
//!   (population standard deviation, like scikit-learn's `normalize_y`); the scaling is stored
//!   in the model and every public result is in original units.
//! * **Likelihood.** The **restricted** (REML) log marginal likelihood is maximised for every
//!   mean (with `Mean::Zero` it is the ordinary one): it is the likelihood with `β` integrated
//!   out under a flat prior, the same assumption that yields the Eq. (A4) variance term, so
//!   fitting and prediction are consistent. See [`LmlProblem`] for the formula and its analytic
//!   gradient `½ tr[(ααᵀ − P) ∂K/∂θ]`.
//! * **Optimiser.** argmin's L-BFGS (More-Thuente line search, memory 10) over
//!   `θ = [ln σ_f², ln ℓ…, ln σ_n²]` (standardised units). **Bounds** ([`Bounds`], default
//!   `σ_f² ∈ [1e-6, 1e4]`, `ℓ ∈ [1e-3, 1e3]`, `σ_n² ∈ [1e-10, 10]`) are enforced by evaluating the
//!   likelihood at `clamp(θ)` and adding a quadratic penalty outside the box ([`BoundedLml`]).
//! * **Multi-start**, deterministic: start 0 is the data-driven default (`σ_f²` = output
//!   variance, `ℓ` = one input standard deviation, `σ_n²` = 1 % of the output variance); then
//!   [`GpParams::restarts`] log-uniform random starts from an explicit [`GpParams::seed`].
//!   The best optimum wins; every start is reported in [`GpModel::diagnostics`]. The starts
//!   run in parallel on rayon's pool, each with its own buffers, with the same result for any
//!   number of threads (500 points, 6 starts, 2 cores: 1.57x faster than one after the other).
//! * **Jitter.** If `K` is numerically not positive definite, a diagonal jitter of
//!   1e-10 … 1e-4 times its mean diagonal is tried in decades (the workspace's shared ladder,
//!   `numerics::JITTER_LADDER`, applied by `numerics::cholesky::cholesky_in_place`); the jitter
//!   used by the final model is reported in [`FitDiagnostics::jitter`] (never silent). Beyond
//!   that the fit fails with [`GpError::NotPositiveDefinite`].
//! * **Log marginal likelihood units.** [`GpModel::log_marginal_likelihood`] is for the data in
//!   original output units (standardised value − `(n − p) ln s_y`);
//!   [`GpModel::log_marginal_likelihood_standardized`] is the optimised value (equal to
//!   scikit-learn's `log_marginal_likelihood_value_` for the same model with `normalize_y=True`
//!   and `Mean::Zero`).
//!
//! # Example
//! ```
//! use gp::{GpParams, Kernel, Mean};
//! use nalgebra::DMatrix;
//! // 30 points of a noisy 2-D response (inputs in inches, output in lbf).
//! let x = DMatrix::from_fn(30, 2, |i, j| 24.0 + 24.0 * ((i * (3 + j)) % 30) as f64);
//! let y: Vec<f64> = (0..30).map(|i| (x[(i, 0)] / 200.0).sin() + 0.001 * x[(i, 1)]).collect();
//! let model = GpParams::new()
//!     .kernel(Kernel::SquaredExponential { ard: true })
//!     .mean(Mean::Constant)
//!     .restarts(2)
//!     .seed(7)
//!     .fit(&x, &y)?;
//! let xs = DMatrix::from_row_slice(2, 2, &[100.0, 200.0, 300.0, 400.0]);
//! let pred = model.predict(&xs)?;              // mean, latent variance (lbf, lbf²)
//! let cov = model.posterior_cov(&xs, &xs)?;    // 2 x 2 joint covariance incl. Eq. (A4)
//! assert!((cov[(0, 0)] - pred.variance[0]).abs() < 1e-9);
//! # Ok::<(), gp::GpError>(())
//! ```
//!
//! # Building blocks
//! [`Kernel::value_and_gradient`] (kernel and its log-parameter gradient), [`LmlProblem`]
//! (argmin `CostFunction` + `Gradient`: negative restricted LML over the log parameters) and
//! [`BoundedLml`] (the bounded version the fit optimises) are public for reuse and testing.
//!
//! # Performance
//! Dense linear algebra uses faer (Cholesky, triangular solves, `K⁻¹` for the gradient), as an
//! implementation detail: no faer type appears in this crate's public API;
//! each likelihood evaluation costs one Cholesky, and each gradient one inverse from the
//! factor plus a single O(n² d) pass, with all `n × n` buffers reused across evaluations.
//! Benchmarks against scikit-learn are in `docs/benchmarks.md` (## gp).

/// The crate README's example, compiled and run as a doc test.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctest;

mod contraction;
mod error;
mod kernel;
mod likelihood;
mod linalg;
mod mean;
mod model;
mod params;
mod validate;

pub use contraction::CovarianceContraction;
pub use error::GpError;
pub use kernel::Kernel;
pub use likelihood::{BoundedLml, LmlProblem, LmlValue, NoiseModel};
pub use mean::Mean;
pub use model::{FitDiagnostics, GpModel, Hyperparameters, Prediction, StartReport};
pub use params::{Bounds, GpParams};
