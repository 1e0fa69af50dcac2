//! `bamudi`: BA-MUDI orchestrator: modules 1-4 of Bayesian calibration of multi-level models with unobservable distributed response, and its CLI.
