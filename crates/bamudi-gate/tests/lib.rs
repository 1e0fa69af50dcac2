//! Tests of the gate application: the `bamudi` binary (bad input, the simulate → calibrate →
//! predict → close-loop round trip) and the close loop on simulated field records (the
//! gate-like test model, and the finite-element gate with the BA-MUDI calibrator), and the quick
//! coverage study of the default calibration mode, and the adequacy verdict on realities that
//! differ from the gate.

mod adequacy;
mod cli;
mod closeloop;
mod coverage;
mod fatigue;
