//! The `θ` posteriors of Module 3, with and without the discrepancy, from a log-density
//! evaluator: exact grid quadrature with an adaptive zoom for one-dimensional `θ`, adaptive
//! Metropolis otherwise.

use super::mcmc::adaptive_metropolis;
use super::theta::{GridPosterior, ThetaPosterior};
use crate::error::Result;
use crate::observe::{Event, Observer, Stage, tick};
use crate::params::CalibrationConfig;
use crate::surrogate::seed_index;
use numerics::random::derive_seed;
use rayon::prelude::*;

/// Unnormalised log posteriors `(with, without discrepancy)` at a `θ` (`-∞` outside the
/// prior); called from worker threads.
pub trait LogPosteriors: Sync {
    /// Evaluates both log posteriors at `θ`.
    fn log_posteriors(&self, theta: &[f64]) -> Result<(f64, f64)>;

    /// Both log posteriors at each node of a one-dimensional `θ` grid, ticking `observer`
    /// once per node (stage Module 3). The default evaluates the nodes one by one in
    /// parallel; an evaluator whose nodes share a costly factor (the dense covariance of
    /// Eq. 51) overrides it to batch the work on that factor.
    ///
    /// ```
    /// use bamudi::internals::LogPosteriors;
    /// struct Normal; // a N(0, 1) posterior with and without discrepancy
    /// impl LogPosteriors for Normal {
    ///     fn log_posteriors(&self, t: &[f64]) -> bamudi::Result<(f64, f64)> {
    ///         Ok((-0.5 * t[0] * t[0], -0.5 * t[0] * t[0]))
    ///     }
    /// }
    /// let v = Normal.log_posteriors_at_nodes(&[0.0, 2.0], &bamudi::observe::Silent).unwrap();
    /// assert_eq!(v, vec![(0.0, 0.0), (-2.0, -2.0)]);
    /// ```
    fn log_posteriors_at_nodes(
        &self,
        nodes: &[f64],
        observer: &dyn Observer,
    ) -> Result<Vec<(f64, f64)>> {
        nodes
            .par_iter()
            .map(|t| {
                let r = self.log_posteriors(&[*t]);
                tick(observer, Stage::Module3);
                r
            })
            .collect()
    }
}

/// Both posteriors: grid quadrature for one-dimensional `θ` (prior box `bounds`), adaptive
/// Metropolis otherwise (started from prior draws `starts`).
pub fn posteriors(
    lp: &dyn LogPosteriors,
    bounds: &[(f64, f64)],
    starts: impl FnOnce(usize, u64) -> Vec<Vec<f64>>,
    cfg: &CalibrationConfig,
    observer: &dyn Observer,
) -> Result<(ThetaPosterior, ThetaPosterior)> {
    if bounds.len() == 1 {
        return grid_posteriors(lp, bounds[0], cfg, observer);
    }
    let starts = starts(
        cfg.mcmc.chains,
        derive_seed(cfg.seed, seed_index::MCMC_STARTS),
    );
    let init_sd: Vec<f64> = bounds.iter().map(|(lo, hi)| (hi - lo) / 20.0).collect();
    let post = |which: usize| {
        adaptive_metropolis(
            |t: &[f64]| {
                lp.log_posteriors(t)
                    .map(|v| if which == 0 { v.0 } else { v.1 })
            },
            &starts,
            &init_sd,
            &cfg.mcmc,
            derive_seed(cfg.seed, seed_index::MCMC_CHAINS + which as u64),
        )
    };
    Ok((
        ThetaPosterior::Mcmc(post(0)?),
        ThetaPosterior::Mcmc(post(1)?),
    ))
}

/// Nodes of the first, uniform pass of the grid posterior.
pub(crate) fn coarse_nodes(cfg: &CalibrationConfig) -> usize {
    (cfg.theta_grid_points.max(8) / 4).max(3)
}

/// Log posteriors (with, without discrepancy) at each node ([`LogPosteriors::log_posteriors_at_nodes`]).
fn evaluate_nodes(
    lp: &dyn LogPosteriors,
    nodes: &[f64],
    observer: &dyn Observer,
) -> Result<Vec<(f64, f64)>> {
    observer.observe(&Event::Started {
        stage: Stage::Module3,
        work: nodes.len() as u64,
    });
    lp.log_posteriors_at_nodes(nodes, observer)
}

/// Exact grid quadrature with adaptive zoom: a quarter of `theta_grid_points` spread
/// uniformly over the prior support, then zoom passes of `theta_grid_points / 8` nodes per
/// posterior, each placed uniformly where that posterior has mass (log density within 30 of
/// its maximum, i.e. relative density > 1e-13, padded to the neighbouring nodes), until
/// every posterior's mass region holds at least [`MIN_LIVE_NODES`] nodes or the node budget
/// is spent. Posteriors are often orders of magnitude narrower than the prior; the zoom puts
/// the nodes where the integrand lives; the log density is then interpolated by local
/// quadratics onto [`SUBDIVISIONS`] sub-intervals per interval and integrated by the trapezoid
/// rule ([`GridPosterior::interpolated`]).
fn grid_posteriors(
    lp: &dyn LogPosteriors,
    (lo, hi): (f64, f64),
    cfg: &CalibrationConfig,
    observer: &dyn Observer,
) -> Result<(ThetaPosterior, ThetaPosterior)> {
    let budget = cfg.theta_grid_points.max(8);
    let n0 = coarse_nodes(cfg);
    let coarse: Vec<f64> = (0..n0)
        .map(|i| lo + (hi - lo) * i as f64 / (n0 - 1) as f64)
        .collect();
    let vals = evaluate_nodes(lp, &coarse, observer)?;
    let mut all: Vec<(f64, (f64, f64))> = coarse.into_iter().zip(vals).collect();
    let n_zoom = (budget / 8).max(2);
    let tol = 1e-9 * (hi - lo);
    while all.len() + n_zoom <= budget {
        let mut fine = Vec::new();
        for which in 0..2 {
            if live_count(&all, which) < MIN_LIVE_NODES {
                fine.extend(zoom_nodes(&all, which, n_zoom, (lo, hi)));
            }
        }
        fine.sort_by(f64::total_cmp);
        fine.dedup_by(|a, b| (*a - *b).abs() <= tol);
        fine.retain(|t| all.iter().all(|a| (a.0 - t).abs() > tol));
        if fine.is_empty() {
            break;
        }
        let fine_vals = evaluate_nodes(lp, &fine, observer)?;
        all.extend(fine.into_iter().zip(fine_vals));
        all.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    let theta: Vec<f64> = all.iter().map(|a| a.0).collect();
    let with = all.iter().map(|a| a.1.0).collect();
    let without = all.iter().map(|a| a.1.1).collect();
    let with: Vec<f64> = with;
    let without: Vec<f64> = without;
    Ok((
        ThetaPosterior::Grid(GridPosterior::interpolated(&theta, &with, SUBDIVISIONS)?),
        ThetaPosterior::Grid(GridPosterior::interpolated(&theta, &without, SUBDIVISIONS)?),
    ))
}

/// Sub-intervals per evaluated interval on which the log density is interpolated
/// ([`GridPosterior::interpolated`]).
pub const SUBDIVISIONS: usize = 8;

/// Grid nodes a posterior's mass region must hold before the zoom stops refining it.
pub const MIN_LIVE_NODES: usize = 12;

/// Number of evaluated nodes where posterior `which` has mass (log density within 30 of max).
fn live_count(all: &[(f64, (f64, f64))], which: usize) -> usize {
    let logd = |a: &(f64, (f64, f64))| if which == 0 { a.1.0 } else { a.1.1 };
    let max = all.iter().map(logd).fold(f64::NEG_INFINITY, f64::max);
    all.iter().filter(|a| logd(a) >= max - 30.0).count()
}

/// `n` uniform nodes covering where posterior `which` (0: with, 1: without discrepancy) of the
/// sorted evaluated nodes `all` has mass (log density within 30 of the maximum), padded by
/// the spacing to the neighbouring evaluated nodes and clipped to `[lo, hi]`.
fn zoom_nodes(all: &[(f64, (f64, f64))], which: usize, n: usize, (lo, hi): (f64, f64)) -> Vec<f64> {
    let logd = |a: &(f64, (f64, f64))| if which == 0 { a.1.0 } else { a.1.1 };
    let max = all.iter().map(logd).fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() {
        return Vec::new();
    }
    let live: Vec<usize> = (0..all.len())
        .filter(|&i| logd(&all[i]) >= max - 30.0)
        .collect();
    let (first, last) = (live[0], live[live.len() - 1]);
    let a = if first > 0 { all[first - 1].0 } else { lo };
    let b = if last + 1 < all.len() {
        all[last + 1].0
    } else {
        hi
    };
    let (a, b) = (a.max(lo), b.min(hi));
    (0..n)
        .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
        .collect()
}
