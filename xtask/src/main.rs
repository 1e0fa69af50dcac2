//! Developer tasks for the bamudi workspace.
fn main() {}
