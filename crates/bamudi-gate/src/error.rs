//! The application's single error type.

/// Errors of the gate application.
#[derive(Debug, thiserror::Error)]
pub enum GateAppError {
    /// The calibration engine failed.
    #[error(transparent)]
    Engine(#[from] bamudi::BamudiError),
    /// The close loop failed (a measured record, its configuration, a step of the loop).
    #[error(transparent)]
    CloseLoop(#[from] bamudi_closeloop::CloseLoopError),
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

/// The one line an error and its causes print as (`outer: inner: ...`), each piece once:
/// a cause whose text the line already ends with is left out (an I/O error that shows its
/// source in its own message), and a cause that starts with what the line ends with (a flag's
/// context `--data rec.csv` and a message `rec.csv: line 3: ...`) continues it instead of
/// repeating it. The command line prints this after `error: `; the Python package raises it.
///
/// ```
/// use bamudi_gate::error::one_line;
/// let causes = ["--gate g.toml", "I/O error on `g.toml`: not found", "not found"];
/// assert_eq!(one_line(causes.map(String::from)), "--gate g.toml: I/O error on `g.toml`: not found");
/// let causes = ["--data rec.csv", "rec.csv: line 3, column `SG1`: empty value"];
/// assert_eq!(one_line(causes.map(String::from)), "--data rec.csv: line 3, column `SG1`: empty value");
/// ```
pub fn one_line(causes: impl IntoIterator<Item = String>) -> String {
    let mut line = String::new();
    for cause in causes {
        let cause = cause.trim_end();
        if cause.is_empty() || line.ends_with(cause) {
            continue;
        }
        if line.is_empty() {
            line.push_str(cause);
            continue;
        }
        // the longest tail of the line (from a word start) that the cause starts with, then `:`
        let overlap = (0..line.len())
            .filter(|&k| line.is_char_boundary(k) && (k == 0 || line[..k].ends_with(' ')))
            .map(|k| &line[k..])
            .find(|tail| cause.starts_with(tail) && cause[tail.len()..].starts_with(':'))
            .map(str::len);
        match overlap {
            Some(n) => line.push_str(&cause[n..]),
            None => {
                line.push_str(": ");
                line.push_str(cause);
            }
        }
    }
    line
}

/// [`one_line`] of `error` and its chain of sources.
pub fn one_line_of(error: &(dyn std::error::Error + 'static)) -> String {
    one_line(std::iter::successors(Some(error), |e| e.source()).map(ToString::to_string))
}
