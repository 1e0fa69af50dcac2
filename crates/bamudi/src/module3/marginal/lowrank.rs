//! The marginal covariance `V = s W Wᵀ + σ² I` of the observations: its low-rank factor `W`
//! and the spectrum of `WᵀW` that serves every amplitude `s` and noise `σ²`.

use super::CoefficientPrior;
use crate::error::{BamudiError, Result};
use nalgebra::{DMatrix, DVector};
use numerics::SymmetricEigen;
use rayon::prelude::*;

/// Eigenvalues of a kernel matrix below this fraction of its largest are dropped. The largest
/// is at most the trace `N_e ā²`, so one dropped direction carries at most `N_e · 1e-7` of a
/// coefficient's prior variance `ā²`: with 500 experiments 5e-5, a discrepancy of 10 µε prior
/// sd then loses directions of at most 0.07 µε sd against 1 µε of gauge noise. The rank (and
/// the cost, cubic in it) falls several-fold from a tolerance of 1e-9 for the Matérn kernel,
/// whose spectrum decays slowly.
const EIGEN_TOL: f64 = 1e-7;

/// `Σ_k K_k ⊗ b_k b_kᵀ = W Wᵀ` with `W = [F_k ⊗ b_k]_k`, `F_k = U_k Λ_k^{1/2}` (the kept
/// eigen-pairs of the scaled kernel matrix `K_k`), observations stacked experiment-major.
#[derive(Debug, Clone)]
pub struct LowRank {
    factors: Vec<DMatrix<f64>>,
    offsets: Vec<usize>,
    b: DMatrix<f64>,
    wtw: DMatrix<f64>,
}

impl LowRank {
    /// The factor of the prior covariance of the coefficients at the rows of `x` (scales
    /// `amps[i, k]` of coefficient `k` at experiment `i`), seen through `b` (`N_o x K`).
    pub fn new(
        priors: &[CoefficientPrior],
        x: &DMatrix<f64>,
        amps: &DMatrix<f64>,
        b: &DMatrix<f64>,
    ) -> Result<Self> {
        Self::with_tolerance(priors, x, amps, b, EIGEN_TOL)
    }

    /// [`new`](Self::new) dropping the eigenvalues below `tol` times the largest.
    pub fn with_tolerance(
        priors: &[CoefficientPrior],
        x: &DMatrix<f64>,
        amps: &DMatrix<f64>,
        b: &DMatrix<f64>,
        tol: f64,
    ) -> Result<Self> {
        if priors.len() != b.ncols() || amps.ncols() != b.ncols() {
            return Err(BamudiError::dim(
                "coefficient priors and scales vs columns of B",
                b.ncols(),
                priors.len(),
            ));
        }
        let factors = priors
            .par_iter()
            .enumerate()
            .map(|(k, p)| {
                let a = amps.column(k);
                let m = p.correlation_matrix(x, x);
                let f = eigen_factor(
                    &DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| a[i] * a[j] * m[(i, j)]),
                    tol,
                )?;
                Ok(with_level(f, &a.into_owned(), p.level_variance))
            })
            .collect::<Result<Vec<_>>>()?;
        let mut offsets = vec![0];
        for f in &factors {
            offsets.push(offsets.last().copied().unwrap_or(0) + f.ncols());
        }
        let wtw = gram(&factors, b, &offsets);
        Ok(Self {
            factors,
            offsets,
            b: b.clone(),
            wtw,
        })
    }

    /// The same kernel factors seen through another `b`.
    pub fn with_b(&self, b: &DMatrix<f64>) -> Self {
        Self {
            factors: self.factors.clone(),
            offsets: self.offsets.clone(),
            b: b.clone(),
            wtw: gram(&self.factors, b, &self.offsets),
        }
    }

    /// Number of columns `R` of `W`.
    pub fn rank(&self) -> usize {
        self.offsets.last().copied().unwrap_or(0)
    }

    /// `B` as seen by this factor.
    pub fn b(&self) -> &DMatrix<f64> {
        &self.b
    }

    /// Number of observations `N_s`.
    pub fn n_obs(&self) -> usize {
        self.factors.first().map_or(0, DMatrix::nrows) * self.b.nrows()
    }

    /// `Wᵀ V` for the columns of `v` (`N_s x c`).
    pub fn wt(&self, v: &DMatrix<f64>) -> DMatrix<f64> {
        let (n_e, n_o) = (self.factors[0].nrows(), self.b.nrows());
        let mut out = DMatrix::zeros(self.rank(), v.ncols());
        for c in 0..v.ncols() {
            // the observations of column c as an N_e x N_o matrix, projected on each b_k
            let vb = DMatrix::from_fn(n_e, n_o, |i, p| v[(i * n_o + p, c)]) * &self.b;
            for (k, f) in self.factors.iter().enumerate() {
                let z = f.transpose() * vb.column(k);
                out.view_mut((self.offsets[k], c), (f.ncols(), 1))
                    .copy_from(&z);
            }
        }
        out
    }

    /// `W z` for the columns of `z` (`R x c`).
    pub fn w(&self, z: &DMatrix<f64>) -> DMatrix<f64> {
        let (n_e, n_o) = (self.factors[0].nrows(), self.b.nrows());
        let mut out = DMatrix::zeros(n_e * n_o, z.ncols());
        for c in 0..z.ncols() {
            for (k, f) in self.factors.iter().enumerate() {
                let fz = f * z.view((self.offsets[k], c), (f.ncols(), 1));
                for i in 0..n_e {
                    for p in 0..n_o {
                        out[(i * n_o + p, c)] += fz[i] * self.b[(p, k)];
                    }
                }
            }
        }
        out
    }

    /// `Wᵀ (I ⊗ diag) C` for cross covariances `cmat[i, k] = C_k(x*, x_i)` of the coefficients
    /// at a new input with those at the experiments: column `k` is the covariance of
    /// `α_k(x*)` with `Wᵀ`-projected observations (`R x K`, before the amplitude).
    pub fn project_cross(&self, cmat: &DMatrix<f64>) -> DMatrix<f64> {
        let k = self.factors.len();
        let bb = self.b.transpose() * &self.b;
        let mut z = DMatrix::zeros(self.rank(), k);
        for (kp, f) in self.factors.iter().enumerate() {
            let block = f.transpose() * cmat;
            for c in 0..k {
                let scaled = block.column(c) * bb[(kp, c)];
                z.view_mut((self.offsets[kp], c), (f.ncols(), 1))
                    .copy_from(&scaled);
            }
        }
        z
    }
}

/// The kept eigen-pairs of a symmetric positive semi-definite `k` as `U Λ^{1/2}`.
fn eigen_factor(k: &DMatrix<f64>, tol: f64) -> Result<DMatrix<f64>> {
    let eig = SymmetricEigen::new(k, "coefficient prior kernel matrix")?;
    let max = eig.values.iter().copied().fold(0.0f64, f64::max);
    let kept: Vec<usize> = (0..eig.values.len())
        .filter(|&j| eig.values[j] > tol * max)
        .collect();
    Ok(DMatrix::from_fn(k.nrows(), kept.len(), |i, c| {
        let j = kept[c];
        eig.vectors[(i, j)] * eig.values[j].sqrt()
    }))
}

/// The factor `F` of a coefficient's scaled correlation matrix with the level's column
/// `√c a` appended (`c` the level variance; none when `c = 0`): `F Fᵀ` gains `c a aᵀ`. The
/// level is a column of its own rather than a constant added before the eigen-decomposition,
/// whose tolerance (relative to the largest eigenvalue) would then drop the process's smaller
/// directions.
fn with_level(f: DMatrix<f64>, a: &DVector<f64>, level_variance: f64) -> DMatrix<f64> {
    if level_variance <= 0.0 {
        return f;
    }
    let n = f.ncols();
    let mut out = f.insert_column(n, 0.0);
    out.column_mut(n).copy_from(&(a * level_variance.sqrt()));
    out
}

/// `WᵀW` by blocks: `(F_kᵀ F_l) (b_k · b_l)`.
fn gram(factors: &[DMatrix<f64>], b: &DMatrix<f64>, offsets: &[usize]) -> DMatrix<f64> {
    let r = offsets.last().copied().unwrap_or(0);
    let mut out = DMatrix::zeros(r, r);
    for (k, fk) in factors.iter().enumerate() {
        for (l, fl) in factors.iter().enumerate().skip(k) {
            let bb = b.column(k).dot(&b.column(l));
            let block = fk.transpose() * fl * bb;
            out.view_mut((offsets[k], offsets[l]), (fk.ncols(), fl.ncols()))
                .copy_from(&block);
            out.view_mut((offsets[l], offsets[k]), (fl.ncols(), fk.ncols()))
                .copy_from(&block.transpose());
        }
    }
    out
}

/// `WᵀW = Q Λ Qᵀ`: with it, for `V = s W Wᵀ + σ² I` and `t = s/σ²`,
/// `V⁻¹ = σ⁻² (I − t W Q (I + tΛ)⁻¹ Qᵀ Wᵀ)` and `ln|V| = N_s ln σ² + Σ ln(1 + tλ)` for every
/// `s` and `σ²` at the cost of one decomposition (Woodbury's identity).
#[derive(Debug, Clone)]
pub struct Spectrum {
    q: DMatrix<f64>,
    /// `Qᵀ`, kept so that [`Spectrum::rotate`] is one blocked product (nalgebra's `tr_mul`
    /// takes a dot product per entry and streams `Q` once per column of its argument).
    qt: DMatrix<f64>,
    lambda: DVector<f64>,
}

impl Spectrum {
    /// Decomposes `WᵀW` of `lr`.
    pub fn new(lr: &LowRank) -> Result<Self> {
        let eig = SymmetricEigen::new(&lr.wtw, "WᵀW of the marginal covariance")?;
        Ok(Self {
            lambda: eig.values.map(|v| v.max(0.0)),
            qt: eig.vectors.transpose(),
            q: eig.vectors,
        })
    }

    /// `Qᵀ z`.
    pub fn rotate(&self, z: &DMatrix<f64>) -> DMatrix<f64> {
        &self.qt * z
    }

    /// `ln |V|` for `N_s` observations.
    pub fn log_det(&self, n_obs: usize, t: f64, sigma2: f64) -> f64 {
        n_obs as f64 * sigma2.ln() + self.lambda.iter().map(|l| (t * l).ln_1p()).sum::<f64>()
    }

    /// `Q (I + tΛ)^{-1/2}` (`R x R`): with it `Z = W Q (I + tΛ)^{-1/2}` gives
    /// `V⁻¹ = σ⁻² (I − t Z Zᵀ)`, whose blocks are cheap.
    pub fn scaled_basis(&self, t: f64) -> DMatrix<f64> {
        DMatrix::from_fn(self.q.nrows(), self.q.ncols(), |i, j| {
            self.q[(i, j)] / (1.0 + t * self.lambda[j]).sqrt()
        })
    }

    /// `(Qᵀa)ᵀ (I + tΛ)⁻¹ (Qᵀb)` from rotated `qa`, `qb`.
    pub fn core(&self, qa: &DMatrix<f64>, qb: &DMatrix<f64>, t: f64) -> DMatrix<f64> {
        let scaled = DMatrix::from_fn(qb.nrows(), qb.ncols(), |i, j| {
            qb[(i, j)] / (1.0 + t * self.lambda[i])
        });
        qa.tr_mul(&scaled)
    }

    /// The Gram matrix `Uᵀ V⁻¹ U` from `qwu = Qᵀ Wᵀ U` and `uu = UᵀU`.
    pub fn gram(&self, qwu: &DMatrix<f64>, uu: &DMatrix<f64>, t: f64, sigma2: f64) -> DMatrix<f64> {
        (uu - self.core(qwu, qwu, t) * t) / sigma2
    }

    /// `V⁻¹ v` for the columns of `v`.
    pub fn inv_apply(&self, lr: &LowRank, v: &DMatrix<f64>, t: f64, sigma2: f64) -> DMatrix<f64> {
        let qwv = self.rotate(&lr.wt(v));
        let scaled = DMatrix::from_fn(qwv.nrows(), qwv.ncols(), |i, j| {
            qwv[(i, j)] / (1.0 + t * self.lambda[i])
        });
        (v - lr.w(&(&self.q * scaled)) * t) / sigma2
    }
}
