//! The crate's single error type.

/// Errors from reading a measured record, configuring the loop, and the loop's steps; an
/// error of the engine (a calibration, a prediction) is carried as [`CloseLoopError::Engine`].
#[derive(Debug, thiserror::Error)]
pub enum CloseLoopError {
    /// A configuration value is invalid.
    #[error("invalid configuration `{name}`: {reason}")]
    InvalidConfig {
        /// Parameter name (TOML key).
        name: &'static str,
        /// Why it is invalid.
        reason: String,
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
    /// A numerical step failed.
    #[error("numerical failure in {context}: {reason}")]
    Numerical {
        /// Where.
        context: String,
        /// What.
        reason: String,
    },
    /// Not enough data rows for a step (e.g. the loop's calibration and validation windows).
    #[error("too few rows for {what}: got {got}")]
    TooFewRows {
        /// What needs the rows.
        what: String,
        /// Rows available.
        got: usize,
    },
    /// A calibration through the [`crate::Calibrator`] interface failed.
    #[error("calibration failed: {0}")]
    Calibration(String),
    /// The engine failed (a calibration, a prediction). A malformed CSV file the engine's
    /// table reader finds is a [`CloseLoopError::Csv`], as the loop's own.
    #[error(transparent)]
    Engine(bamudi::BamudiError),
}

/// Result alias.
pub type Result<T> = std::result::Result<T, CloseLoopError>;

impl From<bamudi::BamudiError> for CloseLoopError {
    fn from(e: bamudi::BamudiError) -> Self {
        match e {
            bamudi::BamudiError::Csv {
                file,
                row,
                column,
                reason,
            } => Self::Csv {
                file,
                row,
                column,
                reason,
            },
            e => Self::Engine(e),
        }
    }
}

impl CloseLoopError {
    /// Shorthand for [`CloseLoopError::InvalidConfig`].
    pub fn config(name: &'static str, reason: impl Into<String>) -> Self {
        Self::InvalidConfig {
            name,
            reason: reason.into(),
        }
    }
}
