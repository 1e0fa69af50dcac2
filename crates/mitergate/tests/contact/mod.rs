//! Tests of the quoin contact model. They (and those of `data` and `multilevel`) run on the
//! analytical beam gate of [`fixture`], shared through [`model`].

pub mod fixture;
mod physics;
mod solver;
mod strategies;

use mitergate::contact::{ContactModel, ContactParams};
use std::sync::OnceLock;

/// The fixture's beam model (shared by all tests of this binary).
pub fn beam() -> &'static fixture::BeamGate {
    static BEAM: OnceLock<fixture::BeamGate> = OnceLock::new();
    BEAM.get_or_init(|| fixture::beam_gate(33, 509))
}

/// The contact model with the paper's parameters on the fixture gate (the condensed form of
/// [`beam`]; tests that use the beam's internals must be revisited when switching gates).
pub fn model() -> &'static ContactModel {
    static MODEL: OnceLock<ContactModel> = OnceLock::new();
    MODEL.get_or_init(|| {
        ContactParams::default()
            .build(fixture::gate())
            .expect("fixture gate is valid")
    })
}

/// Max-norm of a slice.
pub fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |a, x| a.max(x.abs()))
}

/// Resultants (lbf) `[Σ w_b F_N,b, Σ w_b F_T,b]` of blocked line loads.
pub fn resultants(model: &ContactModel, forces: &[f64]) -> [f64; 2] {
    let n = model.gate().n_points();
    let w = model.tributary_lengths();
    [0, 1].map(|c| (0..n).map(|b| w[b] * forces[c * n + b]).sum())
}
