//! Module 2, offline phase: the training set `(ρ, x, α) → μ_o` of Eq. 27.
//!
//! `θ` is marginalised over its prior with a [`QuadratureRule`] (Gauss quadrature by default,
//! or equal-weight prior draws for the paper's Monte Carlo option). For a
//! [`LinearObservableModel`] `g_o = A y_u + b(x, θ)` Eq. 27 collapses to
//! `μ_o = ρ A ḡ(x) + b̄(x) + B α` with `ḡ = E_θ[g_u(x, θ)]`, `b̄ = E_θ[b(x, θ)]` and
//! `B = A · blockdiag(L_c)`, so each `x` of the pool costs `n_nodes` evaluations of `g_u` and
//! every `(ρ, α)` draw at that `x` is a matrix-vector product.

use crate::error::{BamudiError, Result};
use crate::observe::{Observer, Stage, tick};
use crate::params::{Marginalisation, SamplingRule};
use mlmodel::{
    LinearObservableModel, MultiLevelModel, ObservableModel, Prior, QuadratureRule,
    UnobservableModel,
};
use nalgebra::{DMatrix, DVector};
use numerics::random::{derive_seed, standard_normal};
use rand::{RngExt, SeedableRng, rngs::StdRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The nodes and weights used to marginalise `θ` (Eq. 25, 27, 31).
///
/// ```
/// use bamudi::{Marginalisation, internals::theta_rule};
/// let prior = mlmodel::NormalPrior::new(vec![(0.0, 1.0)]).unwrap();
/// let mc = theta_rule(&prior, &Marginalisation::MonteCarlo { samples: 4 }, 1).unwrap();
/// assert_eq!(mc.nodes.len(), 4);
/// assert!((mc.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
/// ```
pub fn theta_rule(
    prior: &dyn Prior,
    method: &Marginalisation,
    seed: u64,
) -> Result<QuadratureRule> {
    match *method {
        Marginalisation::Quadrature { order } => Ok(prior.quadrature(order)?),
        Marginalisation::MonteCarlo { samples } => Ok(QuadratureRule {
            nodes: prior.sample(samples, seed),
            weights: vec![1.0 / samples as f64; samples],
        }),
    }
}

/// The matrices of a linear observable model that Modules 2-4 reuse.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LinearParts {
    /// `A` (`N_o x C N_u`).
    pub a: DMatrix<f64>,
    /// `blockdiag(L_c)` (`C N_u x K`).
    pub l: DMatrix<f64>,
    /// `B = A L` (`N_o x K`): strain per unit discrepancy coefficient.
    pub b: DMatrix<f64>,
}

impl LinearParts {
    /// Extracts `A`, `L` and `B` from a model.
    pub fn new<U: UnobservableModel, O: LinearObservableModel>(
        model: &MultiLevelModel<U, O>,
    ) -> Result<Self> {
        let a = model.observable.matrix().clone();
        let l = model.basis.block_matrix();
        if a.ncols() != l.nrows() {
            return Err(BamudiError::dim(
                "columns of A vs response length C*N_u",
                l.nrows(),
                a.ncols(),
            ));
        }
        let b = &a * &l;
        Ok(Self { a, l, b })
    }
}

/// Prior-averaged quantities at one input `x` (linear observable model).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct XContext {
    /// `A ḡ(x)` with `ḡ = E_θ[g_u(x, θ)]` (length `N_o`).
    pub mean_ag: Vec<f64>,
    /// `b̄(x) = E_θ[b(x, θ)]` (length `N_o`).
    pub mean_offset: Vec<f64>,
    /// Half-widths `c s_k(x)` of the uniform `α_k` training range (length `K`).
    pub alpha_half_width: Vec<f64>,
    /// Root mean square over all points of the nominal response `g_u(x, θ̄)` at the prior mean
    /// (response units; `0` in files written before it existed).
    #[serde(default)]
    pub response_rms: f64,
}

/// Half-widths `c s_k(x)` of the sampling rule from a nominal response.
pub(crate) fn alpha_half_width<U, O>(
    model: &MultiLevelModel<U, O>,
    nominal: &[f64],
    rule: &SamplingRule,
) -> Result<Vec<f64>>
where
    U: UnobservableModel,
    O: ObservableModel,
{
    let coef = model.basis.project(nominal)?;
    let mut s = vec![0.0; coef.len()];
    for c in 0..model.basis.components() {
        let off = model.basis.coefficient_offset(c);
        let k = model.basis.terms()[c];
        let block = &coef[off..off + k];
        let floor = rule.floor_fraction * block.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for j in 0..k {
            s[off + j] = rule.alpha_scale * (block[j].abs() + floor);
        }
    }
    if s.iter().all(|v| *v == 0.0) {
        return Err(BamudiError::Numerical {
            context: "sampling rule".into(),
            reason: "nominal response is identically zero: alpha range would be empty".into(),
        });
    }
    Ok(s)
}

/// Computes the [`XContext`] at `x`: `n_nodes + 1` evaluations of `g_u`.
pub fn x_context<U, O>(
    model: &MultiLevelModel<U, O>,
    parts: &LinearParts,
    theta_rule: &QuadratureRule,
    sampling: &SamplingRule,
    x: &[f64],
) -> Result<XContext>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let n = model.unobservable.response_len();
    let n_o = parts.a.nrows();
    let mut gbar = DVector::zeros(n);
    let mut bbar = vec![0.0; n_o];
    let mut g = vec![0.0; n];
    let mut off = vec![0.0; n_o];
    for (theta, w) in theta_rule.nodes.iter().zip(&theta_rule.weights) {
        model.unobservable.evaluate(x, theta, &mut g)?;
        model.observable.offset(x, theta, &mut off)?;
        for (gb, gi) in gbar.iter_mut().zip(&g) {
            *gb += w * gi;
        }
        for (bb, oi) in bbar.iter_mut().zip(&off) {
            *bb += w * oi;
        }
    }
    model.unobservable.evaluate(x, &theta_rule.mean(), &mut g)?;
    let half = alpha_half_width(model, &g, sampling)?;
    let response_rms = (g.iter().map(|v| v * v).sum::<f64>() / g.len().max(1) as f64).sqrt();
    Ok(XContext {
        mean_ag: (&parts.a * gbar).iter().copied().collect(),
        mean_offset: bbar,
        alpha_half_width: half,
        response_rms,
    })
}

/// The offline training set of Eq. 27: one row per sample.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TrainingSet {
    /// `ρ_{t,c}`.
    pub rho: Vec<f64>,
    /// `x_{t,c}` (`N_t x d`).
    pub x: DMatrix<f64>,
    /// `α_{t,c}` (`N_t x K`).
    pub alpha: DMatrix<f64>,
    /// `μ_o(x, α, ρ)` (`N_t x N_o`), plus optional noise of the sampling rule.
    pub mu_o: DMatrix<f64>,
    /// Distinct `x` values used (the pool size).
    pub pool_size: usize,
}

impl TrainingSet {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.rho.len()
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.rho.is_empty()
    }
}

/// One training sample `(ρ, x, α, μ_o)`.
type Sample = (f64, Vec<f64>, Vec<f64>, Vec<f64>);

/// Draws the pool of `x` values uniformly in `bounds`, keeping only points inside the model's
/// input domain ([`UnobservableModel::check_input`], e.g. `h_up >= h_down` for the gate), so the
/// pool is uniform on the part of the box where the model is defined.
fn draw_pool<U: UnobservableModel>(
    model: &U,
    bounds: &[(f64, f64)],
    pool: usize,
    seed: u64,
) -> Result<Vec<Vec<f64>>> {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut xs = Vec::with_capacity(pool);
    let max_draws = 1000 * pool.max(1);
    for _ in 0..max_draws {
        if xs.len() == pool {
            return Ok(xs);
        }
        let x: Vec<f64> = bounds
            .iter()
            .map(|&(lo, hi)| lo + (hi - lo) * rng.random::<f64>())
            .collect();
        if model.check_input(&x).is_ok() {
            xs.push(x);
        }
    }
    Err(BamudiError::config(
        "sampling.x_bounds",
        format!(
            "fewer than {pool} of {max_draws} draws in the x box {bounds:?} lie in the model's domain"
        ),
    ))
}

/// Draws `(ρ, α)` at one pool point.
fn draw_rho_alpha(rng: &mut StdRng, rule: &SamplingRule, half: &[f64]) -> (f64, Vec<f64>) {
    let (lo, hi) = rule.rho_range;
    let rho = lo + (hi - lo) * rng.random::<f64>();
    let alpha = half
        .iter()
        .map(|h| h * (2.0 * rng.random::<f64>() - 1.0))
        .collect();
    (rho, alpha)
}

/// The `pool` distinct inputs `x` of a training set: `bounds` checked against the model, then
/// drawn with a seed derived from `seed` (the per-`x` draws use the other derived seeds).
fn input_pool<U: UnobservableModel, O>(
    model: &MultiLevelModel<U, O>,
    bounds: &[(f64, f64)],
    pool: usize,
    seed: u64,
) -> Result<Vec<Vec<f64>>> {
    check_bounds(model, bounds)?;
    draw_pool(
        &model.unobservable,
        bounds,
        pool,
        derive_seed(seed, u64::MAX),
    )
}

/// Checks `bounds` against the model's input dimension.
fn check_bounds<U: UnobservableModel, O>(
    model: &MultiLevelModel<U, O>,
    bounds: &[(f64, f64)],
) -> Result<()> {
    if bounds.len() != model.unobservable.input_dim() {
        return Err(BamudiError::dim(
            "x bounds vs model inputs",
            model.unobservable.input_dim(),
            bounds.len(),
        ));
    }
    Ok(())
}

/// What a training set is drawn from (Eq. 27): the `θ` rule, the sampling rule, the input
/// box, the number of samples and the seed.
#[derive(Debug, Clone, Copy)]
pub struct TrainingSpec<'a> {
    /// Nodes and weights marginalising `θ`.
    pub theta_rule: &'a QuadratureRule,
    /// How `(ρ, x, α)` are drawn.
    pub rule: &'a SamplingRule,
    /// The box the inputs `x` are drawn in.
    pub bounds: &'a [(f64, f64)],
    /// Number of samples `N_t`.
    pub size: usize,
    /// Seed of every draw.
    pub seed: u64,
}

/// Generates `spec.size` training samples for a linear observable model (the fast path), in
/// parallel over the pool of `ceil(size / draws_per_x)` distinct `x` values, reporting one
/// [`Stage::TrainingSet`] unit per pool point to `observer`. Deterministic for a given seed
/// regardless of the number of threads.
pub fn generate_linear<U, O>(
    model: &MultiLevelModel<U, O>,
    parts: &LinearParts,
    spec: &TrainingSpec<'_>,
    observer: &dyn Observer,
) -> Result<TrainingSet>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let (rule, seed) = (spec.rule, spec.seed);
    let per = rule.draws_per_x;
    let xs = input_pool(model, spec.bounds, spec.size.div_ceil(per), seed)?;
    let pool = xs.len();
    let rows: Vec<Vec<Sample>> = xs
        .par_iter()
        .enumerate()
        .map(|(i, x)| {
            let ctx = x_context(model, parts, spec.theta_rule, rule, x)?;
            let mut rng = StdRng::seed_from_u64(derive_seed(seed, i as u64));
            let out = (0..per)
                .map(|_| linear_sample(&mut rng, rule, parts, &ctx, x))
                .collect();
            tick(observer, Stage::TrainingSet);
            Ok(out)
        })
        .collect::<Result<_>>()?;
    Ok(assemble(rows, spec.size, pool))
}

/// One `(ρ, x, α, μ_o)` sample of the linear fast path at a pool point with context `ctx`.
fn linear_sample(
    rng: &mut StdRng,
    rule: &SamplingRule,
    parts: &LinearParts,
    ctx: &XContext,
    x: &[f64],
) -> Sample {
    let (rho, alpha) = draw_rho_alpha(rng, rule, &ctx.alpha_half_width);
    let ba = &parts.b * DVector::from_column_slice(&alpha);
    let mu: Vec<f64> = (0..ctx.mean_ag.len())
        .map(|p| {
            rho * ctx.mean_ag[p] + ctx.mean_offset[p] + ba[p] + rule.noise_sd * standard_normal(rng)
        })
        .collect();
    (rho, x.to_vec(), alpha, mu)
}

/// Generates `spec.size` training samples through the general `g_o` (any
/// [`ObservableModel`]): `μ_o = Σ_j w_j g_o(x, θ_j, ρ g_u(x, θ_j) + L α)`, reusing the
/// `g_u(x, θ_j)` of each pool point for all its draws. The `α` range comes from the same
/// [`SamplingRule`].
pub fn generate_general<U, O>(
    model: &MultiLevelModel<U, O>,
    spec: &TrainingSpec<'_>,
    observer: &dyn Observer,
) -> Result<TrainingSet>
where
    U: UnobservableModel,
    O: ObservableModel,
{
    let per = spec.rule.draws_per_x;
    let xs = input_pool(model, spec.bounds, spec.size.div_ceil(per), spec.seed)?;
    let pool = xs.len();
    let rows: Vec<Vec<Sample>> = xs
        .par_iter()
        .enumerate()
        .map(|(i, x)| {
            let out = general_samples(model, spec, x, derive_seed(spec.seed, i as u64))?;
            tick(observer, Stage::TrainingSet);
            Ok(out)
        })
        .collect::<Result<_>>()?;
    Ok(assemble(rows, spec.size, pool))
}

/// The `draws_per_x` samples of the general path at one pool point `x`.
fn general_samples<U, O>(
    model: &MultiLevelModel<U, O>,
    spec: &TrainingSpec<'_>,
    x: &[f64],
    seed: u64,
) -> Result<Vec<Sample>>
where
    U: UnobservableModel,
    O: ObservableModel,
{
    let (theta_rule, rule) = (spec.theta_rule, spec.rule);
    let n_u = model.unobservable.response_len();
    let n_o = model.observable.output_dim();
    let gs = theta_rule
        .nodes
        .iter()
        .map(|t| {
            let mut g = vec![0.0; n_u];
            model.unobservable.evaluate(x, t, &mut g).map(|_| g)
        })
        .collect::<mlmodel::Result<Vec<_>>>()?;
    let mut nominal = vec![0.0; n_u];
    model
        .unobservable
        .evaluate(x, &theta_rule.mean(), &mut nominal)?;
    let half = alpha_half_width(model, &nominal, rule)?;
    let mut rng = StdRng::seed_from_u64(seed);
    let (mut delta, mut yu, mut go) = (vec![0.0; n_u], vec![0.0; n_u], vec![0.0; n_o]);
    let mut out = Vec::with_capacity(rule.draws_per_x);
    for _ in 0..rule.draws_per_x {
        let (rho, alpha) = draw_rho_alpha(&mut rng, rule, &half);
        model.basis.expand(&alpha, &mut delta)?;
        let mut mu = vec![0.0; n_o];
        for ((t, w), g) in theta_rule.nodes.iter().zip(&theta_rule.weights).zip(&gs) {
            for b in 0..n_u {
                yu[b] = rho * g[b] + delta[b];
            }
            model.observable.evaluate(x, t, &yu, &mut go)?;
            for (m, v) in mu.iter_mut().zip(&go) {
                *m += w * v;
            }
        }
        for m in &mut mu {
            *m += rule.noise_sd * standard_normal(&mut rng);
        }
        out.push((rho, x.to_vec(), alpha, mu));
    }
    Ok(out)
}

fn assemble(rows: Vec<Vec<Sample>>, n: usize, pool: usize) -> TrainingSet {
    let flat: Vec<_> = rows.into_iter().flatten().take(n).collect();
    let d = flat.first().map_or(0, |r| r.1.len());
    let k = flat.first().map_or(0, |r| r.2.len());
    let n_o = flat.first().map_or(0, |r| r.3.len());
    let m = flat.len();
    TrainingSet {
        rho: flat.iter().map(|r| r.0).collect(),
        x: DMatrix::from_fn(m, d, |i, j| flat[i].1[j]),
        alpha: DMatrix::from_fn(m, k, |i, j| flat[i].2[j]),
        mu_o: DMatrix::from_fn(m, n_o, |i, j| flat[i].3[j]),
        pool_size: pool,
    }
}
