//! The application's single error type.

/// Errors of the gate application.
#[derive(Debug, thiserror::Error)]
pub enum GateAppError {
    /// The calibration engine failed.
    #[error(transparent)]
    Engine(#[from] bamudi::BamudiError),
    /// The gate model (build, condensation, contact, simulators) failed.
    #[error(transparent)]
    Gate(#[from] mitergate::GateError),
    /// A model evaluation failed.
    #[error(transparent)]
    Model(#[from] mlmodel::ModelError),
    /// Writing a plot failed.
    #[error("plot {file}: {reason}")]
    Plot {
        /// SVG file.
        file: String,
        /// Message.
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
    /// A simulated record could not be made (a contact solve failed: the message names the
    /// levels and the gap).
    #[error("simulating the field record: {0}")]
    Simulation(String),
    /// An option of a study or a command is invalid (the message names it).
    #[error("invalid option: {0}")]
    Option(String),
    /// An input is invalid; the message names the file, key or column and what is wrong.
    #[error("{0}")]
    Invalid(String),
    /// (De)serialisation failed.
    #[error("{context}: {reason}")]
    Serde {
        /// What was (de)serialised.
        context: String,
        /// Parser message.
        reason: String,
    },
}

/// Result alias.
pub type Result<T> = std::result::Result<T, GateAppError>;

impl GateAppError {
    /// A plot error for `file`.
    pub fn plot(file: &std::path::Path, reason: impl std::fmt::Display) -> Self {
        Self::Plot {
            file: file.display().to_string(),
            reason: reason.to_string(),
        }
    }
}
