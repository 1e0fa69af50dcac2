//! Module 3: the full-covariance Gaussian likelihood of Eq. 40 for a linear `g_o`.
//!
//! # Structure exploited
//!
//! Observations are stacked experiment-major, `s = i N_o + p`. With `B = A · blockdiag(L_c)`
//! and independent coefficient GPs, Eq. 51 reads
//!
//! `V = Σ_k C_k ⊗ (b_k b_kᵀ) + σ_ε² I`,
//!
//! where `C_k = Cov_k(X_e, X_e)` is the latent GP posterior covariance of coefficient `k` between
//! all experiments and `b_k` the `k`-th column of `B`. Because `g_u` is deterministic, **`V` does
//! not depend on `θ`** (only the mean `E_o(θ)` of Eq. 41/50 does): it is assembled and factored
//! once (dense Cholesky through [`numerics::Cholesky`], with its jitter ladder), its
//! log-determinant stored, and each `θ` costs a triangular solve, `O(N_s²)`, plus the `N_e`
//! evaluations of `g_u` for the mean. The grid solves for all nodes of a pass at once
//! ([`FactoredCovariance::log_densities`]), which reads the factor once instead of once per node.

use crate::error::{BamudiError, Result};
use nalgebra::DMatrix;
use numerics::Cholesky;
use serde::{Deserialize, Serialize};

/// A factored covariance `V = L Lᵀ` of the stacked observations.
#[derive(Debug, Clone)]
pub struct FactoredCovariance {
    factor: Cholesky,
}

/// Summary of how the factorisation went (for reports).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FactorReport {
    /// Size `N_s` of `V`.
    pub size: usize,
    /// `ln |V|`.
    pub log_det: f64,
    /// Diagonal jitter that had to be added (0 when the first Cholesky succeeded).
    pub jitter: f64,
}

/// Assembles `V = Σ_k C_k ⊗ (b_k b_kᵀ) + σ² I` (see the module docs).
pub fn assemble_covariance(
    b: &DMatrix<f64>,
    covs: &[DMatrix<f64>],
    sigma2: f64,
) -> Result<DMatrix<f64>> {
    let (n_o, k) = (b.nrows(), b.ncols());
    if covs.len() != k {
        return Err(BamudiError::dim(
            "Eq. 51: GP covariances vs columns of B",
            k,
            covs.len(),
        ));
    }
    let n_e = covs.first().map_or(0, DMatrix::nrows);
    if covs.iter().any(|c| c.nrows() != n_e || c.ncols() != n_e) {
        return Err(BamudiError::dim(
            "Eq. 51: every C_k must be N_e x N_e",
            n_e,
            0,
        ));
    }
    // outer products b_k b_kᵀ, stored [k][p * n_o + q]
    let outer: Vec<Vec<f64>> = (0..k)
        .map(|kk| {
            (0..n_o * n_o)
                .map(|pq| b[(pq / n_o, kk)] * b[(pq % n_o, kk)])
                .collect()
        })
        .collect();
    let n_s = n_e * n_o;
    Ok(DMatrix::from_fn(n_s, n_s, |s, t| {
        let (i, p) = (s / n_o, s % n_o);
        let (j, q) = (t / n_o, t % n_o);
        let mut v: f64 = (0..k)
            .map(|kk| covs[kk][(i, j)] * outer[kk][p * n_o + q])
            .sum();
        if s == t {
            v += sigma2;
        }
        v
    }))
}

impl FactoredCovariance {
    /// Factors a symmetric positive-definite `v` with [`numerics::Cholesky`]: when the plain
    /// factorisation fails, a diagonal jitter along [`numerics::JITTER_LADDER`] (times the mean
    /// diagonal) is tried in turn (a documented recovery; the jitter used is reported by
    /// [`report`](Self::report) and logged); past the ladder it is an error naming `what`.
    pub fn new(v: &DMatrix<f64>, what: &str) -> Result<Self> {
        let factor = Cholesky::new(v, what)?;
        if factor.jitter() > 0.0 {
            log::warn!(
                "{what}: Cholesky needed a diagonal jitter of {:.3e}",
                factor.jitter()
            );
        }
        Ok(Self { factor })
    }

    /// Size `N_s`.
    pub fn size(&self) -> usize {
        self.factor.size()
    }

    /// Factorisation summary.
    pub fn report(&self) -> FactorReport {
        FactorReport {
            size: self.size(),
            log_det: self.factor.log_det(),
            jitter: self.factor.jitter(),
        }
    }

    /// `ln N(r; 0, V) = −½ rᵀ V⁻¹ r − ½ ln|V| − (N_s/2) ln 2π` for a residual `r = y − E_o(θ)`
    /// (one sequential triangular solve, for a single `θ`; the grid uses
    /// [`log_densities`](Self::log_densities) for its nodes).
    pub fn log_density(&self, resid: &[f64]) -> Result<f64> {
        let n = self.size();
        if resid.len() != n {
            return Err(BamudiError::dim(
                "residual vs covariance size",
                n,
                resid.len(),
            ));
        }
        let quad = self.factor.quad_form(resid)?;
        Ok(-0.5 * quad
            - 0.5 * self.factor.log_det()
            - 0.5 * n as f64 * (2.0 * std::f64::consts::PI).ln())
    }

    /// [`log_density`](Self::log_density) of every column of `resids` (`N_s x m`, one
    /// residual per candidate `θ`), by one blocked triangular solve
    /// ([`numerics::Cholesky::quad_forms`]): the per-`θ` cost of the grid falls from a
    /// memory-bound sweep over the whole factor to a share of one cache-blocked solve. Equal to
    /// the one-by-one values up to round-off.
    ///
    /// ```
    /// use bamudi::internals::FactoredCovariance;
    /// use nalgebra::DMatrix;
    /// let v = DMatrix::from_row_slice(2, 2, &[4.0, 2.0, 2.0, 3.0]);
    /// let f = FactoredCovariance::new(&v, "V").unwrap();
    /// let r = DMatrix::from_column_slice(2, 2, &[2.0, 0.0, 0.5, -1.0]);
    /// let both = f.log_densities(&r).unwrap();
    /// assert!((both[0] - f.log_density(&[2.0, 0.0]).unwrap()).abs() < 1e-12);
    /// assert!((both[1] - f.log_density(&[0.5, -1.0]).unwrap()).abs() < 1e-12);
    /// ```
    pub fn log_densities(&self, resids: &DMatrix<f64>) -> Result<Vec<f64>> {
        let n = self.size();
        if resids.nrows() != n {
            return Err(BamudiError::dim(
                "residuals vs covariance size",
                n,
                resids.nrows(),
            ));
        }
        let constant =
            -0.5 * self.factor.log_det() - 0.5 * n as f64 * (2.0 * std::f64::consts::PI).ln();
        Ok(self
            .factor
            .quad_forms(resids)?
            .into_iter()
            .map(|quad| -0.5 * quad + constant)
            .collect())
    }
}

/// `ln N(r; 0, σ² I)`: the "without discrepancy" likelihood (Fig. 16 comparison).
pub fn iid_log_density(resid: &[f64], sigma2: f64) -> f64 {
    let n = resid.len() as f64;
    let quad: f64 = resid.iter().map(|r| r * r).sum();
    -0.5 * quad / sigma2 - 0.5 * n * (2.0 * std::f64::consts::PI * sigma2).ln()
}
