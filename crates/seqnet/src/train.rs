//! Fitting: checked parameters and data in, a trained [`LstmRegressor`] out (the mini-batch
//! training loop).

use crate::data::{check_matrix, select_rows, shuffle, split_indices, to_row_major};
use crate::error::SeqError;
use crate::float::{Float, Precision};
use crate::model::{LstmRegressor, TrainingHistory, Weights};
use crate::net::{Network, Workspace};
use crate::observe::{EpochReport, NoObserver, TrainObserver};
use crate::optim::{LrTracker, OptimizerState, clip_by_norm, l2_norm};
use crate::params::{CheckedLstmParams, LstmParams};
use crate::settings::LstmSettings;
use nalgebra::DMatrix;
use numerics::Standardizer;
use rand::{SeedableRng, rngs::StdRng};
use std::time::Instant;

impl LstmParams {
    /// Checks the parameters ([`LstmParams::check`]), then trains
    /// ([`CheckedLstmParams::fit`]).
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(64, 2, |r, c| ((r * 7 + c * 3) % 11) as f64 / 11.0);
    /// let y = DMatrix::from_fn(64, 1, |r, _| x[(r, 0)] - x[(r, 1)]);
    /// let model = seqnet::LstmParams::new(2, 1).hidden(4).epochs(2).batch_size(16)
    ///     .fit(&x, &y).unwrap();
    /// assert_eq!(model.history().train_loss.len(), 2);
    /// ```
    pub fn fit(&self, x: &DMatrix<f64>, y: &DMatrix<f64>) -> Result<LstmRegressor, SeqError> {
        self.clone().check()?.fit(x, y)
    }
}

impl CheckedLstmParams {
    /// Trains a regressor on `x` (rows = samples, `n_inputs` columns) and `y` (`n_outputs`
    /// columns). The validation split is drawn with the seed; inputs and outputs are
    /// standardised with statistics of the training split (stored with the model).
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(64, 2, |r, c| ((r * 7 + c * 3) % 11) as f64 / 11.0);
    /// let y = DMatrix::from_fn(64, 1, |r, _| x[(r, 0)] - x[(r, 1)]);
    /// let params = seqnet::LstmParams::new(2, 1).hidden(4).epochs(2).batch_size(16).check()?;
    /// let model = params.fit(&x, &y)?;
    /// assert_eq!(model.history().train_loss.len(), 2);
    /// # Ok::<(), seqnet::SeqError>(())
    /// ```
    pub fn fit(&self, x: &DMatrix<f64>, y: &DMatrix<f64>) -> Result<LstmRegressor, SeqError> {
        self.fit_observed(x, y, &mut NoObserver)
    }

    /// Like [`fit`](Self::fit), reporting every finished epoch to `observer` (see
    /// [`TrainObserver`]); the numbers do not depend on the observer.
    pub fn fit_observed(
        &self,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
        observer: &mut dyn TrainObserver,
    ) -> Result<LstmRegressor, SeqError> {
        check_matrix("x", x, None, self.n_inputs())?;
        check_matrix("y", y, Some(x.nrows()), self.n_outputs())?;
        let (tr, va) = split_indices(x.nrows(), self.settings().validation_fraction, self.seed())?;
        let (x_tr, y_tr) = (select_rows(x, &tr), select_rows(y, &tr));
        let (x_va, y_va) = (select_rows(x, &va), select_rows(y, &va));
        let xs = Standardizer::fit(&x_tr);
        let ys = Standardizer::fit(&y_tr);
        let data = RawSplits {
            xs: &xs,
            ys: &ys,
            train: (&x_tr, &y_tr),
            valid: (&x_va, &y_va),
        };
        let (weights, history) = match self.settings().precision {
            Precision::F32 => {
                let (net, h) = train_typed::<f32>(self, &data, observer)?;
                (Weights::F32(net), h)
            }
            Precision::F64 => {
                let (net, h) = train_typed::<f64>(self, &data, observer)?;
                (Weights::F64(net), h)
            }
        };
        Ok(LstmRegressor::from_parts(
            self.clone(),
            weights,
            xs,
            ys,
            history,
        ))
    }
}

/// The training and validation splits in data units, with the scalers fitted on the training
/// split.
struct RawSplits<'a> {
    xs: &'a Standardizer,
    ys: &'a Standardizer,
    train: (&'a DMatrix<f64>, &'a DMatrix<f64>),
    valid: (&'a DMatrix<f64>, &'a DMatrix<f64>),
}

/// Row-major standardised data of one split.
struct Split<T> {
    x: Vec<T>,
    y: Vec<T>,
    n: usize,
}

impl<T: Float> Split<T> {
    fn new(xs: &Standardizer, ys: &Standardizer, x: &DMatrix<f64>, y: &DMatrix<f64>) -> Self {
        Self {
            x: to_row_major(xs, x),
            y: to_row_major(ys, y),
            n: x.nrows(),
        }
    }
}

/// Per-thread state for one shard of a mini-batch.
struct Shard<T: Float> {
    ws: Workspace<T>,
    grad: Vec<T>,
    x: Vec<T>,
    y: Vec<T>,
    sse: f64,
}

impl<T: Float> Shard<T> {
    fn new(n_params: usize) -> Self {
        Self {
            ws: Workspace::new(),
            grad: vec![T::of(0.0); n_params],
            x: Vec::new(),
            y: Vec::new(),
            sse: 0.0,
        }
    }
}

/// The best epoch so far (lowest monitored loss) and its weights, for early stopping.
struct Best<T> {
    loss: f64,
    epoch: usize,
    params: Vec<T>,
    /// Epochs since the last improvement.
    since: usize,
}

impl<T: Float> Best<T> {
    fn new(params: &[T]) -> Self {
        Self {
            loss: f64::INFINITY,
            epoch: 0,
            params: params.to_vec(),
            since: 0,
        }
    }

    /// Records epoch `epoch` with monitored loss `loss` and the network's current weights.
    fn update(&mut self, epoch: usize, loss: f64, params: &[T]) {
        if loss < self.loss {
            self.loss = loss;
            self.epoch = epoch;
            self.params.copy_from_slice(params);
            self.since = 0;
        } else {
            self.since += 1;
        }
    }
}

/// Network, optimiser and per-thread buffers of one training run.
struct Trainer<'p, T: Float> {
    settings: &'p LstmSettings,
    net: Network<T>,
    opt: OptimizerState,
    lr: LrTracker,
    /// The per-epoch shuffles' stream.
    rng: StdRng,
    shards: Vec<Shard<T>>,
    /// The mini-batch gradient (sum over shards).
    grad: Vec<T>,
    /// Worker threads when `threads > 1`.
    pool: Option<rayon::ThreadPool>,
}

fn train_typed<T: Float>(
    p: &CheckedLstmParams,
    data: &RawSplits<'_>,
    observer: &mut dyn TrainObserver,
) -> Result<(Network<T>, TrainingHistory), SeqError> {
    let start = Instant::now();
    let tr = Split::<T>::new(data.xs, data.ys, data.train.0, data.train.1);
    let va = Split::<T>::new(data.xs, data.ys, data.valid.0, data.valid.1);
    let s = p.settings();
    let mut trainer = Trainer::<T>::new(p)?;
    let mut order: Vec<usize> = (0..tr.n).collect();
    let mut hist = TrainingHistory::default();
    let mut best = Best::new(trainer.net.params());
    for epoch in 0..s.epochs {
        let t0 = Instant::now();
        let rate = trainer.lr.rate(epoch);
        shuffle(&mut order, &mut trainer.rng);
        let train_loss = trainer.epoch(epoch, &order, &tr, rate)?;
        let val_loss = trainer.validation_loss(epoch, &va)?;
        let monitored = val_loss.unwrap_or(train_loss);
        trainer.lr.observe(monitored);
        let seconds = t0.elapsed().as_secs_f64();
        hist.train_loss.push(train_loss);
        hist.val_loss.extend(val_loss);
        hist.learning_rate.push(rate);
        hist.epoch_seconds.push(seconds);
        best.update(epoch, monitored, trainer.net.params());
        observer.epoch(&EpochReport {
            epoch,
            epochs: s.epochs,
            train_loss,
            val_loss,
            learning_rate: rate,
            best_epoch: best.epoch,
            best_loss: best.loss,
            seconds,
        });
        if s.patience > 0 && best.since >= s.patience {
            hist.stopped_early = true;
            break;
        }
    }
    let mut net = trainer.net;
    net.params_mut().copy_from_slice(&best.params);
    hist.best_epoch = best.epoch;
    hist.best_loss = best.loss;
    hist.train_samples = tr.n;
    hist.validation_samples = va.n;
    hist.wall_seconds = start.elapsed().as_secs_f64();
    Ok((net, hist))
}

impl<'p, T: Float> Trainer<'p, T> {
    /// Initial weights, optimiser state and buffers; the shuffle stream is seeded apart from
    /// the initialisation and the validation split.
    fn new(p: &'p CheckedLstmParams) -> Result<Self, SeqError> {
        let (s, shape) = (p.settings(), p.shape());
        Ok(Self {
            settings: s,
            net: Network::<T>::init(shape, p.seed()),
            opt: OptimizerState::new(s.optimizer, shape.n_params()),
            lr: LrTracker::new(s.schedule, s.learning_rate, s.epochs),
            rng: StdRng::seed_from_u64(p.seed().wrapping_add(0x9E37_79B9_7F4A_7C15)),
            shards: (0..s.threads)
                .map(|_| Shard::new(shape.n_params()))
                .collect(),
            grad: vec![T::of(0.0); shape.n_params()],
            pool: thread_pool(s.threads)?,
        })
    }

    /// One pass over the training rows in `order`, one optimiser step per mini-batch; returns
    /// the mean training loss (standardised units).
    fn epoch(
        &mut self,
        epoch: usize,
        order: &[usize],
        tr: &Split<T>,
        rate: f64,
    ) -> Result<f64, SeqError> {
        let n_out = self.net.shape().n_outputs;
        let mut sse_epoch = 0.0;
        for (bi, rows) in order.chunks(self.settings.batch_size).enumerate() {
            let sse = self
                .batch_step(rows, tr, rate)
                .map_err(|what| SeqError::Diverged {
                    what,
                    epoch,
                    batch: bi,
                })?;
            sse_epoch += sse;
        }
        Ok(sse_epoch / (tr.n * n_out) as f64)
    }

    /// Gradient of the mean loss over the mini-batch `rows` (sharded over the threads), global
    /// norm clipping if set, and one optimiser step. Returns the batch's sum of squared errors,
    /// or which quantity (`loss` or `gradient`) became non-finite.
    fn batch_step(
        &mut self,
        rows: &[usize],
        tr: &Split<T>,
        rate: f64,
    ) -> Result<f64, &'static str> {
        let shape = *self.net.shape();
        let scale = 1.0 / (rows.len() * shape.n_outputs) as f64;
        fill_shards(
            &mut self.shards,
            rows,
            tr,
            shape.n_inputs(),
            shape.n_outputs,
        );
        shard_gradients(&self.net, &mut self.shards, self.pool.as_ref(), scale);
        let sse = sum_shards(&self.shards, &mut self.grad);
        if !sse.is_finite() {
            return Err("loss");
        }
        let norm = match self.settings.clip_norm {
            Some(c) => clip_by_norm(&mut self.grad, c),
            None => l2_norm(&self.grad),
        };
        if !norm.is_finite() {
            return Err("gradient");
        }
        self.opt.step(self.net.params_mut(), &self.grad, rate);
        Ok(sse)
    }

    /// Validation loss after an epoch (`None` without a validation split).
    fn validation_loss(&mut self, epoch: usize, va: &Split<T>) -> Result<Option<f64>, SeqError> {
        if va.n == 0 {
            return Ok(None);
        }
        let loss = evaluate(
            &self.net,
            va,
            self.settings.batch_size,
            &mut self.shards[0].ws,
        );
        if !loss.is_finite() {
            return Err(SeqError::Diverged {
                what: "loss",
                epoch,
                batch: 0,
            });
        }
        Ok(Some(loss))
    }
}

/// A pool of `threads` workers, or none for a single thread.
fn thread_pool(threads: usize) -> Result<Option<rayon::ThreadPool>, SeqError> {
    if threads <= 1 {
        return Ok(None);
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map(Some)
        .map_err(|e| SeqError::InvalidParameter {
            name: "threads",
            reason: format!("cannot start thread pool: {e}"),
        })
}

/// Copies the mini-batch `rows` into contiguous per-shard buffers (shard `s` gets the `s`-th
/// block of `ceil(len / shards)` rows; trailing shards may be empty).
fn fill_shards<T: Float>(
    shards: &mut [Shard<T>],
    rows: &[usize],
    tr: &Split<T>,
    n_in: usize,
    n_out: usize,
) {
    let per = rows.len().div_ceil(shards.len());
    for (s, shard) in shards.iter_mut().enumerate() {
        let part = &rows[(s * per).min(rows.len())..((s + 1) * per).min(rows.len())];
        shard.x.clear();
        shard.y.clear();
        for &r in part {
            shard.x.extend_from_slice(&tr.x[r * n_in..(r + 1) * n_in]);
            shard.y.extend_from_slice(&tr.y[r * n_out..(r + 1) * n_out]);
        }
    }
}

/// Each shard's sum of squared errors and its share (`scale` times the SSE gradient) of the
/// mean-loss gradient, in parallel on `pool` when there is one.
fn shard_gradients<T: Float>(
    net: &Network<T>,
    shards: &mut [Shard<T>],
    pool: Option<&rayon::ThreadPool>,
    scale: f64,
) {
    let n_in = net.shape().n_inputs();
    let run = |shard: &mut Shard<T>| {
        let b = shard.x.len() / n_in;
        shard.sse = if b == 0 {
            shard.grad.fill(T::of(0.0));
            0.0
        } else {
            net.sse_and_gradient(&shard.x, &shard.y, b, scale, &mut shard.grad, &mut shard.ws)
        };
    };
    match pool {
        Some(pool) => pool.install(|| {
            rayon::scope(|sc| {
                for shard in shards.iter_mut() {
                    sc.spawn(|_| run(shard));
                }
            })
        }),
        None => run(&mut shards[0]),
    }
}

/// Sums the shards' gradients into `grad` and returns the summed SSE, in shard order (a fixed
/// summation order keeps results independent of thread scheduling).
fn sum_shards<T: Float>(shards: &[Shard<T>], grad: &mut [T]) -> f64 {
    grad.copy_from_slice(&shards[0].grad);
    let mut sse = shards[0].sse;
    for shard in &shards[1..] {
        sse += shard.sse;
        for (g, s) in grad.iter_mut().zip(&shard.grad) {
            *g += *s;
        }
    }
    sse
}

/// Mean squared error (standardised units) of `net` on a split, in chunks of `batch` rows.
fn evaluate<T: Float>(net: &Network<T>, s: &Split<T>, batch: usize, ws: &mut Workspace<T>) -> f64 {
    let (n_in, n_out) = (net.shape().n_inputs(), net.shape().n_outputs);
    let mut sse = 0.0;
    for start in (0..s.n).step_by(batch) {
        let b = batch.min(s.n - start);
        let out = net
            .forward(&s.x[start * n_in..(start + b) * n_in], b, ws)
            .expect("split buffers are built with the network's shape");
        sse += out
            .iter()
            .zip(&s.y[start * n_out..(start + b) * n_out])
            .map(|(a, t)| (a.f64() - t.f64()).powi(2))
            .sum::<f64>();
    }
    sse / (s.n * n_out) as f64
}
