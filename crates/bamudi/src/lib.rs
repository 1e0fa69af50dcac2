//! `bamudi`: Bayesian calibration of multi-level models with an unobservable distributed
//! response (BA-MUDI, paper Modules 2-4), generic over the [`mlmodel`] traits. The engine knows
//! no application: the miter gate of the paper is one user of it (crate `bamudi-gate`). Closing
//! the loop with a measured record (finding and adding the effects a calibrated model misses)
//! is a crate above this one, `bamudi-closeloop`.
//!
//! # Reading order
//!
//! 1. [`params`]: what a user sets ([`CalibrationParams`], TOML or setters), checked once into
//!    an immutable [`CalibrationConfig`].
//! 2. The executor ([`Calibrate`], [`calibrate()`]) runs the stages, times them and reports
//!    them to an [`observe::Observer`]; its result is a [`Calibration`].
//! 3. [`surrogate`] (the paper's Module 2): the training set (Eq. 27), the coefficient
//!    estimator (Eq. 29: exact linear-Gaussian, `smartcore` ridge, or the paper's LSTM from
//!    `seqnet`), `ρ*` (Eq. 30), `α̂` (Eq. 32) and the coefficient GPs (Eq. 33-37).
//! 4. [`posterior`] (Module 3): the posterior of `θ` under the chosen coefficient mode, on a
//!    grid or by Metropolis, with and without a discrepancy, and the two weighed by evidence.
//! 5. [`predict`] (Module 4): the one [`Predictor`] of responses and outputs with bands
//!    (Eq. 44, 52), their moments and joint draws.
//! 6. [`adequacy`]: the verdict on every (marginal-mode) calibration: is the model adequate
//!    for the data, and if not, is it a sensor or the model's form?
//! 7. [`data`]: CSV tables with located errors (`ndarray`), experiments, atomic writes;
//!    [`validation`]: coverage and rank statistics of replicate studies.
//!
//! [`internals`] exposes the building blocks (likelihood, MCMC, training set, estimators) to
//! the workspace's tests and benchmarks; it is not part of the API a user needs.
//!
//! # Example
//!
//! The crate README (`examples/analytic.rs`) calibrates a small analytic two-level model end to
//! end in a twentieth of a second; the doc test of [`calibrate()`] is a smaller one.
//!
//! Known limits: the learnt estimators' own error enters only through the GP white noise, so
//! their `θ` intervals can be over-confident; `ρ` is weakly identified when `θ`'s prior is wide
//! (Eq. 31 smears `g_u`).

pub mod adequacy;
mod calibration;
pub mod data;
mod error;
pub mod internals;
pub mod observe;
mod optim;
pub mod params;
pub mod posterior;
pub mod predict;
pub mod surrogate;
pub mod validation;

/// The README's example, compiled and run as a doc test.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctest;

pub use adequacy::{AdequacyReport, Verdict};
pub use calibration::{Calibrate, Calibration, Timings, calibrate};
pub use data::Experiments;
pub use error::{BamudiError, Result};
pub use params::{
    AdequacyParams, CalibrationConfig, CalibrationParams, CoefficientKernel, CoefficientMode,
    CoefficientScales, DiscrepancyPresence, EstimatorParams, MarginalPrior, Marginalisation,
    McmcConfig, ModeKind, RhoSearch, RidgeParams, SamplingRule,
};
pub use posterior::{SupportPolicy, ThetaPosterior, ThetaSummary};
pub use predict::{Band, DrawPaths, Predictor};
pub use surrogate::Surrogate;
