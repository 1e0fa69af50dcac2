//! Integration tests for `seqnet` (one binary; modules under tests/lib/).

#[path = "lib/errors.rs"]
mod errors;
#[path = "lib/gradients.rs"]
mod gradients;
#[path = "lib/learning.rs"]
mod learning;
#[path = "lib/persistence.rs"]
mod persistence;
#[path = "lib/strategies.rs"]
mod strategies;
#[path = "lib/torch.rs"]
mod torch;
