//! The engine's building blocks, for the workspace's own tests and benchmarks: the pieces of
//! Modules 2-3 that a test checks against a brute-force computation one by one (the training
//! set, the estimators, the Eq.-51 likelihood, the grid and the Metropolis sampler). A user
//! calibrates through [`crate::Calibrate`] and never needs these; their signatures may change
//! with the engine's internals.

pub use crate::posterior::evaluate::{ThetaLikelihood, ThetaResiduals};
pub use crate::posterior::grid::LogPosteriors;
pub use crate::posterior::likelihood::{FactoredCovariance, assemble_covariance, iid_log_density};
pub use crate::posterior::marginal::{CoefficientPrior, LowRank, Spectrum, orthonormalised};
pub use crate::posterior::mcmc::{adaptive_metropolis, effective_sample_size, split_rhat};
pub use crate::surrogate::estimator::ExactLinearEstimator;
pub use crate::surrogate::problem::Problem;
pub use crate::surrogate::training::{
    LinearParts, TrainingSpec, XContext, generate_general, generate_linear, theta_rule,
};
