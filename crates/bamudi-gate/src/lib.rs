//! `bamudi-gate`: the navigation-lock miter gate as a user of the `bamudi` engine.
//!
//! * [`gate`]: the gate's multi-level model for the engine (built through
//!   [`mitergate::build_contact`] and [`mitergate::multilevel`], the one place the gate is
//!   assembled), the saved model file, and the gate's record layout for the close loop;
//! * [`paper`]: the paper's case study (`cargo xtask reproduce-paper`): both scenarios of
//!   Table 1 on the default gate, scored against the synthetic truth;
//! * [`calibrator`]: BA-MUDI on the gate as the close loop's [`bamudi_closeloop::Calibrator`];
//! * [`report`]: `results.json`, `report.md` and SVG plots of a calibration and of a close-loop
//!   run;
//! * [`output`]: results directories written atomically (staging directory, then rename);
//! * [`session`]: what the command line and the Python package share (the calibration
//!   specification, experiments from a table, the calibration, synthetic experiments);
//! * [`progress`]: the engine's observer events as indicatif progress bars, and a stderr logger
//!   for the `log` facade;
//! * the `bamudi` command line (`src/main.rs`, see `docs/cli.md`).
//!
//! Units: inches, lbf, lbf/in, psi, microstrain.

/// The crate README's example, compiled and run as a doc test.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctest;

pub mod baselines;
pub mod calibrator;
pub mod coverage;
pub mod error;
pub mod gate;
pub mod output;
pub mod paper;
pub mod physics;
pub mod progress;
pub mod record_fatigue;
pub mod report;
pub mod session;
pub mod tolerance;

pub use error::{GateAppError, Result};
