//! `mitergate`: a finite-element miter gate leaf, condensed to the quoin and the strain gauges,
//! with a quoin contact model and synthetic / field data generators.
//!
//! Units throughout: inches, lbf, psi, lbf/in for line loads, microstrain for strains.

pub mod condensed;

/// Errors of the `mitergate` crate.
#[derive(Debug, thiserror::Error)]
pub enum GateError {
    /// A hydrostatic response table was malformed.
    #[error("invalid hydrostatic table: {0}")]
    InvalidTable(String),
}
