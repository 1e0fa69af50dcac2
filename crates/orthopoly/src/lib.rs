//! `orthopoly`: orthogonal polynomial bases and Gauss quadrature on any interval.
//!
//! API contract (being implemented): see the crate README / issue 2.
#![allow(missing_docs)]
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

#[derive(Debug, thiserror::Error)]
pub enum OrthoError {
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParameter { name: &'static str, reason: String },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Family {
    Legendre,
    Chebyshev,
    Hermite,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Basis {
    family: Family,
}

impl Basis {
    pub fn new(family: Family, _a: f64, _b: f64, _n_terms: usize) -> Result<Self, OrthoError> {
        todo!("{family:?}")
    }
    pub fn matrix(&self, _points: &[f64]) -> Result<DMatrix<f64>, OrthoError> {
        todo!()
    }
}

pub fn gauss_legendre(_n: usize, _a: f64, _b: f64) -> Result<(Vec<f64>, Vec<f64>), OrthoError> {
    todo!()
}
pub fn gauss_hermite_prob(_n: usize) -> Result<(Vec<f64>, Vec<f64>), OrthoError> {
    todo!()
}
