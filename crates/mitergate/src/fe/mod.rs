//! Finite elements and their assembly, independent of the gate: flat shell quadrilaterals
//! ([`shell`]), shell triangles ([`tri`]) and beams ([`beam`]), consistent loads ([`loads`]),
//! and the supported, factored [`ShellModel`] that solves `K u = f`.
//!
//! Full-DOF vectors have 6 entries per node `[ux, uy, uz, rx, ry, rz]` (in, rad; or lbf,
//! lbf·in for loads), in the order of [`DOF_NAMES`].

mod assembly;
pub mod beam;
pub mod loads;
pub mod shell;
mod supports;
pub mod tri;

pub(crate) use assembly::element_dofs;
pub use assembly::{GeneralElement, QuadElement, Reactions, ShellMesh, ShellModel};
pub use supports::Support;

/// Names of the six nodal degrees of freedom, in storage order.
pub const DOF_NAMES: [&str; 6] = ["ux", "uy", "uz", "rx", "ry", "rz"];
