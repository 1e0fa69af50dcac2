//! The crate's single error type.

/// Everything that can go wrong in `orthopoly`.
///
/// Every variant names the offending parameter (and, for slices, the index), so a caller can
/// report exactly which input was bad.
///
/// ```
/// use orthopoly::{gauss_legendre, OrthoError};
/// let err = gauss_legendre(0, 0.0, 1.0).unwrap_err();
/// assert!(matches!(err, OrthoError::InvalidParameter { name: "n", .. }));
/// ```
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OrthoError {
    /// A scalar parameter is out of its valid range (zero order, empty interval, NaN bound, ...).
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParameter {
        /// Name of the parameter as it appears in the signature.
        name: &'static str,
        /// Human-readable explanation.
        reason: String,
    },
    /// An element of an input slice is NaN or infinite.
    #[error("`{name}[{index}]` is not finite ({value})")]
    NonFinite {
        /// Name of the slice parameter.
        name: &'static str,
        /// Position of the bad element.
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// A point lies outside the interval `[a, b]` of a Legendre or Chebyshev basis.
    #[error("`points[{index}]` = {point} lies outside the basis interval [{a}, {b}]")]
    OutOfInterval {
        /// Position of the point in the slice.
        index: usize,
        /// The offending point (physical units, e.g. inches).
        point: f64,
        /// Lower end of the interval.
        a: f64,
        /// Upper end of the interval.
        b: f64,
    },
    /// Two slices that must have matching lengths do not.
    #[error("`{name}` has length {found}, expected {expected}")]
    LengthMismatch {
        /// Name of the slice parameter whose length is wrong.
        name: &'static str,
        /// Required length.
        expected: usize,
        /// Actual length.
        found: usize,
    },
    /// The least-squares problem of [`crate::Basis::project`] does not determine all coefficients
    /// (fewer distinct points than terms, or numerically collinear columns).
    #[error(
        "least-squares projection is rank deficient: numerical rank {rank} < {n_terms} terms \
         ({n_points} points)"
    )]
    RankDeficient {
        /// Numerical rank of the basis matrix.
        rank: usize,
        /// Number of basis terms (columns).
        n_terms: usize,
        /// Number of points (rows).
        n_points: usize,
    },
    /// Newton iteration for a quadrature node did not converge.
    #[error("Newton iteration for node {node} of the order-{n} {rule} rule did not converge")]
    NoConvergence {
        /// Name of the quadrature rule.
        rule: &'static str,
        /// Order (number of nodes) of the rule.
        n: usize,
        /// Index of the node that failed.
        node: usize,
    },
}
