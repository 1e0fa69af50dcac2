//! [`GateError`], the one error type of the crate.

/// Errors of the `mitergate` crate.
#[derive(Debug, thiserror::Error)]
pub enum GateError {
    /// A hydrostatic response table was malformed.
    #[error("invalid hydrostatic table: {0}")]
    InvalidTable(String),
    /// A configuration parameter is out of its valid range.
    #[error("invalid gate configuration parameter `{parameter}`: {reason}")]
    InvalidConfig {
        /// Dotted name of the parameter, e.g. `girders.heights[3]`.
        parameter: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The TOML text of a configuration could not be parsed.
    #[error("cannot parse gate configuration TOML{}: {message}", source_name(.path))]
    ConfigParse {
        /// File the text came from, if any.
        path: Option<std::path::PathBuf>,
        /// Parser message (with line and column).
        message: String,
    },
    /// A file could not be read or written.
    #[error("I/O error on `{path}`: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A water level is outside its valid range.
    #[error("invalid water level `{parameter}` = {value} in: {reason}")]
    InvalidWaterLevel {
        /// `h_up` or `h_down`.
        parameter: &'static str,
        /// The offending value (in).
        value: f64,
        /// What is wrong.
        reason: String,
    },
    /// An input vector or matrix has the wrong size.
    #[error("`{what}` has length {got}, expected {expected}")]
    DimensionMismatch {
        /// Which argument.
        what: String,
        /// Expected length.
        expected: usize,
        /// Actual length.
        got: usize,
    },
    /// An input value is invalid (non-finite, out of range, unsorted, ...).
    #[error("invalid input `{what}`: {reason}")]
    InvalidInput {
        /// Which argument.
        what: String,
        /// What is wrong.
        reason: String,
    },
    /// The mesh is invalid (degenerate element, node index out of range, ...).
    #[error("invalid mesh: {0}")]
    InvalidMesh(String),
    /// A degree of freedom has no stiffness at all (a node not attached to any element, or a
    /// rotation nothing resists).
    #[error("degree of freedom {dof} of node {node} at {position:?} has no stiffness")]
    UnconnectedDof {
        /// Node index.
        node: usize,
        /// DOF name (`ux`, `uy`, `uz`, `rx`, `ry`, `rz`).
        dof: &'static str,
        /// Node coordinates (in).
        position: [f64; 3],
    },
    /// The supports leave a rigid-body motion of the whole structure free.
    #[error("the supports do not restrain the rigid-body mode {mode}")]
    UnrestrainedRigidMode {
        /// The free mode as a combination of translations (in) and rotations about the
        /// centroid (scaled by the structure size).
        mode: String,
    },
    /// The Cholesky factorisation met a non-positive pivot.
    #[error(
        "stiffness matrix is not positive definite: pivot of {dof} of node {node} at {position:?} \
         (a mechanism or unsupported part)"
    )]
    NotPositiveDefinite {
        /// Node index of the failing pivot.
        node: usize,
        /// DOF name of the failing pivot.
        dof: &'static str,
        /// Node coordinates (in).
        position: [f64; 3],
    },
    /// A sparse-matrix operation of `faer` failed (out of memory, index overflow).
    #[error("sparse linear algebra failure: {0}")]
    Sparse(String),
    /// A strain gauge does not lie on any shell element with the requested surface.
    #[error(
        "gauge `{name}` at {point:?} does not lie on an element whose normal is parallel to {side:?}"
    )]
    GaugeNotOnMesh {
        /// Gauge name.
        name: String,
        /// Gauge point (in).
        point: [f64; 3],
        /// Requested surface side.
        side: [f64; 3],
    },
    /// A dense linear solve failed (singular matrix).
    #[error("dense solve failed: {0}")]
    DenseSolve(String),
    /// An Abaqus / CalculiX input deck could not be parsed.
    #[error("cannot parse .inp deck at line {line}: {reason}")]
    InpParse {
        /// Line of the deck (1-based).
        line: usize,
        /// What is wrong (names the keyword or field).
        reason: String,
    },
    /// A parsed deck cannot be built into a shell stiffness model (unsupported element,
    /// undefined set, missing section or material, unsupported constraint).
    #[error("cannot build a shell model from the .inp deck: {0}")]
    InpBuild(String),
    /// A contact-model hyper-parameter is invalid.
    #[error("invalid contact parameter `{name}` = {value}: {reason}")]
    InvalidContactParameter {
        /// Parameter name.
        name: &'static str,
        /// Offending value.
        value: f64,
        /// Why it is invalid.
        reason: String,
    },
    /// A condensed gate handed to the contact / strain model is inconsistent.
    #[error("invalid condensed gate: {0}")]
    InvalidCondensedGate(String),
    /// An input of the contact model lies outside its domain.
    #[error("contact input `{name}` = {value} is outside [{lo}, {hi}]")]
    ContactDomain {
        /// Input name.
        name: &'static str,
        /// Offending value.
        value: f64,
        /// Lower bound.
        lo: f64,
        /// Upper bound (exclusive for the gap length).
        hi: f64,
    },
    /// A slice passed to the contact model had the wrong length.
    #[error("{what}: expected length {expected}, got {got}")]
    ContactDimension {
        /// Which argument.
        what: &'static str,
        /// Required length.
        expected: usize,
        /// Length received.
        got: usize,
    },
    /// A matrix that must be symmetric positive definite is not.
    #[error("{what} is not positive definite")]
    ContactNotPositiveDefinite {
        /// Which matrix.
        what: &'static str,
    },
    /// An iterative contact solve hit its iteration cap.
    #[error(
        "contact solve did not converge in the {stage} after {iterations} iterations (residual {residual:e})"
    )]
    ContactNotConverged {
        /// Which loop.
        stage: &'static str,
        /// Iterations performed.
        iterations: usize,
        /// Last residual (relative tangential-law residual, or number of active-set changes).
        residual: f64,
    },
    /// A synthetic-data scenario is invalid.
    #[error("invalid scenario parameter `{name}`: {reason}")]
    InvalidScenario {
        /// Parameter name.
        name: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// A [`MultiLevelSpec`](crate::multilevel::MultiLevelSpec) field is invalid.
    #[error("invalid multi-level spec field `{field}`: {reason}")]
    InvalidMultiLevelSpec {
        /// Field name.
        field: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// A reality specification ([`Reality`](crate::reality::Reality)) is invalid.
    #[error("invalid reality specification `{key}`: {reason}")]
    InvalidReality {
        /// The key (dotted path) or file at fault.
        key: String,
        /// Why.
        reason: String,
    },
    /// A gate-configuration field named by a dotted key cannot be scaled
    /// ([`Reality::scaled_field`](crate::reality::Reality::scaled_field)): not a field, not a
    /// number, a factor that is not positive, or a gate that is invalid once scaled.
    #[error("gate field `{key}`: {reason}")]
    GateField {
        /// The dotted key.
        key: String,
        /// Why.
        reason: String,
    },
    /// Assembling the `mlmodel` multi-level model (prior, discrepancy basis, dimensions)
    /// failed.
    #[error("multi-level model: {0}")]
    Model(#[from] mlmodel::ModelError),
}

fn source_name(path: &Option<std::path::PathBuf>) -> String {
    match path {
        Some(p) => format!(" in `{}`", p.display()),
        None => String::new(),
    }
}
