//! `numerics`: the few numerical kernels that several bamudi crates need, written once.
//!
//! | module | what | used by |
//! |---|---|---|
//! | [`cholesky`] | Cholesky factorisation with a documented diagonal-jitter ladder, in place (faer) and owned (nalgebra in, nalgebra out) | `gp` (training covariance), `bamudi` (the Eq.-51 covariance of Module 3) |
//! | [`standardize`] | per-column affine standardisation `z = (v − mean) / sd` | `seqnet` (LSTM inputs and outputs), `bamudi` (ridge estimator), `bamudi-closeloop` (features) |
//! | [`random`] | seeded standard-normal draws (Box-Muller) and per-index seed derivation | `mlmodel` (prior draws), `bamudi` (training sets, MCMC) |
//! | [`robust`] | median and the first-difference noise scale | `bamudi` (gauge-noise estimate), `bamudi-closeloop` (residual checks) |
//! | [`changepoint`] | changes in the mean of a serially correlated series: PELT with the modified BIC, location intervals (Bai 1997) and sizes | `bamudi-closeloop` (the whole-record event scan) |
//! | [`stats`] | sample autocorrelations, the Ljung-Box test, the chi-square survival function | `bamudi` (adequacy checks), `bamudi-closeloop` (residual checks) |
//! | [`rainflow`] | online rainflow cycle counting (ASTM E1049) | `bamudi-gate` (quoin-block fatigue over a record) |
//!
//! Distributions (normal, chi-square, Student t, binomial) come from `statrs`, not from here.
//!
//! The public matrices of this crate are `nalgebra` matrices, except the in-place kernel
//! [`cholesky::cholesky_in_place`], which works on `faer` views with caller-owned scratch (the
//! faer pattern: an owned convenience API over an in-place kernel); it is the only place where
//! `faer` types cross a crate boundary in the workspace.

/// The crate README's example, compiled and run as a doc test.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctest;

pub mod changepoint;
pub mod cholesky;
pub mod eigen;
mod error;
pub mod rainflow;
pub mod random;
pub mod robust;
pub mod standardize;
pub mod stats;

pub use cholesky::{Cholesky, JITTER_LADDER};
pub use eigen::SymmetricEigen;
pub use error::NumericsError;
pub use standardize::Standardizer;
