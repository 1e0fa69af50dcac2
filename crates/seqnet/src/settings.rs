//! The LSTM's hyper-parameters as plain data: the one definition that builders, saved models
//! and configuration files (e.g. the calibration engine's `[estimator]` table) share.
//!
//! This module depends on nothing of the training or model code; validation happens once, in
//! [`LstmParams::check`](crate::LstmParams::check).

use crate::float::Precision;
use crate::optim::{LrSchedule, Optimizer};
use serde::{Deserialize, Serialize};

/// Hyper-parameters of an LSTM regressor: architecture, training budget and optimiser. Not
/// included: the data shape (`n_inputs`, `n_outputs`) and the seed, which belong to one fit
/// ([`LstmParams`](crate::LstmParams)).
///
/// Every field has a default ([`LstmSettings::default`]), so a configuration names only what
/// it changes; unknown keys are errors (`deny_unknown_fields`), so a typo is never silently
/// ignored.
///
/// ```
/// let s: seqnet::LstmSettings = serde_json::from_str(r#"{"hidden": 32, "steps": 10}"#).unwrap();
/// assert_eq!((s.hidden, s.steps, s.epochs), (32, 10, 20));
/// assert!(serde_json::from_str::<seqnet::LstmSettings>(r#"{"hiden": 32}"#).is_err());
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LstmSettings {
    /// Hidden units per layer.
    pub hidden: usize,
    /// Number of stacked LSTM layers.
    pub layers: usize,
    /// Sequence length: each sample's `n_inputs` values are fed as `steps` time steps of
    /// `n_inputs / steps` consecutive values (`steps = n_inputs`: a sequence of scalars;
    /// `steps = 1`: one step of all features). Must divide `n_inputs`.
    pub steps: usize,
    /// Maximum number of passes over the training split.
    pub epochs: usize,
    /// Mini-batch size (the last batch of an epoch may be smaller).
    pub batch_size: usize,
    /// Base learning rate (before the schedule).
    pub learning_rate: f64,
    /// Update rule (Adam or SGD).
    pub optimizer: Optimizer,
    /// Learning-rate schedule.
    pub schedule: LrSchedule,
    /// Fraction of samples held out (seeded shuffle) for validation, early stopping and the
    /// plateau schedule; in `[0, 1)`. With 0 the training loss is monitored instead.
    pub validation_fraction: f64,
    /// Stop after this many epochs without improvement of the monitored loss (the best weights
    /// are restored); 0 disables early stopping.
    pub patience: usize,
    /// Rescale each mini-batch gradient to Euclidean norm at most this (global-norm
    /// clipping); `None` disables clipping.
    pub clip_norm: Option<f64>,
    /// Kernel and weight precision.
    pub precision: Precision,
    /// Worker threads: each mini-batch is split into this many contiguous shards whose
    /// gradients are computed in parallel and summed in a fixed order, so results depend on the
    /// seed and the thread count but not on scheduling.
    pub threads: usize,
}

impl Default for LstmSettings {
    /// 1 layer of 64 hidden units, `steps = 1` (all inputs in one step), 20 epochs, batch 256,
    /// Adam with learning rate 1e-3 and a constant schedule, 10 % validation split,
    /// early-stopping patience 10, no clipping, f32 kernels, 1 thread.
    ///
    /// ```
    /// let s = seqnet::LstmSettings::default();
    /// assert_eq!((s.hidden, s.layers, s.batch_size), (64, 1, 256));
    /// ```
    fn default() -> Self {
        Self {
            hidden: 64,
            layers: 1,
            steps: 1,
            epochs: 20,
            batch_size: 256,
            learning_rate: 1e-3,
            optimizer: Optimizer::adam(),
            schedule: LrSchedule::Constant,
            validation_fraction: 0.1,
            patience: 10,
            clip_norm: None,
            precision: Precision::F32,
            threads: 1,
        }
    }
}
