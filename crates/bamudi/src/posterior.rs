//! Posterior summaries of `θ`: exact quadrature on a grid (one-dimensional `θ`).

use crate::error::{BamudiError, Result};
use serde::{Deserialize, Serialize};

/// A one-dimensional posterior tabulated on a grid and normalised by the trapezoid rule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GridPosterior {
    /// Grid nodes (increasing).
    pub theta: Vec<f64>,
    /// Unnormalised log posterior at the nodes.
    pub log_density: Vec<f64>,
    /// Normalised density (trapezoid integral 1).
    pub density: Vec<f64>,
    /// Cumulative distribution at the nodes (trapezoid).
    pub cdf: Vec<f64>,
    /// Posterior mean.
    pub mean: f64,
    /// Posterior standard deviation.
    pub sd: f64,
    /// Node of highest density.
    pub map: f64,
    /// Equal-tailed 95% credible interval, from the CDF (linear interpolation).
    pub ci95: (f64, f64),
}

impl GridPosterior {
    /// Normalises `log_density` on `theta` (increasing, at least 3 nodes).
    ///
    /// ```
    /// use bamudi::posterior::GridPosterior;
    /// let theta: Vec<f64> = (0..401).map(|i| -8.0 + 16.0 * i as f64 / 400.0).collect();
    /// let logp: Vec<f64> = theta.iter().map(|t| -0.5 * (t - 1.0) * (t - 1.0)).collect();
    /// let post = GridPosterior::new(theta, logp).unwrap();
    /// assert!((post.mean - 1.0).abs() < 1e-6 && (post.sd - 1.0).abs() < 1e-3);
    /// assert!((post.ci95.1 - 2.96).abs() < 1e-2);
    /// ```
    pub fn new(theta: Vec<f64>, log_density: Vec<f64>) -> Result<Self> {
        let n = theta.len();
        if n < 3 || log_density.len() != n {
            return Err(BamudiError::dim(
                "grid posterior: nodes vs log densities (>= 3)",
                n.max(3),
                log_density.len(),
            ));
        }
        if theta.windows(2).any(|w| w[1] <= w[0]) {
            return Err(BamudiError::config(
                "theta grid",
                "nodes must be strictly increasing",
            ));
        }
        let max = log_density
            .iter()
            .copied()
            .filter(|v| !v.is_nan())
            .fold(f64::NEG_INFINITY, f64::max);
        if !max.is_finite() {
            return Err(BamudiError::DegeneratePosterior(
                "every grid node has zero posterior density".into(),
            ));
        }
        let un: Vec<f64> = log_density
            .iter()
            .map(|l| if l.is_nan() { 0.0 } else { (l - max).exp() })
            .collect();
        let mut cdf = vec![0.0; n];
        for i in 1..n {
            cdf[i] = cdf[i - 1] + 0.5 * (un[i] + un[i - 1]) * (theta[i] - theta[i - 1]);
        }
        let z = cdf[n - 1];
        let density: Vec<f64> = un.iter().map(|u| u / z).collect();
        cdf.iter_mut().for_each(|c| *c /= z);
        let moment = |f: &dyn Fn(f64) -> f64| -> f64 {
            (1..n)
                .map(|i| {
                    0.5 * (f(theta[i]) * density[i] + f(theta[i - 1]) * density[i - 1])
                        * (theta[i] - theta[i - 1])
                })
                .sum()
        };
        let mean = moment(&|t| t);
        let var = moment(&|t| (t - mean) * (t - mean)).max(0.0);
        let map = theta[density
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map_or(0, |(i, _)| i)];
        let quantile = |p: f64| -> f64 {
            let i = cdf.partition_point(|c| *c < p).clamp(1, n - 1);
            let (c0, c1) = (cdf[i - 1], cdf[i]);
            let w = if c1 > c0 { (p - c0) / (c1 - c0) } else { 0.0 };
            theta[i - 1] + w * (theta[i] - theta[i - 1])
        };
        let ci95 = (quantile(0.025), quantile(0.975));
        Ok(Self {
            theta,
            log_density,
            density,
            cdf,
            mean,
            sd: var.sqrt(),
            map,
            ci95,
        })
    }

    /// Probability masses of the nodes (trapezoid weights times density), summing to one.
    ///
    /// ```
    /// use bamudi::posterior::GridPosterior;
    /// let post = GridPosterior::new(vec![0.0, 1.0, 2.0], vec![0.0, 0.0, 0.0]).unwrap();
    /// assert_eq!(post.masses(), vec![0.25, 0.5, 0.25]);
    /// ```
    pub fn masses(&self) -> Vec<f64> {
        let n = self.theta.len();
        (0..n)
            .map(|i| {
                let left = if i > 0 {
                    self.theta[i] - self.theta[i - 1]
                } else {
                    0.0
                };
                let right = if i + 1 < n {
                    self.theta[i + 1] - self.theta[i]
                } else {
                    0.0
                };
                0.5 * (left + right) * self.density[i]
            })
            .collect()
    }
}
