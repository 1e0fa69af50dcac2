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
//! 2. [`calibration`]: the executor ([`Calibrate`], [`calibrate()`]) that runs the stages,
//!    times them and reports them to an [`observe::Observer`]; its result, [`Calibration`].
//! 3. [`module2`]: training set (Eq. 27), estimator (Eq. 29: exact linear-Gaussian, `smartcore`
//!    ridge, or the paper's LSTM from `seqnet`), `ρ*` (Eq. 30), `α̂` (Eq. 32), coefficient GPs
//!    (Eq. 33-37).
//! 4. [`module3`]: the `θ` posterior with the Eq.-51 covariance, the coefficient mode as a
//!    strategy (the paper's, or conditioned on `θ`), grid quadrature or MCMC.
//! 5. [`module4`]: the one predictor of responses and outputs with bands (Eq. 44, 52).
//! 6. [`data`]: CSV tables with located errors (`ndarray`), experiments, atomic writes.
//! 7. [`adequacy`]: the verdict on every (marginal-mode) calibration: is the model adequate
//!    for the data, and if not, is it a sensor or the model's form?
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
pub mod calibration;
pub mod data;
pub mod error;
pub mod module2;
pub mod module3;
pub mod module4;
pub mod observe;
mod optim;
pub mod params;
pub mod validation;

/// The README's example, compiled and run as a doc test.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctest;

pub use adequacy::{AdequacyReport, Verdict};
pub use calibration::{Calibrate, Calibration, Timings, calibrate};
pub use data::Experiments;
pub use error::{BamudiError, Result};
pub use module3::posterior::{SupportPolicy, ThetaPosterior};
pub use module4::{Band, DrawPaths, Predictor};
pub use params::{
    AdequacyParams, CalibrationConfig, CalibrationParams, CoefficientKernel, CoefficientMode,
    CoefficientScales, DiscrepancyPresence, EstimatorParams, MarginalPrior, Marginalisation,
    McmcConfig, RhoSearch, RidgeParams, SamplingRule,
};
