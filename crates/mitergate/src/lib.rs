//! `mitergate`: a finite-element miter gate leaf, condensed to the quoin and the strain gauges,
//! with a quoin contact model and synthetic / field data generators.
//!
//! Units throughout: inches, lbf, psi, lbf/in for line loads, microstrain for strains.
//!
//! # The finite-element leaf (paper Sec. 4.1, Eq. 47)
//!
//! The paper calibrated the quoin contact forces of a USACE Greenup-lock miter gate against an
//! ABAQUS shell model. We do not have that model, so this crate builds its own, parametrically:
//!
//! * [`GateConfig`] — every dimension of a horizontally framed leaf (skin plate, horizontal
//!   girders with downstream flanges, vertical diaphragms, quoin and miter end posts with bearing
//!   webs), the material, the mesh density and the strain gauges. [`GateConfig::default`] is an
//!   Ohio-River-lock-like leaf read from the embedded `data/default_gate.toml`.
//! * [`GateModel::build`] meshes the leaf with flat 4-node shells ([`shell`]: QM6 incompatible-
//!   mode membrane + drilling penalty + MITC4 plate bending), applies the pintle, gudgeon and
//!   miter-bearing supports, assembles the sparse stiffness and factors it once (sparse
//!   supernodal Cholesky from `faer`).
//! * [`GateModel::condense`] reduces the leaf to what calibration needs: the strain matrix
//!   `A` of Eq. 47, the water terms and the quoin flexibility, as a
//!   [`condensed::CondensedGate`], using adjoint solves.
//!
//! Coordinates (the leaf frame): `x` along the leaf from the quoin (`x = 0`) to the miter end
//! (`x = L`); `y` normal to the skin plate, positive downstream (the skin plate is the plane
//! `y = 0`, framing at `y > 0`); `z` up from the sill (`z = 0`) to the top of the quoin
//! (`z = H`). Full-DOF vectors have 6 entries per node `[ux, uy, uz, rx, ry, rz]` (in, rad; or
//! lbf, lbf·in for loads).
//!
//! ```
//! use mitergate::{GateConfig, GateModel};
//! // a coarse version of the default leaf (the default mesh has 12 in elements)
//! let mut cfg = GateConfig::default();
//! cfg.mesh.element_size = 60.0;
//! let model = GateModel::build(&cfg).unwrap();
//! let f = model.water_load(600.0, 100.0).unwrap();
//! let u = model.solve(&f).unwrap();
//! let strains = model.gauge_strains(&u); // microstrain, one per gauge
//! assert_eq!(strains.len(), 7);
//! ```
//!
//! Users with their own gate model bring it as an Abaqus / CalculiX deck ([`inp`]): `S4`/`S4R`
//! quads, `S3` triangles ([`tri`]) and `B31` beams ([`beam`]) are built into the same sparse
//! system, and [`inp::ImportedModel::condense`] with an [`inp::ImportSpec`] (quoin set, skin
//! set, frame, gauges) gives the same [`condensed::CondensedGate`] through the same code.
//!
//! See `docs/mitergate.md` for the model description and `docs/verification.md` for the
//! element and model verification.
//!
//! # Contact, truth and trait implementations (paper Sec. 4.1-4.3)
//!
//! * [`condensed`]: the condensed gate (`C`, `T`, `A`, water tables), the contract between
//!   the FE model and everything downstream.
//! * [`contact`]: the quoin contact model `g_BC(x, θ)` with a bottom gap (Eq. 45-46): linear
//!   normal springs without tension, the bilinear tangential law, solved exactly by an
//!   active-set method on the `2m`-sized condensed system (see `docs/contact.md`).
//! * [`truth`]: the paper's synthetic truth (Sec. 4.3, Eq. 53-54, Table 1) and a check that
//!   the discrepancy is visible through the gauges.
//! * [`gate_model`]: `mlmodel` trait implementations (contact forces as the unobservable
//!   model, strains as the linear observable model).
//! * [`field`]: a field-data simulator (months of lockages, pools, temperatures and gauge
//!   effects such as thermal strain, drift or a growing gap) around any true strain function,
//!   for the close-the-loop workflow of `bamudi::closeloop` (see `docs/closeloop.md`).

// `!(x > 0.0)` is used on purpose throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod beam;
pub mod calculix;
mod condense;
pub mod condensed;
pub mod config;
pub mod contact;
pub mod fe;
pub mod field;
pub mod gate_model;
pub mod inp;
pub mod loads;
pub mod mesh;
mod model;
pub mod plot;
pub mod shell;
pub mod tri;
pub mod truth;

pub use condense::DEFAULT_NU;
pub use config::GateConfig;
pub use fe::Reactions;
pub use model::{GateModel, RigidQuoinResponse, WATER_LEVEL_RANGE};
pub use plot::plot_mesh;

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
    /// Running CalculiX or reading its results failed.
    #[error("CalculiX cross-check: {0}")]
    CalculiX(String),
    /// Plotting failed.
    #[error("plotting to `{path}` failed: {message}")]
    Plot {
        /// Output file.
        path: std::path::PathBuf,
        /// Backend message.
        message: String,
    },
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
}

fn source_name(path: &Option<std::path::PathBuf>) -> String {
    match path {
        Some(p) => format!(" in `{}`", p.display()),
        None => String::new(),
    }
}

/// Names of the six nodal degrees of freedom, in storage order.
pub const DOF_NAMES: [&str; 6] = ["ux", "uy", "uz", "rx", "ry", "rz"];
