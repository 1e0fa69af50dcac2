//! Module 2, the coefficient estimator `α = f_ML(ρ, x, y)` of Eq. 29, with three
//! implementations:
//!
//! * [`ExactLinearEstimator`]: the linear-Gaussian conditional mean, available when `g_o` is
//!   linear. A network trained by mean-squared error on the Eq.-27 training set approximates
//!   the conditional mean `E[α | ρ, x, μ_o]` under the training distribution. Given `(ρ, x)`,
//!   `μ_o = ρ A ḡ(x) + b̄(x) + B α (+ ε_t)` is affine in `α`, so when `α` is Gaussian with the
//!   training moments `(m(x), Σ_α(x))` the conditional mean is exactly
//!   `α̂ = m + Σ_α Bᵀ (B Σ_α Bᵀ + σ_t² I)⁺ (y − ρ A ḡ(x) − b̄(x) − B m)` (`σ_t` = training-output
//!   noise, `⁺` = pseudo-inverse, which is the limit `σ_t → 0` and reduces to least squares
//!   when `B` has full column rank). For the uniform `α` of the [`SamplingRule`] it is the best
//!   *linear* estimator (linear MMSE), which is what the network converges to when the
//!   relation is linear. No training is needed: it is the reference the learnt estimators
//!   are measured against.
//! * [`RidgeEstimator`]: a `smartcore` ridge regression on quadratic features of the
//!   standardised `[ρ, x, y]` (so products `ρ x_j` are representable), one model per coefficient.
//! * [`LstmEstimator`]: the paper's LSTM (Eq. 28, `seqnet`, hand-written backpropagation through
//!   time), fed `[ρ, x, y]` as a sequence (by default 10 scalar steps), trained by mean-squared
//!   error with Adam and early stopping; `seqnet` standardises inputs and outputs itself.
//!
//! Every kind is fitted through the one [`FitEstimator`] trait and predicts through
//! [`CoefficientEstimator`].
//!
//! [`SamplingRule`]: crate::SamplingRule

mod exact;
mod lstm;
mod ridge;

pub use exact::ExactLinearEstimator;
pub use lstm::LstmEstimator;
pub use ridge::RidgeEstimator;
pub use seqnet::LstmSettings;

use crate::error::{BamudiError, Result};
use crate::observe::Observer;
use crate::params::EstimatorParams;
use crate::surrogate::training::{LinearParts, TrainingSet, XContext};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// `α = f_ML(ρ, x, y)` (Eq. 29), evaluated for many experiments at one `ρ`.
pub trait CoefficientEstimator: Send + Sync {
    /// Short name for reports.
    fn name(&self) -> &'static str;
    /// Predicts `α̂` (`N x K`) for the rows of `x` (`N x d`) and `y` (`N x N_o`) at `ρ`.
    /// `ctx` holds the prior-averaged quantities at each row's `x` (used by the exact
    /// estimator; learnt estimators ignore it).
    fn predict(
        &self,
        rho: f64,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
        ctx: &[XContext],
    ) -> Result<DMatrix<f64>>;
}

/// What Module 2 gives an estimator to fit on.
pub struct EstimatorData<'a> {
    /// `A`, `L`, `B = A L` of the model.
    pub parts: &'a LinearParts,
    /// The sampling rule's training-output noise `σ_t` (output units).
    pub noise_sd: f64,
    /// The Eq.-27 training set, when the estimator needs one
    /// ([`FitEstimator::needs_training_set`]).
    pub training: Option<&'a TrainingSet>,
    /// Seed of the estimator's own random steps.
    pub seed: u64,
    /// Receives the learnt estimators' epoch reports.
    pub observer: &'a dyn Observer,
}

impl EstimatorData<'_> {
    /// The training set, or an error naming the estimator that needs it.
    pub fn training(&self, estimator: &'static str) -> Result<&TrainingSet> {
        self.training.ok_or(BamudiError::Estimator {
            estimator,
            reason: "needs the Eq.-27 training set, and none was generated".into(),
        })
    }
}

/// Fitting an estimator of Eq. 29: one signature for every kind (linfa's `Fit`).
pub trait FitEstimator {
    /// Whether [`fit`](Self::fit) needs the Eq.-27 training set (the exact estimator needs
    /// none).
    fn needs_training_set(&self) -> bool;
    /// Fits the estimator.
    fn fit(&self, data: &EstimatorData<'_>) -> Result<FittedEstimator>;
}

impl FitEstimator for EstimatorParams {
    fn needs_training_set(&self) -> bool {
        !matches!(self, Self::ExactLinear)
    }
    fn fit(&self, data: &EstimatorData<'_>) -> Result<FittedEstimator> {
        match self {
            Self::Lstm(settings) => lstm::fit(settings, data),
            Self::Ridge(params) => ridge::fit(params, data),
            Self::ExactLinear => exact::fit(data),
        }
    }
}

/// Stacks `[ρ, x, y]` row-wise into the learnt estimators' raw input matrix.
pub fn stack_inputs(rho: &[f64], x: &DMatrix<f64>, y: &DMatrix<f64>) -> DMatrix<f64> {
    let d = x.ncols();
    DMatrix::from_fn(x.nrows(), 1 + d + y.ncols(), |i, j| match j {
        0 => rho[i],
        j if j <= d => x[(i, j - 1)],
        j => y[(i, j - 1 - d)],
    })
}

/// A fitted estimator of any kind (serialisable, so a re-run can skip training).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FittedEstimator {
    /// See [`ExactLinearEstimator`].
    ExactLinear(ExactLinearEstimator),
    /// See `RidgeEstimator`.
    Ridge(RidgeEstimator),
    /// See `LstmEstimator` (boxed: the network is much larger than the other variants).
    Lstm(Box<LstmEstimator>),
}

impl CoefficientEstimator for FittedEstimator {
    fn name(&self) -> &'static str {
        match self {
            Self::ExactLinear(e) => e.name(),
            Self::Ridge(e) => e.name(),
            Self::Lstm(e) => e.name(),
        }
    }
    fn predict(
        &self,
        rho: f64,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
        ctx: &[XContext],
    ) -> Result<DMatrix<f64>> {
        match self {
            Self::ExactLinear(e) => e.predict(rho, x, y, ctx),
            Self::Ridge(e) => e.predict(rho, x, y, ctx),
            Self::Lstm(e) => e.predict(rho, x, y, ctx),
        }
    }
}
