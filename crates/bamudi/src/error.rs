//! The crate's single error type.

/// Errors from calibration, I/O and reporting.
#[derive(Debug, thiserror::Error)]
pub enum BamudiError {
    /// A configuration value is invalid.
    #[error("invalid configuration `{name}`: {reason}")]
    InvalidConfig {
        /// Parameter name (TOML key).
        name: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// Arrays passed together have inconsistent sizes.
    #[error("dimension mismatch in {what}: expected {expected}, got {got}")]
    Dimension {
        /// What was compared.
        what: String,
        /// Expected size.
        expected: usize,
        /// Size received.
        got: usize,
    },
    /// A CSV file is malformed; `row` is the file line (the header is line 1).
    #[error("{file}: line {row}, column `{column}`: {reason}")]
    Csv {
        /// File path.
        file: String,
        /// File line (the header is line 1); 0 when the problem is not tied to a line.
        row: usize,
        /// Column name (or `-`).
        column: String,
        /// What is wrong.
        reason: String,
    },
    /// A text file that is not UTF-8; `line` is the line of its first bad byte.
    #[error("{file}: line {line}: {reason}")]
    Encoding {
        /// File path.
        file: String,
        /// File line of the first byte that is not UTF-8 (the first line is 1).
        line: usize,
        /// What is wrong and what to do.
        reason: String,
    },
    /// File-system error with the path.
    #[error("{path}: {source}")]
    Io {
        /// Offending path.
        path: String,
        /// Underlying error.
        #[source]
        source: std::io::Error,
    },
    /// (De)serialisation error with the path or context.
    #[error("{context}: {reason}")]
    Serde {
        /// File or artefact.
        context: String,
        /// Parser message.
        reason: String,
    },
    /// A covariance matrix that must be positive definite is not.
    #[error("{what} is not positive definite (Cholesky failed)")]
    NotPositiveDefinite {
        /// Which matrix.
        what: String,
    },
    /// A shared numerical kernel failed (Cholesky past its jitter ladder, ...).
    #[error(transparent)]
    Numerics(#[from] numerics::NumericsError),
    /// A numerical step failed.
    #[error("numerical failure in {context}: {reason}")]
    Numerical {
        /// Where.
        context: String,
        /// What.
        reason: String,
    },
    /// The posterior has no mass on the grid / chain (all log densities -inf or NaN).
    #[error("degenerate posterior: {0}")]
    DegeneratePosterior(String),
    /// A model evaluation failed.
    #[error(transparent)]
    Model(#[from] mlmodel::ModelError),
    /// Gaussian-process fitting or prediction failed.
    #[error("Gaussian process for coefficient {coefficient}: {reason}")]
    Gp {
        /// Index of the coefficient whose GP failed.
        coefficient: usize,
        /// The GP error message.
        reason: String,
    },
    /// The coefficient estimator (LSTM, smartcore ridge) failed.
    #[error("coefficient estimator `{estimator}`: {reason}")]
    Estimator {
        /// Estimator name.
        estimator: &'static str,
        /// Message.
        reason: String,
    },
    /// A calibration failed (an input it cannot use, a step that left nothing to report).
    #[error("calibration failed: {0}")]
    Calibration(String),
}

/// Result alias.
pub type Result<T> = std::result::Result<T, BamudiError>;

impl BamudiError {
    /// Shorthand for [`BamudiError::InvalidConfig`].
    pub fn config(name: &'static str, reason: impl Into<String>) -> Self {
        Self::InvalidConfig {
            name,
            reason: reason.into(),
        }
    }
    /// Shorthand for [`BamudiError::Dimension`].
    pub fn dim(what: impl Into<String>, expected: usize, got: usize) -> Self {
        Self::Dimension {
            what: what.into(),
            expected,
            got,
        }
    }
}
