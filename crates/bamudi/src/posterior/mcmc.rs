//! Adaptive random-walk Metropolis (Haario, Saksman & Tamminen 2001) with several seeded
//! chains, and the convergence diagnostics split-R̂ and effective sample size (Gelman et al.,
//! *Bayesian Data Analysis*, 3rd ed., Sec. 11.4-11.5), for `θ` of more than one dimension.
//!
//! During warm-up the Gaussian proposal covariance is re-estimated from the chain's history
//! every 50 iterations as `(2.38² / d) (Σ̂ + 1e-10 I)`; it is frozen afterwards, so the kept
//! draws come from a time-homogeneous Metropolis kernel that leaves the target invariant.

use crate::error::{BamudiError, Result};
use crate::params::McmcConfig;
use nalgebra::{DMatrix, DVector};
use numerics::random::{derive_seed, standard_normal};
use rand::{RngExt, SeedableRng, rngs::StdRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Draws, diagnostics and summaries of a multi-chain run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct McmcResult {
    /// Kept draws: `chains[c][t]` is a point of dimension `d`.
    pub chains: Vec<Vec<Vec<f64>>>,
    /// Acceptance rate of each chain after warm-up.
    pub acceptance: Vec<f64>,
    /// Split-R̂ per dimension.
    pub rhat: Vec<f64>,
    /// Effective sample size per dimension (all chains together).
    pub ess: Vec<f64>,
    /// Posterior mean.
    pub mean: Vec<f64>,
    /// Posterior covariance (`d x d`).
    pub cov: DMatrix<f64>,
    /// Equal-tailed 95% intervals per dimension.
    pub ci95: Vec<(f64, f64)>,
}

fn empirical_cov(points: &[Vec<f64>]) -> DMatrix<f64> {
    let d = points[0].len();
    let n = points.len() as f64;
    let mean: Vec<f64> = (0..d)
        .map(|j| points.iter().map(|p| p[j]).sum::<f64>() / n)
        .collect();
    DMatrix::from_fn(d, d, |a, b| {
        points
            .iter()
            .map(|p| (p[a] - mean[a]) * (p[b] - mean[b]))
            .sum::<f64>()
            / (n - 1.0).max(1.0)
    })
}

/// Runs one chain; returns (kept draws, acceptance rate).
fn run_chain<F: Fn(&[f64]) -> Result<f64>>(
    logp: &F,
    start: &[f64],
    init_sd: &[f64],
    cfg: &McmcConfig,
    seed: u64,
) -> Result<(Vec<Vec<f64>>, f64)> {
    let d = start.len();
    let mut rng = StdRng::seed_from_u64(seed);
    let mut x = start.to_vec();
    let mut lp = logp(&x)?;
    if !lp.is_finite() {
        return Err(BamudiError::DegeneratePosterior(format!(
            "MCMC start {x:?} has log density {lp}"
        )));
    }
    let mut chol = DMatrix::from_diagonal(&DVector::from_iterator(d, init_sd.iter().copied()));
    let scale = 2.38 / (d as f64).sqrt();
    let mut history = Vec::with_capacity(cfg.warmup);
    let mut kept = Vec::with_capacity(cfg.samples);
    let mut accepted = 0usize;
    for it in 0..cfg.warmup + cfg.samples {
        let z = DVector::from_fn(d, |_, _| standard_normal(&mut rng));
        let step = &chol * z;
        let prop: Vec<f64> = x.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
        // A model error inside the density is an error of the run, not a rejected proposal.
        let lp_prop = logp(&prop)?;
        let u: f64 = rng.random::<f64>();
        let accept = lp_prop.is_finite() && u.ln() < lp_prop - lp;
        if accept {
            x = prop;
            lp = lp_prop;
        }
        if it < cfg.warmup {
            history.push(x.clone());
            if it >= 2 * d.max(10) && it % 50 == 0 {
                let mut c = empirical_cov(&history) * (scale * scale);
                for j in 0..d {
                    c[(j, j)] += 1e-10 * (1.0 + c[(j, j)]);
                }
                if let Some(ch) = c.cholesky() {
                    chol = ch.l();
                }
            }
        } else {
            accepted += usize::from(accept);
            kept.push(x.clone());
        }
    }
    Ok((kept, accepted as f64 / cfg.samples.max(1) as f64))
}

/// Samples `exp(logp)` with one chain per start point (in parallel; chain `c` uses a seed
/// derived from `seed` and `c`). `init_sd` sets the initial proposal standard deviations.
/// `logp` returns `-∞` outside the support; an `Err` from it stops the run and is returned.
///
/// ```
/// use bamudi::{McmcConfig, internals::adaptive_metropolis};
/// let cfg = McmcConfig { chains: 2, warmup: 500, samples: 2000 };
/// let res = adaptive_metropolis(|t: &[f64]| Ok(-0.5 * t[0] * t[0]), &[vec![-1.0], vec![1.0]], &[0.5], &cfg, 3).unwrap();
/// assert!(res.mean[0].abs() < 0.2 && res.rhat[0] < 1.05);
/// ```
pub fn adaptive_metropolis<F>(
    logp: F,
    starts: &[Vec<f64>],
    init_sd: &[f64],
    cfg: &McmcConfig,
    seed: u64,
) -> Result<McmcResult>
where
    F: Fn(&[f64]) -> Result<f64> + Sync,
{
    if starts.len() < 2 {
        return Err(BamudiError::config(
            "mcmc.chains",
            "need at least two chains for R-hat",
        ));
    }
    let d = starts[0].len();
    if d == 0 || starts.iter().any(|s| s.len() != d) || init_sd.len() != d {
        return Err(BamudiError::dim(
            "MCMC start points / init_sd dimension",
            d,
            init_sd.len(),
        ));
    }
    let runs = starts
        .par_iter()
        .enumerate()
        .map(|(c, s)| run_chain(&logp, s, init_sd, cfg, derive_seed(seed, c as u64)))
        .collect::<Result<Vec<_>>>()?;
    let (chains, acceptance): (Vec<_>, Vec<_>) = runs.into_iter().unzip();
    Ok(summarise(chains, acceptance))
}

fn summarise(chains: Vec<Vec<Vec<f64>>>, acceptance: Vec<f64>) -> McmcResult {
    let d = chains[0][0].len();
    let all: Vec<Vec<f64>> = chains.iter().flatten().cloned().collect();
    let n = all.len() as f64;
    let mean: Vec<f64> = (0..d)
        .map(|j| all.iter().map(|p| p[j]).sum::<f64>() / n)
        .collect();
    let cov = empirical_cov(&all);
    let mut rhat = Vec::with_capacity(d);
    let mut ess = Vec::with_capacity(d);
    let mut ci95 = Vec::with_capacity(d);
    for j in 0..d {
        let series: Vec<Vec<f64>> = chains
            .iter()
            .map(|c| c.iter().map(|p| p[j]).collect())
            .collect();
        rhat.push(split_rhat(&series));
        ess.push(effective_sample_size(&series));
        let mut v: Vec<f64> = all.iter().map(|p| p[j]).collect();
        v.sort_by(f64::total_cmp);
        let q = |p: f64| v[((p * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)];
        ci95.push((q(0.025), q(0.975)));
    }
    McmcResult {
        chains,
        acceptance,
        rhat,
        ess,
        mean,
        cov,
        ci95,
    }
}

fn mean_var(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    (
        m,
        x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0),
    )
}

/// Within-chain variance `W` and the pooled estimate `var⁺` of BDA3 Eq. 11.3.
fn w_and_var_plus(chains: &[&[f64]]) -> (f64, f64) {
    let n = chains[0].len() as f64;
    let stats: Vec<(f64, f64)> = chains.iter().map(|c| mean_var(c)).collect();
    let w = stats.iter().map(|s| s.1).sum::<f64>() / stats.len() as f64;
    let means: Vec<f64> = stats.iter().map(|s| s.0).collect();
    let b_over_n = mean_var(&means).1;
    (w, (n - 1.0) / n * w + b_over_n)
}

/// Split-R̂: each chain is cut in two halves and R̂ = √(var⁺ / W) over the halves.
///
/// ```
/// // two identical-looking stationary chains: R-hat close to one
/// let a: Vec<f64> = (0..1000).map(|i| ((i * 7919) % 1000) as f64).collect();
/// let b: Vec<f64> = (0..1000).map(|i| ((i * 104729) % 1000) as f64).collect();
/// assert!(bamudi::internals::split_rhat(&[a, b]) < 1.01);
/// ```
pub fn split_rhat(chains: &[Vec<f64>]) -> f64 {
    let half = chains.iter().map(Vec::len).min().unwrap_or(0) / 2;
    if half < 2 {
        return f64::NAN;
    }
    let halves: Vec<&[f64]> = chains
        .iter()
        .flat_map(|c| [&c[..half], &c[half..2 * half]])
        .collect();
    let (w, var_plus) = w_and_var_plus(&halves);
    if w <= 0.0 {
        return f64::NAN;
    }
    (var_plus / w).sqrt()
}

/// Multi-chain effective sample size with Geyer's initial-positive-sequence truncation of the
/// combined autocorrelation `ρ̂_t = 1 − (W − mean_m γ̂_{t,m}) / var⁺` (BDA3 Eq. 11.7-11.8).
///
/// ```
/// // independent draws: ESS close to the number of draws
/// let mut s = 1u64;
/// let mut u = || { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); (s >> 11) as f64 / (1u64 << 53) as f64 };
/// let a: Vec<f64> = (0..2000).map(|_| u()).collect();
/// let b: Vec<f64> = (0..2000).map(|_| u()).collect();
/// let ess = bamudi::internals::effective_sample_size(&[a, b]);
/// assert!(ess > 3000.0 && ess < 5000.0, "{ess}");
/// ```
pub fn effective_sample_size(chains: &[Vec<f64>]) -> f64 {
    let n = chains.iter().map(Vec::len).min().unwrap_or(0);
    let m = chains.len();
    if n < 4 || m == 0 {
        return f64::NAN;
    }
    let slices: Vec<&[f64]> = chains.iter().map(|c| &c[..n]).collect();
    let (w, var_plus) = w_and_var_plus(&slices);
    if var_plus <= 0.0 {
        return f64::NAN;
    }
    let means: Vec<f64> = slices
        .iter()
        .map(|c| c.iter().sum::<f64>() / n as f64)
        .collect();
    let autocov = |t: usize| -> f64 {
        slices
            .iter()
            .zip(&means)
            .map(|(c, mu)| {
                (0..n - t)
                    .map(|i| (c[i] - mu) * (c[i + t] - mu))
                    .sum::<f64>()
                    / n as f64
            })
            .sum::<f64>()
            / m as f64
    };
    let rho = |t: usize| 1.0 - (w - autocov(t)) / var_plus;
    // Geyer: sum pairs Γ_k = ρ_{2k} + ρ_{2k+1} while they stay positive
    let mut tau = -1.0;
    let mut t = 0;
    while t + 1 < n {
        let pair = rho(t) + rho(t + 1);
        if pair <= 0.0 {
            break;
        }
        tau += 2.0 * pair;
        t += 2;
    }
    (m * n) as f64 / tau.max(1.0 / (m * n) as f64)
}
