//! The crate's single error type.

use std::path::PathBuf;

/// Everything that can go wrong in `seqnet`: bad hyper-parameters, bad data, numerical failure
/// during training, and I/O or format problems when saving/loading a network.
#[derive(Debug, thiserror::Error)]
pub enum SeqError {
    /// A hyper-parameter is outside its valid range.
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParameter {
        /// Name of the offending parameter (as in the builder method).
        name: &'static str,
        /// Why the value was rejected.
        reason: String,
    },
    /// A matrix or buffer has the wrong shape.
    #[error("shape mismatch for {what}: expected {expected}, found {found}")]
    Shape {
        /// Which argument is wrong.
        what: &'static str,
        /// The shape that was required.
        expected: String,
        /// The shape that was given.
        found: String,
    },
    /// An input value is NaN or infinite.
    #[error("non-finite value {value} in {what} at row {row}, column {col}")]
    NonFinite {
        /// Which argument holds the value (`x` or `y`).
        what: &'static str,
        /// Row (sample) index, 0-based.
        row: usize,
        /// Column index, 0-based.
        col: usize,
        /// The offending value.
        value: f64,
    },
    /// Training diverged: the mini-batch loss or gradient became NaN/infinite.
    #[error(
        "training diverged: non-finite {what} at epoch {epoch}, batch {batch} (try a smaller learning rate or a clip norm)"
    )]
    Diverged {
        /// `loss` or `gradient`.
        what: &'static str,
        /// Epoch index, 0-based.
        epoch: usize,
        /// Mini-batch index inside the epoch, 0-based.
        batch: usize,
    },
    /// Not enough samples for the requested split / batch.
    #[error("not enough data: {reason}")]
    NotEnoughData {
        /// Explanation including the counts involved.
        reason: String,
    },
    /// A saved network has a different format version or shape than expected.
    #[error("incompatible model file {path}: expected {expected}, found {found}")]
    Format {
        /// The file being read.
        path: PathBuf,
        /// What the loader (or caller) required.
        expected: String,
        /// What the file contains.
        found: String,
    },
    /// File-system error while saving or loading.
    #[error("I/O error on {path}: {source}")]
    Io {
        /// The file being read or written.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid JSON for a saved network.
    #[error("cannot parse model file {path}: {source}")]
    Json {
        /// The file being read or written.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: serde_json::Error,
    },
}
