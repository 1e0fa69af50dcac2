//! Validated hyper-parameters (linfa style) and `fit`.

use crate::error::SeqError;
use crate::float::Precision;
use crate::model::LstmRegressor;
use crate::net::LstmShape;
use crate::optim::{LrSchedule, Optimizer};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Hyper-parameters of an LSTM regressor; chain the setters, then call [`LstmParams::fit`].
///
/// Defaults: 1 layer of 64 hidden units, `steps = 1` (all inputs in one step), 20 epochs,
/// batch 256, Adam with learning rate 1e-3 and a constant schedule, 10 % validation split,
/// early-stopping patience 10, no clipping, f32 kernels, seed 0, 1 thread, progress bar on.
///
/// ```
/// use seqnet::{LstmParams, Optimizer, Precision};
/// let p = LstmParams::new(10, 12).hidden(32).layers(2).steps(10).epochs(5)
///     .optimizer(Optimizer::adam()).precision(Precision::F64).seed(3);
/// assert_eq!(p.shape().unwrap().n_features, 1);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LstmParams {
    n_inputs: usize,
    n_outputs: usize,
    hidden: usize,
    layers: usize,
    steps: usize,
    epochs: usize,
    batch_size: usize,
    learning_rate: f64,
    optimizer: Optimizer,
    schedule: LrSchedule,
    validation_fraction: f64,
    patience: usize,
    clip_norm: Option<f64>,
    precision: Precision,
    seed: u64,
    threads: usize,
    progress: bool,
}

impl LstmParams {
    /// Defaults (see the type docs) for `n_inputs` features in and `n_outputs` targets out.
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(10, 12);
    /// assert_eq!(p.get_batch_size(), 256);
    /// ```
    pub fn new(n_inputs: usize, n_outputs: usize) -> Self {
        Self {
            n_inputs,
            n_outputs,
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
            seed: 0,
            threads: 1,
            progress: true,
        }
    }

    /// Hidden units per layer.
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(2, 1).hidden(8).shape().unwrap().hidden, 8);
    /// ```
    pub fn hidden(mut self, h: usize) -> Self {
        self.hidden = h;
        self
    }

    /// Number of stacked LSTM layers.
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(2, 1).layers(3).shape().unwrap().layers, 3);
    /// ```
    pub fn layers(mut self, l: usize) -> Self {
        self.layers = l;
        self
    }

    /// Sequence length: each sample's inputs are fed as `s` steps of `n_inputs / s` consecutive
    /// values (`s = n_inputs`: a sequence of scalars; `s = 1`: one step of all features).
    /// `n_inputs % s == 0` is checked by `fit`.
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(10, 1).steps(5).shape().unwrap().n_features, 2);
    /// assert!(seqnet::LstmParams::new(10, 1).steps(3).shape().is_err());
    /// ```
    pub fn steps(mut self, s: usize) -> Self {
        self.steps = s;
        self
    }

    /// Maximum number of passes over the training split.
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).epochs(3);
    /// # let _ = p;
    /// ```
    pub fn epochs(mut self, e: usize) -> Self {
        self.epochs = e;
        self
    }

    /// Mini-batch size (the last batch of an epoch may be smaller).
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(2, 1).batch_size(32).get_batch_size(), 32);
    /// ```
    pub fn batch_size(mut self, b: usize) -> Self {
        self.batch_size = b;
        self
    }

    /// Base learning rate (before the schedule).
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).learning_rate(3e-3);
    /// # let _ = p;
    /// ```
    pub fn learning_rate(mut self, lr: f64) -> Self {
        self.learning_rate = lr;
        self
    }

    /// Update rule (Adam or SGD).
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).optimizer(seqnet::Optimizer::sgd(0.9));
    /// # let _ = p;
    /// ```
    pub fn optimizer(mut self, o: Optimizer) -> Self {
        self.optimizer = o;
        self
    }

    /// Learning-rate schedule.
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).schedule(seqnet::LrSchedule::Cosine { min_factor: 0.05 });
    /// # let _ = p;
    /// ```
    pub fn schedule(mut self, s: LrSchedule) -> Self {
        self.schedule = s;
        self
    }

    /// Fraction of samples held out (seeded shuffle) for validation, early stopping and the
    /// plateau schedule; in `[0, 1)`. With 0 the training loss is monitored instead.
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).validation_fraction(0.2);
    /// # let _ = p;
    /// ```
    pub fn validation_fraction(mut self, f: f64) -> Self {
        self.validation_fraction = f;
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
        self.patience = p;
        self
    }

    /// Rescale each mini-batch gradient to Euclidean norm at most `c` (global-norm clipping).
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).clip_norm(1.0);
    /// # let _ = p;
    /// ```
    pub fn clip_norm(mut self, c: f64) -> Self {
        self.clip_norm = Some(c);
        self
    }

    /// Kernel and weight precision.
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).precision(seqnet::Precision::F64);
    /// # let _ = p;
    /// ```
    pub fn precision(mut self, p: Precision) -> Self {
        self.precision = p;
        self
    }

    /// Seed of the initial weights, the validation split and the per-epoch shuffles.
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).seed(42);
    /// # let _ = p;
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
    /// let p = seqnet::LstmParams::new(2, 1).threads(2);
    /// # let _ = p;
    /// ```
    pub fn threads(mut self, t: usize) -> Self {
        self.threads = t;
        self
    }

    /// Show an indicatif progress bar with the per-epoch losses. It is drawn only when stderr is
    /// a terminal and the `CI` environment variable is not `true`.
    ///
    /// ```
    /// let p = seqnet::LstmParams::new(2, 1).progress(false);
    /// # let _ = p;
    /// ```
    pub fn progress(mut self, show: bool) -> Self {
        self.progress = show;
        self
    }

    /// The mini-batch size.
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(2, 1).get_batch_size(), 256);
    /// ```
    pub fn get_batch_size(&self) -> usize {
        self.batch_size
    }

    /// The hidden size and layer count, `(hidden, layers)`.
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(2, 1).get_architecture(), (64, 1));
    /// ```
    pub fn get_architecture(&self) -> (usize, usize) {
        (self.hidden, self.layers)
    }

    /// The maximum number of epochs.
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(2, 1).get_epochs(), 20);
    /// ```
    pub fn get_epochs(&self) -> usize {
        self.epochs
    }

    /// The seed.
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(2, 1).seed(9).get_seed(), 9);
    /// ```
    pub fn get_seed(&self) -> u64 {
        self.seed
    }

    /// The network shape these parameters describe (validates sizes and `n_inputs % steps`).
    ///
    /// ```
    /// let s = seqnet::LstmParams::new(10, 12).steps(10).shape().unwrap();
    /// assert_eq!((s.steps, s.n_features, s.n_outputs), (10, 1, 12));
    /// ```
    pub fn shape(&self) -> Result<LstmShape, SeqError> {
        if self.steps == 0 || !self.n_inputs.is_multiple_of(self.steps) {
            return Err(SeqError::InvalidParameter {
                name: "steps",
                reason: format!(
                    "must be a positive divisor of n_inputs = {}, got {}",
                    self.n_inputs, self.steps
                ),
            });
        }
        if self.n_inputs == 0 {
            return Err(SeqError::InvalidParameter {
                name: "n_inputs",
                reason: "must be at least 1".into(),
            });
        }
        LstmShape::new(
            self.n_inputs / self.steps,
            self.steps,
            self.hidden,
            self.layers,
            self.n_outputs,
        )
    }

    /// Checks every hyper-parameter; `fit` calls this first.
    ///
    /// ```
    /// assert!(seqnet::LstmParams::new(2, 1).learning_rate(-1.0).validate().is_err());
    /// assert!(seqnet::LstmParams::new(2, 1).validate().is_ok());
    /// ```
    pub fn validate(&self) -> Result<LstmShape, SeqError> {
        let shape = self.shape()?;
        let bad = |name: &'static str, reason: &str| {
            Err(SeqError::InvalidParameter {
                name,
                reason: reason.into(),
            })
        };
        if self.epochs == 0 {
            return bad("epochs", "must be at least 1");
        }
        if self.batch_size == 0 {
            return bad("batch_size", "must be at least 1");
        }
        if !(self.learning_rate > 0.0 && self.learning_rate.is_finite()) {
            return bad("learning_rate", "must be positive and finite");
        }
        if !(0.0..1.0).contains(&self.validation_fraction) {
            return bad("validation_fraction", "must be in [0, 1)");
        }
        if let Some(c) = self.clip_norm
            && !(c > 0.0 && c.is_finite())
        {
            return bad("clip_norm", "must be positive and finite");
        }
        if self.threads == 0 {
            return bad("threads", "must be at least 1");
        }
        if let Err(reason) = self.optimizer.validate() {
            return bad("optimizer", &reason);
        }
        if let Err(reason) = self.schedule.validate() {
            return bad("schedule", &reason);
        }
        Ok(shape)
    }

    /// Trains a regressor on `x` (rows = samples, `n_inputs` columns) and `y` (`n_outputs`
    /// columns). Inputs and outputs are standardised with statistics of the whole `x`, `y` (stored
    /// with the model); the validation split is drawn with the seed.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(64, 2, |r, c| ((r * 7 + c * 3) % 11) as f64 / 11.0);
    /// let y = DMatrix::from_fn(64, 1, |r, _| x[(r, 0)] - x[(r, 1)]);
    /// let model = seqnet::LstmParams::new(2, 1).hidden(4).epochs(2).batch_size(16)
    ///     .progress(false).fit(&x, &y).unwrap();
    /// assert_eq!(model.history().train_loss.len(), 2);
    /// ```
    pub fn fit(&self, x: &DMatrix<f64>, y: &DMatrix<f64>) -> Result<LstmRegressor, SeqError> {
        let shape = self.validate()?;
        check_matrix("x", x, None, self.n_inputs)?;
        check_matrix("y", y, Some(x.nrows()), self.n_outputs)?;
        crate::train::fit(self, shape, x, y)
    }

    pub(crate) fn get_learning_rate(&self) -> f64 {
        self.learning_rate
    }
    pub(crate) fn get_optimizer(&self) -> Optimizer {
        self.optimizer
    }
    pub(crate) fn get_schedule(&self) -> LrSchedule {
        self.schedule
    }
    pub(crate) fn get_validation_fraction(&self) -> f64 {
        self.validation_fraction
    }
    pub(crate) fn get_patience(&self) -> usize {
        self.patience
    }
    pub(crate) fn get_clip_norm(&self) -> Option<f64> {
        self.clip_norm
    }
    /// The kernel precision.
    ///
    /// ```
    /// assert_eq!(seqnet::LstmParams::new(2, 1).get_precision(), seqnet::Precision::F32);
    /// ```
    pub fn get_precision(&self) -> Precision {
        self.precision
    }
    pub(crate) fn get_threads(&self) -> usize {
        self.threads
    }
    pub(crate) fn get_progress(&self) -> bool {
        self.progress
    }
}

/// Checks a data matrix's shape and finiteness; errors name the argument, row and column.
pub(crate) fn check_matrix(
    what: &'static str,
    m: &DMatrix<f64>,
    rows: Option<usize>,
    cols: usize,
) -> Result<(), SeqError> {
    if m.ncols() != cols || rows.is_some_and(|r| r != m.nrows()) || m.nrows() == 0 {
        return Err(SeqError::Shape {
            what,
            expected: format!(
                "{} x {cols}",
                rows.map_or("n >= 1".to_string(), |r| r.to_string())
            ),
            found: format!("{} x {}", m.nrows(), m.ncols()),
        });
    }
    for c in 0..m.ncols() {
        for r in 0..m.nrows() {
            let v = m[(r, c)];
            if !v.is_finite() {
                return Err(SeqError::NonFinite {
                    what,
                    row: r,
                    col: c,
                    value: v,
                });
            }
        }
    }
    Ok(())
}
