//! The mini-batch training loop.

use crate::error::SeqError;
use crate::float::{Float, Precision};
use crate::model::{LstmRegressor, TrainingHistory, Weights};
use crate::net::{LstmShape, Network, Workspace};
use crate::optim::{LrTracker, OptimizerState, clip_by_norm, l2_norm};
use crate::params::LstmParams;
use crate::scaler::Standardizer;
use nalgebra::DMatrix;
use rand::{RngExt, SeedableRng, rngs::StdRng};
use std::io::IsTerminal;
use std::time::Instant;

/// Fisher-Yates shuffle driven by the crate's seeded generator.
pub(crate) fn shuffle(v: &mut [usize], rng: &mut StdRng) {
    for i in (1..v.len()).rev() {
        let j = rng.random_range(0..=i);
        v.swap(i, j);
    }
}

/// Seeded split of `0..n` into (train, validation) row indices.
pub(crate) fn split_indices(
    n: usize,
    fraction: f64,
    seed: u64,
) -> Result<(Vec<usize>, Vec<usize>), SeqError> {
    let mut idx: Vec<usize> = (0..n).collect();
    if fraction == 0.0 {
        return Ok((idx, Vec::new()));
    }
    // A separate stream from the shuffles and the init, so changing epochs does not move the split.
    let mut rng = StdRng::seed_from_u64(seed ^ 0x5EED_5E11_7000_0001);
    shuffle(&mut idx, &mut rng);
    let n_val = ((n as f64) * fraction).round() as usize;
    if n_val == 0 || n_val >= n {
        return Err(SeqError::NotEnoughData {
            reason: format!(
                "validation fraction {fraction} of {n} samples leaves {n_val} for validation"
            ),
        });
    }
    let val = idx.split_off(n - n_val);
    Ok((idx, val))
}

/// Rows `idx` of `m` as a new matrix.
pub(crate) fn select_rows(m: &DMatrix<f64>, idx: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(idx.len(), m.ncols(), |r, c| m[(idx[r], c)])
}

pub(crate) fn fit(
    p: &LstmParams,
    shape: LstmShape,
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
) -> Result<LstmRegressor, SeqError> {
    let (tr, va) = split_indices(x.nrows(), p.get_validation_fraction(), p.get_seed())?;
    let (x_tr, y_tr) = (select_rows(x, &tr), select_rows(y, &tr));
    let (x_va, y_va) = (select_rows(x, &va), select_rows(y, &va));
    let xs = Standardizer::fit(&x_tr);
    let ys = Standardizer::fit(&y_tr);
    let (weights, history) = match p.get_precision() {
        Precision::F32 => {
            let (net, h) = train_typed::<f32>(p, shape, &xs, &ys, (&x_tr, &y_tr), (&x_va, &y_va))?;
            (Weights::F32(net), h)
        }
        Precision::F64 => {
            let (net, h) = train_typed::<f64>(p, shape, &xs, &ys, (&x_tr, &y_tr), (&x_va, &y_va))?;
            (Weights::F64(net), h)
        }
    };
    Ok(LstmRegressor::from_parts(
        p.clone(),
        weights,
        xs,
        ys,
        history,
    ))
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
            x: xs.to_row_major(x),
            y: ys.to_row_major(y),
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

fn train_typed<T: Float>(
    p: &LstmParams,
    shape: LstmShape,
    xs: &Standardizer,
    ys: &Standardizer,
    train: (&DMatrix<f64>, &DMatrix<f64>),
    valid: (&DMatrix<f64>, &DMatrix<f64>),
) -> Result<(Network<T>, TrainingHistory), SeqError> {
    let start = Instant::now();
    let tr = Split::<T>::new(xs, ys, train.0, train.1);
    let va = Split::<T>::new(xs, ys, valid.0, valid.1);
    let (n_in, n_out) = (shape.n_inputs(), shape.n_outputs);
    let mut net = Network::<T>::init(shape, p.get_seed());
    let mut opt = OptimizerState::new(p.get_optimizer(), shape.n_params());
    let mut lr = LrTracker::new(p.get_schedule(), p.get_learning_rate(), p.get_epochs());
    let mut rng = StdRng::seed_from_u64(p.get_seed().wrapping_add(0x9E37_79B9_7F4A_7C15));
    let threads = p.get_threads();
    let mut shards: Vec<Shard<T>> = (0..threads)
        .map(|_| Shard {
            ws: Workspace::new(),
            grad: vec![T::of(0.0); shape.n_params()],
            x: Vec::new(),
            y: Vec::new(),
            sse: 0.0,
        })
        .collect();
    let mut grad = vec![T::of(0.0); shape.n_params()];
    let mut order: Vec<usize> = (0..tr.n).collect();
    let mut hist = TrainingHistory::default();
    let mut best_params = net.params().to_vec();
    let mut best = f64::INFINITY;
    let mut since_best = 0;
    let bar = progress_bar(p.get_progress(), p.get_epochs());
    let batch = p.get_batch_size();
    let pool = if threads > 1 {
        Some(
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .map_err(|e| SeqError::InvalidParameter {
                    name: "threads",
                    reason: format!("cannot start thread pool: {e}"),
                })?,
        )
    } else {
        None
    };

    for epoch in 0..p.get_epochs() {
        let t0 = Instant::now();
        let rate = lr.rate(epoch);
        shuffle(&mut order, &mut rng);
        let mut sse_epoch = 0.0;
        for (bi, rows) in order.chunks(batch).enumerate() {
            let scale = 1.0 / (rows.len() * n_out) as f64;
            // Contiguous shards of the batch; each computes its share of the mean-loss gradient.
            let per = rows.len().div_ceil(threads);
            for (s, shard) in shards.iter_mut().enumerate() {
                let part = &rows[(s * per).min(rows.len())..((s + 1) * per).min(rows.len())];
                shard.x.clear();
                shard.y.clear();
                for &r in part {
                    shard.x.extend_from_slice(&tr.x[r * n_in..(r + 1) * n_in]);
                    shard.y.extend_from_slice(&tr.y[r * n_out..(r + 1) * n_out]);
                }
            }
            let run = |shard: &mut Shard<T>| {
                let b = shard.x.len() / n_in;
                shard.sse = if b == 0 {
                    shard.grad.fill(T::of(0.0));
                    0.0
                } else {
                    net.sse_and_gradient(
                        &shard.x,
                        &shard.y,
                        b,
                        scale,
                        &mut shard.grad,
                        &mut shard.ws,
                    )
                };
            };
            match &pool {
                Some(pool) => pool.install(|| {
                    rayon::scope(|sc| {
                        for shard in shards.iter_mut() {
                            sc.spawn(|_| run(shard));
                        }
                    })
                }),
                None => run(&mut shards[0]),
            }
            // Fixed summation order keeps results independent of thread scheduling.
            grad.copy_from_slice(&shards[0].grad);
            let mut sse = shards[0].sse;
            for shard in &shards[1..] {
                sse += shard.sse;
                for (g, s) in grad.iter_mut().zip(&shard.grad) {
                    *g += *s;
                }
            }
            if !sse.is_finite() {
                return Err(SeqError::Diverged {
                    what: "loss",
                    epoch,
                    batch: bi,
                });
            }
            let norm = match p.get_clip_norm() {
                Some(c) => clip_by_norm(&mut grad, c),
                None => l2_norm(&grad),
            };
            if !norm.is_finite() {
                return Err(SeqError::Diverged {
                    what: "gradient",
                    epoch,
                    batch: bi,
                });
            }
            opt.step(net.params_mut(), &grad, rate);
            sse_epoch += sse;
        }
        let train_loss = sse_epoch / (tr.n * n_out) as f64;
        let val_loss = if va.n > 0 {
            Some(evaluate(&net, &va, batch, &mut shards[0].ws))
        } else {
            None
        };
        if val_loss.is_some_and(|v| !v.is_finite()) {
            return Err(SeqError::Diverged {
                what: "loss",
                epoch,
                batch: 0,
            });
        }
        let monitored = val_loss.unwrap_or(train_loss);
        lr.observe(monitored);
        hist.train_loss.push(train_loss);
        hist.val_loss.extend(val_loss);
        hist.learning_rate.push(rate);
        hist.epoch_seconds.push(t0.elapsed().as_secs_f64());
        if monitored < best {
            best = monitored;
            hist.best_epoch = epoch;
            best_params.copy_from_slice(net.params());
            since_best = 0;
        } else {
            since_best += 1;
        }
        if let Some(bar) = &bar {
            bar.set_message(format!(
                "train {train_loss:.4e}{} lr {rate:.1e}",
                val_loss.map_or(String::new(), |v| format!(" val {v:.4e}"))
            ));
            bar.inc(1);
        }
        if p.get_patience() > 0 && since_best >= p.get_patience() {
            hist.stopped_early = true;
            break;
        }
    }
    if let Some(bar) = bar {
        bar.finish();
    }
    net.params_mut().copy_from_slice(&best_params);
    hist.best_loss = best;
    hist.train_samples = tr.n;
    hist.validation_samples = va.n;
    hist.wall_seconds = start.elapsed().as_secs_f64();
    Ok((net, hist))
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

fn progress_bar(show: bool, epochs: usize) -> Option<indicatif::ProgressBar> {
    let ci = std::env::var("CI").is_ok_and(|v| v.eq_ignore_ascii_case("true"));
    if !show || ci || !std::io::stderr().is_terminal() {
        return None;
    }
    let bar = indicatif::ProgressBar::new(epochs as u64);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "epoch {pos}/{len} [{elapsed_precise}] {bar:30} {msg}",
    ) {
        bar.set_style(style);
    }
    Some(bar)
}
