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
//! See `docs/mitergate.md` for the model description and `docs/verification.md` for the
//! element and model verification.

// `!(x > 0.0)` is used on purpose throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod condense;
pub mod condensed;
pub mod config;
pub mod fe;
pub mod loads;
pub mod mesh;
mod model;
pub mod plot;
pub mod shell;

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
    /// Plotting failed.
    #[error("plotting to `{path}` failed: {message}")]
    Plot {
        /// Output file.
        path: std::path::PathBuf,
        /// Backend message.
        message: String,
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
