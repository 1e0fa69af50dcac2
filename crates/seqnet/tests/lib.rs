//! Integration tests for `seqnet` (one binary; modules under tests/lib/).

#[path = "lib/config.rs"]
mod config;
#[path = "lib/errors.rs"]
mod errors;
#[path = "lib/gradients.rs"]
mod gradients;
#[path = "lib/learning.rs"]
mod learning;
#[path = "lib/persistence.rs"]
mod persistence;
#[path = "lib/reproducibility.rs"]
mod reproducibility;
#[path = "lib/strategies.rs"]
mod strategies;
#[path = "lib/torch.rs"]
mod torch;
