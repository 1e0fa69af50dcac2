//! Integration tests for the `gp` crate (one test binary; modules under `tests/lib/`).

#[path = "lib/strategies.rs"]
mod strategies;

#[path = "lib/gradient.rs"]
mod gradient;

#[path = "lib/prediction.rs"]
mod prediction;

#[path = "lib/fitting.rs"]
mod fitting;

#[path = "lib/errors.rs"]
mod errors;

#[path = "lib/reproducibility.rs"]
mod reproducibility;
