//! The parametric gate: its configuration, mesh, model and condensation.

mod config;
mod model;
