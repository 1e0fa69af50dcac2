//! The crate's single error type.

use thiserror::Error;

/// Everything that can go wrong when fitting or evaluating a Gaussian process.
///
/// Each variant names the offending argument (and row / column where that applies) so a caller
/// can report the problem without re-deriving it.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GpError {
    /// A data set had no rows (or no columns).
    #[error("`{name}` is empty: it needs at least one row and one column")]
    EmptyData {
        /// Name of the argument (`x`, `y`, `x1`, ...).
        name: &'static str,
    },
    /// Two arguments that must agree in size do not.
    #[error("shape mismatch: `{name}` has {found} {what}, expected {expected}")]
    ShapeMismatch {
        /// Name of the argument with the wrong size.
        name: &'static str,
        /// What was counted (`rows`, `columns`, `entries`, `parameters`).
        what: &'static str,
        /// The size that was required.
        expected: usize,
        /// The size that was given.
        found: usize,
    },
    /// An input value is NaN or infinite.
    #[error("`{name}` has a non-finite value ({value}) at row {row}, column {col}")]
    NonFinite {
        /// Name of the argument.
        name: &'static str,
        /// Row of the bad value (0-based).
        row: usize,
        /// Column of the bad value (0-based; 0 for vectors).
        col: usize,
        /// The bad value itself.
        value: f64,
    },
    /// Too few training points for the requested prior mean (restricted likelihood needs `n > p`).
    #[error(
        "{n} training points are too few: the prior mean has {p} regression coefficients, need n > p"
    )]
    TooFewPoints {
        /// Number of training points.
        n: usize,
        /// Number of regression coefficients of the prior mean.
        p: usize,
    },
    /// A hyper-parameter setting is invalid (non-positive, non-finite, empty bound interval...).
    #[error("invalid hyper-parameter setting `{name}`: {reason}")]
    InvalidParameter {
        /// Name of the setting.
        name: &'static str,
        /// Why it was rejected.
        reason: String,
    },
    /// A covariance matrix stayed non-positive-definite even after the largest allowed jitter.
    /// `index` is the pivot at which the Cholesky factorisation broke down.
    #[error(
        "{matrix} is not positive definite (Cholesky pivot {index} failed, jitter tried up to {max_jitter:e})"
    )]
    NotPositiveDefinite {
        /// Which matrix (`K` = training covariance, `H^T K^-1 H` = GLS normal matrix).
        matrix: &'static str,
        /// Failing pivot (0-based).
        index: usize,
        /// Largest diagonal jitter that was tried (standardised units).
        max_jitter: f64,
    },
    /// Every optimiser start failed (the message of the last failure is kept).
    #[error("hyper-parameter optimisation failed for all {starts} starts; last error: {last}")]
    OptimizationFailed {
        /// Number of starts tried.
        starts: usize,
        /// Message of the last failure.
        last: String,
    },
}
