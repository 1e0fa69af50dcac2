//! Integration tests of `orthopoly` (one test binary; modules live in `tests/suite/`).
mod suite;
