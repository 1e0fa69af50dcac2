//! The crate's single error type.

/// Errors of the numerical kernels.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NumericsError {
    /// A matrix stayed non-positive-definite after the largest jitter of the ladder.
    #[error(
        "{what} is not positive definite: Cholesky pivot {index} failed even with a diagonal \
         jitter of {max_jitter:.3e} (the top of the ladder)"
    )]
    NotPositiveDefinite {
        /// Which matrix (for the message).
        what: String,
        /// The failing pivot of the last attempt.
        index: usize,
        /// The largest absolute jitter tried.
        max_jitter: f64,
    },
    /// A matrix that must be square is not, or two sizes disagree.
    #[error("{what}: expected {expected}, got {got}")]
    Dimension {
        /// What was compared.
        what: String,
        /// Expected size.
        expected: usize,
        /// Size received.
        got: usize,
    },
    /// A non-finite value where a finite one is required.
    #[error("{what}: non-finite value at index {index}")]
    NonFinite {
        /// Which argument.
        what: String,
        /// Flat index of the first non-finite value.
        index: usize,
    },
    /// An iterative kernel did not converge.
    #[error("{what}: did not converge")]
    NoConvergence {
        /// What was computed.
        what: String,
    },
    /// An argument outside its domain.
    #[error("{what}: {reason}")]
    Invalid {
        /// Which argument.
        what: String,
        /// Why it is refused.
        reason: String,
    },
}
