//! Integration tests of `bamudi-closeloop`: the loop on records made by the test doubles
//! (`closeloop`), and every reader of a user's file fuzzed with mutated documents (`fuzz`).
//! The loop on the finite-element gate is tested in `bamudi-gate`.

mod closeloop;
mod fuzz;
