//! The linfa-style parameter pipeline: [`LstmParams`] (a builder, unchecked) →
//! [`LstmParams::check`] → [`CheckedLstmParams`] (validated, immutable) → `fit` (in the
//! training module).

use crate::error::SeqError;
use crate::float::Precision;
use crate::net::LstmShape;
use crate::optim::{LrSchedule, Optimizer};
use crate::settings::LstmSettings;
use serde::{Deserialize, Serialize};

/// Parameters of one LSTM fit: the data shape, the hyper-parameters ([`LstmSettings`]) and the
/// seed. Chain the setters, then [`check`](Self::check) them (or call
/// [`fit`](Self::fit), which checks first).
///
/// Defaults: [`LstmSettings::default`] and seed 0.
///
/// ```
/// use seqnet::{LstmParams, Optimizer, Precision};
/// let p = LstmParams::new(10, 12).hidden(32).layers(2).steps(10).epochs(5)
///     .optimizer(Optimizer::adam()).precision(Precision::F64).seed(3)
///     .check()
///     .unwrap();
/// assert_eq!(p.shape().n_features, 1);
/// ```
///
/// Serialised flat: `n_inputs`, `n_outputs`, every [`LstmSettings`] field, `seed`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LstmParams {
    n_inputs: usize,
    n_outputs: usize,
    #[serde(flatten)]
    settings: LstmSettings,
    seed: u64,
}

impl LstmParams {
    /// Defaults (see the type docs) for `n_inputs` features in and `n_outputs` targets out.
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(10, 12).check().unwrap();
    /// assert_eq!(p.settings(), &seqnet::LstmSettings::default());
    /// ```
    pub fn new(n_inputs: usize, n_outputs: usize) -> Self {
        Self {
            n_inputs,
            n_outputs,
            settings: LstmSettings::default(),
            seed: 0,
        }
    }

    /// Replaces every hyper-parameter at once (e.g. settings read from a configuration file);
    /// the data shape and the seed are kept.
    ///
    /// ```
    /// let s = seqnet::LstmSettings { hidden: 8, steps: 2, ..Default::default() };
    /// let p = seqnet::LstmParams::new(4, 1).seed(5).settings(s.clone()).check().unwrap();
    /// assert_eq!((p.settings(), p.seed()), (&s, 5));
    /// ```
    pub fn settings(mut self, settings: LstmSettings) -> Self {
        self.settings = settings;
        self
    }

    /// Hidden units per layer.
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(2, 1).hidden(8).check().unwrap().shape().hidden, 8);
    /// ```
    pub fn hidden(mut self, h: usize) -> Self {
        self.settings.hidden = h;
        self
    }

    /// Number of stacked LSTM layers.
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(2, 1).layers(3).check().unwrap().shape().layers, 3);
    /// ```
    pub fn layers(mut self, l: usize) -> Self {
        self.settings.layers = l;
        self
    }

    /// Sequence length: each sample's inputs are fed as `s` steps of `n_inputs / s` consecutive
    /// values (`s = n_inputs`: a sequence of scalars; `s = 1`: one step of all features).
    /// `n_inputs % s == 0` is checked by [`check`](Self::check).
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(10, 1).steps(5).check().unwrap().shape().n_features, 2);
    /// assert!(seqnet::LstmParams::new(10, 1).steps(3).check().is_err());
    /// ```
    pub fn steps(mut self, s: usize) -> Self {
        self.settings.steps = s;
        self
    }

    /// Maximum number of passes over the training split.
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(2, 1).epochs(3).check().unwrap().settings().epochs, 3);
    /// ```
    pub fn epochs(mut self, e: usize) -> Self {
        self.settings.epochs = e;
        self
    }

    /// Mini-batch size (the last batch of an epoch may be smaller).
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).batch_size(32).check().unwrap();
    /// assert_eq!(p.settings().batch_size, 32);
    /// ```
    pub fn batch_size(mut self, b: usize) -> Self {
        self.settings.batch_size = b;
        self
    }

    /// Base learning rate (before the schedule).
    ///
    /// ```
    /// assert!(seqnet::LstmParams::new(2, 1).learning_rate(-1.0).check().is_err());
    /// ```
    pub fn learning_rate(mut self, lr: f64) -> Self {
        self.settings.learning_rate = lr;
        self
    }

    /// Update rule (Adam or SGD).
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).optimizer(seqnet::Optimizer::sgd(0.9));
    /// # let _ = p;
    /// ```
    pub fn optimizer(mut self, o: Optimizer) -> Self {
        self.settings.optimizer = o;
        self
    }

    /// Learning-rate schedule.
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).schedule(seqnet::LrSchedule::Cosine { min_factor: 0.05 });
    /// # let _ = p;
    /// ```
    pub fn schedule(mut self, s: LrSchedule) -> Self {
        self.settings.schedule = s;
        self
    }

    /// Fraction of samples held out (seeded shuffle) for validation, early stopping and the
    /// plateau schedule; in `[0, 1)`. With 0 the training loss is monitored instead.
    ///
    /// ```
    /// assert!(seqnet::LstmParams::new(2, 1).validation_fraction(1.0).check().is_err());
    /// ```
    pub fn validation_fraction(mut self, f: f64) -> Self {
        self.settings.validation_fraction = f;
        self
    }

    /// Stop after `p` epochs without improvement of the monitored loss; the best weights are
    /// restored. `0` disables early stopping.
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).patience(5);
    /// # let _ = p;
    /// ```
    pub fn patience(mut self, p: usize) -> Self {
        self.settings.patience = p;
        self
    }

    /// Rescale each mini-batch gradient to Euclidean norm at most `c` (global-norm clipping).
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).clip_norm(1.0).check().unwrap();
    /// assert_eq!(p.settings().clip_norm, Some(1.0));
    /// ```
    pub fn clip_norm(mut self, c: f64) -> Self {
        self.settings.clip_norm = Some(c);
        self
    }

    /// Kernel and weight precision.
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).precision(seqnet::Precision::F64);
    /// # let _ = p;
    /// ```
    pub fn precision(mut self, p: Precision) -> Self {
        self.settings.precision = p;
        self
    }

    /// Seed of the initial weights, the validation split and the per-epoch shuffles.
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(2, 1).seed(42).check().unwrap().seed(), 42);
    /// ```
    pub fn seed(mut self, s: u64) -> Self {
        self.seed = s;
        self
    }

    /// Worker threads: each mini-batch is split into this many contiguous shards whose gradients
    /// are computed in parallel and summed in a fixed order, so results depend on the seed and
    /// the thread count but not on scheduling.
    ///
    /// ```
    /// assert!(seqnet::LstmParams::new(2, 1).threads(0).check().is_err());
    /// ```
    pub fn threads(mut self, t: usize) -> Self {
        self.settings.threads = t;
        self
    }

    /// Validates every hyper-parameter against the data shape, once; the result cannot be
    /// changed afterwards. Errors name the offending parameter
    /// ([`SeqError::InvalidParameter`]).
    ///
    /// ```
    /// let err = seqnet::LstmParams::new(2, 1).batch_size(0).check().unwrap_err();
    /// assert!(matches!(err, seqnet::SeqError::InvalidParameter { name: "batch_size", .. }));
    /// ```
    pub fn check(self) -> Result<CheckedLstmParams, SeqError> {
        let shape = validate(self.n_inputs, self.n_outputs, &self.settings)?;
        Ok(CheckedLstmParams {
            params: self,
            shape,
        })
    }
}

/// Validated [`LstmParams`] (from [`LstmParams::check`]): read-only, ready to
/// [`fit`](Self::fit). Deserialising validates again, so a loaded value is as trustworthy as a
/// checked one.
///
/// ```
/// let p = seqnet::LstmParams::new(6, 2).steps(3).hidden(8).seed(1).check().unwrap();
/// assert_eq!((p.n_inputs(), p.n_outputs(), p.seed()), (6, 2, 1));
/// assert_eq!((p.shape().steps, p.shape().n_features), (3, 2));
/// // back to a builder to change something (checked again before use)
/// let more: seqnet::LstmParams = p.into();
/// assert!(more.hidden(16).check().is_ok());
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "LstmParams", into = "LstmParams")]
pub struct CheckedLstmParams {
    params: LstmParams,
    shape: LstmShape,
}

impl CheckedLstmParams {
    /// Number of input columns.
    pub fn n_inputs(&self) -> usize {
        self.params.n_inputs
    }

    /// Number of output columns.
    pub fn n_outputs(&self) -> usize {
        self.params.n_outputs
    }

    /// The hyper-parameters.
    pub fn settings(&self) -> &LstmSettings {
        &self.params.settings
    }

    /// The seed of the initial weights, the validation split and the shuffles.
    pub fn seed(&self) -> u64 {
        self.params.seed
    }

    /// The network shape (`n_features = n_inputs / steps`).
    pub fn shape(&self) -> LstmShape {
        self.shape
    }
}

impl From<CheckedLstmParams> for LstmParams {
    fn from(c: CheckedLstmParams) -> Self {
        c.params
    }
}

impl TryFrom<LstmParams> for CheckedLstmParams {
    type Error = SeqError;
    fn try_from(p: LstmParams) -> Result<Self, SeqError> {
        p.check()
    }
}

/// The network shape `settings` describe for `n_inputs` → `n_outputs` (sizes positive,
/// `n_inputs % steps == 0`).
fn shape_of(
    n_inputs: usize,
    n_outputs: usize,
    settings: &LstmSettings,
) -> Result<LstmShape, SeqError> {
    let steps = settings.steps;
    if steps == 0 || !n_inputs.is_multiple_of(steps) {
        return Err(SeqError::InvalidParameter {
            name: "steps",
            reason: format!("must be a positive divisor of n_inputs = {n_inputs}, got {steps}"),
        });
    }
    if n_inputs == 0 {
        return Err(SeqError::InvalidParameter {
            name: "n_inputs",
            reason: "must be at least 1".into(),
        });
    }
    LstmShape::new(
        n_inputs / steps,
        steps,
        settings.hidden,
        settings.layers,
        n_outputs,
    )
}

/// Checks every hyper-parameter (shape first); returns the network shape.
fn validate(n_inputs: usize, n_outputs: usize, s: &LstmSettings) -> Result<LstmShape, SeqError> {
    let shape = shape_of(n_inputs, n_outputs, s)?;
    let bad = |name: &'static str, reason: &str| {
        Err(SeqError::InvalidParameter {
            name,
            reason: reason.into(),
        })
    };
    if s.epochs == 0 {
        return bad("epochs", "must be at least 1");
    }
    if s.batch_size == 0 {
        return bad("batch_size", "must be at least 1");
    }
    if !(s.learning_rate > 0.0 && s.learning_rate.is_finite()) {
        return bad("learning_rate", "must be positive and finite");
    }
    if !(0.0..1.0).contains(&s.validation_fraction) {
        return bad("validation_fraction", "must be in [0, 1)");
    }
    if let Some(c) = s.clip_norm
        && !(c > 0.0 && c.is_finite())
    {
        return bad("clip_norm", "must be positive and finite");
    }
    if s.threads == 0 {
        return bad("threads", "must be at least 1");
    }
    if let Err(reason) = s.optimizer.validate() {
        return bad("optimizer", &reason);
    }
    if let Err(reason) = s.schedule.validate() {
        return bad("schedule", &reason);
    }
    Ok(shape)
}
