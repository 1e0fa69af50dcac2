//! `seqnet`: a hand-written LSTM with backpropagation through time, batched GEMM kernels and
//! Adam/SGD training: the machine-learning model `alpha = f_ML(rho, x, mu_o)` of Module 2 of
//! BA-MUDI (paper Sec. 3.3.2, Eqs. 27-29, Fig. 5-6).
//!
//! In the miter-gate application the network maps 10 inputs (the regression coefficient `rho`,
//! two water levels in inches, seven strains in microstrain) to 12 outputs (the Legendre
//! coefficients of the normal and tangential quoin-force discrepancy, in the units of the force
//! basis), learned from 50,000 simulated samples. The paper's LSTM took 172 min to train; here one
//! epoch over 50,000 samples takes well under a second of CPU (see docs/benchmarks.md, `## seqnet`).
//!
//! # Model
//! Each sample's `n_inputs` values are fed as a sequence of `steps` time steps of
//! `n_inputs / steps` values each ([`LstmSettings::steps`]: a sequence of scalars, one step of all
//! features, or anything in between). Each layer is the cell of Eq. 28,
//!
//! ```text
//! f_t = sigma(W_f [h_{t-1}, x_t] + b_f)        forget gate
//! i_t = sigma(W_i [h_{t-1}, x_t] + b_i)        input gate
//! C~_t = tanh(W_C [h_{t-1}, x_t] + b_C)        candidate
//! C_t = f_t * C_{t-1} + i_t * C~_t             cell state
//! o_t = sigma(W_o [h_{t-1}, x_t] + b_o)        output gate
//! h_t = o_t * tanh(C_t)                        hidden state
//! ```
//!
//! with `h_{-1} = C_{-1} = 0`; layers are stacked (layer `l+1` reads layer `l`'s `h_t`), and a dense
//! head maps the top layer's last hidden state to the outputs. The loss is the mean squared error
//! over outputs and samples (in standardised units). Gradients come from hand-written
//! backpropagation through time ([`Network::loss_and_gradient`]); they agree with central
//! finite differences to better than 1e-6 relative (property test) and with PyTorch's autograd for
//! the same weights to 1e-5 (f32) and 1e-12 (f64) relative (fixture test).
//!
//! # Kernels
//! For a batch of `B` samples, one GEMM per layer and step computes all four gates:
//! `[x_t, h_{t-1}]` (`B x (F+H)`) times `W` (`(F+H) x 4H`), using faer's `matmul`. Backward, per
//! step, `dZ_t W_h^T` gives the recurrent gradient, and one GEMM over all steps at once gives the
//! weight gradient. Gate non-linearities use a branch-free exponential ([`fast_exp_f32`],
//! [`fast_exp_f64`]) compiled for AVX2/FMA through pulp's runtime dispatch. All buffers live in a
//! reusable [`Workspace`]; nothing is allocated per step. Both `f32` and `f64` are supported
//! ([`Precision`]).
//!
//! # Training
//! The hyper-parameters are one plain struct, [`LstmSettings`] (serde, every field defaulted,
//! unknown keys refused: what a configuration file embeds). Fitting follows linfa's pipeline:
//! [`LstmParams`] (builder: data shape, settings, seed) → [`LstmParams::check`] (validates
//! once) → [`CheckedLstmParams`] (immutable) → [`CheckedLstmParams::fit`] or
//! [`CheckedLstmParams::fit_observed`]; [`LstmParams::fit`] does check and fit in one call.
//!
//! `fit` holds out a seeded validation split, standardises inputs and outputs (statistics of
//! the training split, stored in the model; [`numerics::Standardizer`]) and runs seeded
//! mini-batch epochs with Adam or SGD ([`Optimizer`]), optional global-norm gradient clipping, a
//! learning-rate schedule ([`LrSchedule`]: constant, step, cosine, reduce-on-plateau) and early
//! stopping with restoration of the best weights. The library never prints: progress goes to a
//! [`TrainObserver`], one [`EpochReport`] per epoch ([`NoObserver`] ignores them; closures are
//! observers). With `threads(n)` each mini-batch is split into `n` shards whose gradients are
//! summed in a fixed order, so results depend only on the seed and the thread count.
//! Initialisation: Xavier-uniform input and head weights, orthogonal recurrent blocks,
//! forget-gate bias 1.
//!
//! Bad input is an error, never a panic: non-finite data ([`SeqError::NonFinite`] with row and
//! column), wrong shapes, invalid hyper-parameters (named), and a loss or gradient that becomes
//! NaN/infinite during training ([`SeqError::Diverged`] with epoch and batch).
//!
//! The hyper-parameters the paper picks by a train/test split (layers and hidden units) are chosen
//! by [`select_hyperparameters`] over a [`SearchSpace`] with a candidate and epoch budget.
//!
//! # Persistence
//! [`LstmRegressor::save`] writes JSON with a `format_version` ([`FORMAT_VERSION`]), the shape,
//! hyper-parameters, weights, scalers and history; [`LstmRegressor::load`] restores it bit for bit
//! (files of the previous version 1 too) and refuses other versions or inconsistent files with
//! [`SeqError::Format`];
//! [`LstmRegressor::load_with_shape`] also checks the expected shape.
//!
//! # Example
//! ```
//! use nalgebra::DMatrix;
//! use seqnet::{EpochReport, LstmParams, LrSchedule};
//! // y = (sin(2 a) b, a^2 - b) from 2 inputs fed as a sequence of 2 scalars.
//! let x = DMatrix::from_fn(400, 2, |r, c| (((r * 37 + c * 11) % 101) as f64 / 50.0) - 1.0);
//! let y = DMatrix::from_fn(400, 2, |r, c| {
//!     let (a, b) = (x[(r, 0)], x[(r, 1)]);
//!     if c == 0 { (2.0 * a).sin() * b } else { a * a - b }
//! });
//! let params = LstmParams::new(2, 2)
//!     .hidden(16)
//!     .steps(2)
//!     .epochs(30)
//!     .batch_size(32)
//!     .learning_rate(1e-2)
//!     .schedule(LrSchedule::Cosine { min_factor: 0.1 })
//!     .seed(7)
//!     .check()?;
//! let mut last = None;
//! let model = params.fit_observed(&x, &y, &mut |r: &EpochReport| last = Some(r.train_loss))?;
//! let h = model.history();
//! assert_eq!(last, h.train_loss.last().copied());
//! assert!(h.best_loss < 0.1 * h.train_loss[0]);
//! let yhat = model.predict(&x)?;
//! assert_eq!(yhat.shape(), (400, 2));
//! # Ok::<(), seqnet::SeqError>(())
//! ```
//!
//! # Modules
//! Dependencies run one way: `settings` (plain data) ← `params` (builder, checks) ←
//! `train` (fit) → `model` (the trained regressor) → `net` (shape, kernels); `observe`,
//! `data` (checks, splits, buffers) and `search` sit beside them. No faer type appears in the
//! public API (the GEMM parallelism of a [`Workspace`] is a thread count).
/// The crate README's example, compiled and run as a doc test.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctest;

mod data;
mod error;
mod float;
mod gemm;
mod model;
mod net;
mod observe;
mod optim;
mod params;
mod search;
mod settings;
mod train;

pub use error::SeqError;
pub use float::{Float, Precision, fast_exp_f32, fast_exp_f64};
pub use model::{FORMAT_VERSION, LstmRegressor, TrainingHistory};
pub use net::{LstmShape, Network, Workspace};
pub use observe::{EpochReport, NoObserver, TrainObserver};
pub use optim::{LrSchedule, Optimizer};
pub use params::{CheckedLstmParams, LstmParams};
pub use search::{CandidateScore, SearchResult, SearchSpace, select_hyperparameters};
pub use settings::LstmSettings;
