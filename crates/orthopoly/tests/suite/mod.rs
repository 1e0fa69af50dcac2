//! Test modules of the `orthopoly` integration-test binary.
mod basis;
mod errors;
mod fixture;
mod properties;
mod quadrature;
pub mod strategies;
