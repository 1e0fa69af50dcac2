//! The marginal covariance `V = s W Wᵀ + σ² I` of the observations: its low-rank factor `W`
//! and the spectrum of `WᵀW` (or of `W Wᵀ`, whichever is smaller) that serves every amplitude
//! `s` and noise `σ²`.

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
    pub(crate) fn with_tolerance(
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
        Ok(Self {
            factors,
            offsets,
            b: b.clone(),
        })
    }

    /// The same kernel factors seen through another `b`.
    pub fn with_b(&self, b: &DMatrix<f64>) -> Self {
        Self {
            factors: self.factors.clone(),
            offsets: self.offsets.clone(),
            b: b.clone(),
        }
    }

    /// Number of columns `R` of `W`.
    pub fn rank(&self) -> usize {
        self.offsets.last().copied().unwrap_or(0)
    }

    /// Coordinates in coefficient `k`'s factor columns (`F_k = [U_k Λ_k^{1/2}, √c a]`) of
    /// its cross covariance with an input: the correlation part `corr` (`N_e`) projected
    /// orthogonally onto the kept eigenvectors (the columns of `U_k Λ_k^{1/2}` are orthogonal:
    /// `f_jᵀ corr / |f_j|²`), and `level` (`ax √c`) on the level's column when there is one.
    ///
    /// ```
    /// use bamudi::internals::{CoefficientPrior, LowRank};
    /// use nalgebra::{DMatrix, DVector};
    /// let x = DMatrix::from_fn(6, 1, |i, _| i as f64);
    /// let prior = CoefficientPrior {
    ///     kernel: gp::Kernel::Matern52 { ard: false },
    ///     length_scales: vec![1.0],
    ///     level_variance: 4.0,
    /// };
    /// let amps = DMatrix::from_element(6, 1, 1.0);
    /// let lr = LowRank::new(&[prior], &x, &amps, &DMatrix::from_element(1, 1, 1.0)).unwrap();
    /// let corr = DVector::from_fn(6, |i, _| (-(i as f64) / 2.0).exp());
    /// let g = lr.factor_coordinates(0, &corr, Some(2.0));
    /// let (f, _) = lr.factor(0);
    /// // every eigen-pair of this 6 x 6 matrix is kept: F g is corr plus the level part 2 √4
    /// let back = f * &g;
    /// assert!((0..6).all(|i| (back[i] - corr[i] - 4.0).abs() < 1e-9));
    /// ```
    pub fn factor_coordinates(
        &self,
        k: usize,
        corr: &DVector<f64>,
        level: Option<f64>,
    ) -> DVector<f64> {
        let f = &self.factors[k];
        let n_corr = f.ncols() - usize::from(level.is_some() && f.ncols() > 0);
        let mut g = DVector::zeros(f.ncols());
        for j in 0..n_corr {
            let col = f.column(j);
            let norm2 = col.norm_squared();
            if norm2 > 0.0 {
                g[j] = col.dot(corr) / norm2;
            }
        }
        if let (Some(v), true) = (level, n_corr < f.ncols()) {
            g[n_corr] = v;
        }
        g
    }

    /// Coefficient `k`'s factor `F_k` (`N_e x r_k`) and the row of its first column in `W`.
    pub fn factor(&self, k: usize) -> (&DMatrix<f64>, usize) {
        (&self.factors[k], self.offsets[k])
    }

    /// `B` as seen by this factor.
    pub fn b(&self) -> &DMatrix<f64> {
        &self.b
    }

    /// Number of observations `N_s`.
    pub(crate) fn n_obs(&self) -> usize {
        self.factors.first().map_or(0, DMatrix::nrows) * self.b.nrows()
    }

    /// `Wᵀ V` for the columns of `v` (`N_s x c`).
    pub(crate) fn wt(&self, v: &DMatrix<f64>) -> DMatrix<f64> {
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

impl LowRank {
    /// `W Wᵀ = Σ_k (F_k F_kᵀ) ⊗ (b_k b_kᵀ)` (`N_s x N_s`), the prior covariance of the
    /// observations at unit amplitude.
    fn outer(&self) -> DMatrix<f64> {
        let (n_e, n_o) = (self.factors[0].nrows(), self.b.nrows());
        let mut out = DMatrix::zeros(n_e * n_o, n_e * n_o);
        for (k, f) in self.factors.iter().enumerate() {
            let kk = f * f.transpose();
            let bk = self.b.column(k);
            for j in 0..n_e {
                for q in 0..n_o {
                    let mut col = out.column_mut(j * n_o + q);
                    let bq = bk[q];
                    for i in 0..n_e {
                        let kij = kk[(i, j)] * bq;
                        for p in 0..n_o {
                            col[i * n_o + p] += kij * bk[p];
                        }
                    }
                }
            }
        }
        out
    }

    /// The observations whose `Wᵀ` projection is [`project_cross`](Self::project_cross):
    /// column `c` is `cmat[:, c] ⊗ b_c` (`N_s x K`).
    fn cross_observations(&self, cmat: &DMatrix<f64>) -> DMatrix<f64> {
        let n_o = self.b.nrows();
        DMatrix::from_fn(cmat.nrows() * n_o, cmat.ncols(), |r, c| {
            cmat[(r / n_o, c)] * self.b[(r % n_o, c)]
        })
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

/// Eigenvalues of `W Wᵀ` below this fraction of the largest are null directions in the dual
/// form of [`Spectrum::explained`]: rounding puts the eigenvalues of exactly null directions
/// near `1e-16 · N_s · λ_max`, and their weight `1/λ_j` would amplify rounding. `W G` lies in
/// the span of the others, so only rounding is dropped.
pub const NULL_DIRECTION: f64 = 1e-12;

/// The spectrum of `W`: `WᵀW = Q Λ Qᵀ`, equivalently `W Wᵀ = P Λ Pᵀ` with `W Q = P Λ^{1/2}`
/// on the non-zero eigenvalues. With it, for `V = s W Wᵀ + σ² I` and `t = s/σ²`,
/// `V⁻¹ = σ⁻² (I − t W Q (I + tΛ)⁻¹ Qᵀ Wᵀ)` and `ln|V| = N_s ln σ² + Σ ln(1 + tλ)` for every
/// `s` and `σ²` at the cost of one decomposition (Woodbury's identity).
///
/// Observations enter only through their projections `Qᵀ Wᵀ v` ([`project`](Self::project)),
/// so the decomposition is of whichever Gram matrix is smaller: `WᵀW` (`R x R`) when the rank
/// `R` is at most the number of observations `N_s`, otherwise `W Wᵀ` (`N_s x N_s`, where
/// `Qᵀ Wᵀ v = Λ^{1/2} Pᵀ v`). A rough Matérn prior on 500 experiments keeps several hundred
/// directions per coefficient, so `R` can exceed `N_s` and the decomposition, cubic in its
/// size, then costs `(R/N_s)³` times more in the primal form.
///
/// ```
/// use bamudi::internals::{CoefficientPrior, LowRank, Spectrum};
/// use nalgebra::DMatrix;
/// // one rough coefficient function at 8 experiments seen by one gauge: W has 8 + 1 (level)
/// // columns against 8 observations, so the spectrum is of W Wᵀ
/// let x = DMatrix::from_fn(8, 1, |i, _| i as f64);
/// let prior = CoefficientPrior {
///     kernel: gp::Kernel::Matern52 { ard: false },
///     length_scales: vec![0.5],
///     level_variance: 1.0,
/// };
/// let (amps, b) = (DMatrix::from_element(8, 1, 2.0), DMatrix::from_element(1, 1, 1.0));
/// let lr = LowRank::new(&[prior.clone()], &x, &amps, &b).unwrap();
/// let spectrum = Spectrum::new(&lr).unwrap();
/// // V = s W Wᵀ + σ² I with s = 1, σ² = 0.5 (t = s/σ² = 2): V (V⁻¹ v) = v
/// let v = DMatrix::from_fn(8, 1, |i, _| (i as f64).sin());
/// let inv_v = spectrum.inv_apply(&lr, &v, 2.0, 0.5);
/// // amplitude² times the prior's covariance (correlation + level), plus the noise
/// let dense = prior.matrix(&x, &x) * 4.0 + DMatrix::identity(8, 8) * 0.5;
/// assert!((&dense * inv_v - &v).amax() < 1e-6);
/// ```
#[derive(Debug, Clone)]
pub struct Spectrum {
    basis: Basis,
    lambda: DVector<f64>,
}

/// The eigenvectors of [`Spectrum`] in the form that was decomposed.
#[derive(Debug, Clone)]
enum Basis {
    /// `Q` and `Qᵀ` of `WᵀW` (`R x R`). `Qᵀ` is kept so that the projection is one blocked
    /// product (nalgebra's `tr_mul` takes a dot product per entry and streams `Q` once per
    /// column of its argument).
    Primal { q: DMatrix<f64>, qt: DMatrix<f64> },
    /// `W Q = P Λ^{1/2}` and its transpose (`N_s x N_s`), from `W Wᵀ = P Λ Pᵀ`.
    Dual { wq: DMatrix<f64>, wqt: DMatrix<f64> },
}

impl Spectrum {
    /// The largest eigenvalue `λ_max` of `WᵀW` (0 without columns).
    pub fn lambda_max(&self) -> f64 {
        self.lambda.iter().copied().fold(0.0f64, f64::max)
    }

    /// Decomposes the smaller of `WᵀW` and `W Wᵀ` of `lr`.
    pub fn new(lr: &LowRank) -> Result<Self> {
        if lr.rank() > lr.n_obs() {
            Self::dual(lr)
        } else {
            Self::primal(lr)
        }
    }

    /// From `WᵀW = Q Λ Qᵀ` whatever the rank (the tests compare the two forms).
    pub(super) fn primal(lr: &LowRank) -> Result<Self> {
        let wtw = gram(&lr.factors, &lr.b, &lr.offsets);
        let eig = SymmetricEigen::new(&wtw, "WᵀW of the marginal covariance")?;
        Ok(Self {
            lambda: eig.values.map(|v| v.max(0.0)),
            basis: Basis::Primal {
                qt: eig.vectors.transpose(),
                q: eig.vectors,
            },
        })
    }

    /// From `W Wᵀ = P Λ Pᵀ`.
    fn dual(lr: &LowRank) -> Result<Self> {
        let eig = SymmetricEigen::new(&lr.outer(), "W Wᵀ of the marginal covariance")?;
        let lambda = eig.values.map(|v| v.max(0.0));
        let mut wq = eig.vectors;
        for (mut col, l) in wq.column_iter_mut().zip(lambda.iter()) {
            col *= l.sqrt();
        }
        Ok(Self {
            lambda,
            basis: Basis::Dual {
                wqt: wq.transpose(),
                wq,
            },
        })
    }

    /// `Qᵀ Wᵀ v` for the columns of `v` (`N_s x c`).
    pub fn project(&self, lr: &LowRank, v: &DMatrix<f64>) -> DMatrix<f64> {
        match &self.basis {
            Basis::Primal { qt, .. } => qt * lr.wt(v),
            Basis::Dual { wqt, .. } => wqt * v,
        }
    }

    /// `Qᵀ` times [`LowRank::project_cross`] of `cmat`.
    pub fn project_cross(&self, lr: &LowRank, cmat: &DMatrix<f64>) -> DMatrix<f64> {
        match &self.basis {
            Basis::Primal { qt, .. } => qt * lr.project_cross(cmat),
            Basis::Dual { wqt, .. } => wqt * lr.cross_observations(cmat),
        }
    }

    /// `W Q z` for the columns of `z`.
    fn expand(&self, lr: &LowRank, z: &DMatrix<f64>) -> DMatrix<f64> {
        match &self.basis {
            Basis::Primal { q, .. } => lr.w(&(q * z)),
            Basis::Dual { wq, .. } => wq * z,
        }
    }

    /// `ln |V|` for `N_s` observations.
    pub fn log_det(&self, n_obs: usize, t: f64, sigma2: f64) -> f64 {
        n_obs as f64 * sigma2.ln() + self.lambda.iter().map(|l| (t * l).ln_1p()).sum::<f64>()
    }

    /// `Z = W Q (I + tΛ)^{-1/2}` (`N_s` rows): `V⁻¹ = σ⁻² (I − t Z Zᵀ)`, whose blocks are
    /// cheap.
    pub(crate) fn whitened_factor(&self, lr: &LowRank, t: f64) -> DMatrix<f64> {
        let scale = self.lambda.map(|l| 1.0 / (1.0 + t * l).sqrt());
        match &self.basis {
            Basis::Primal { q, .. } => lr.w(&DMatrix::from_fn(q.nrows(), q.ncols(), |i, j| {
                q[(i, j)] * scale[j]
            })),
            Basis::Dual { wq, .. } => {
                DMatrix::from_fn(wq.nrows(), wq.ncols(), |i, j| wq[(i, j)] * scale[j])
            }
        }
    }

    /// `(Qᵀa)ᵀ (I + tΛ)⁻¹ (Qᵀb)` from projected `qa`, `qb`.
    pub fn core(&self, qa: &DMatrix<f64>, qb: &DMatrix<f64>, t: f64) -> DMatrix<f64> {
        qa.tr_mul(&self.shrink(qb, t))
    }

    /// The coordinates `y` of cross covariances `Cᵀ = W G` in the eigenbasis; with the weights
    /// `w` of [`cross_weights`](Self::cross_weights), `s Gᵀ Wᵀ V⁻¹ v = yᵀ diag(w) (Qᵀ Wᵀ v)`
    /// for every `v` projected by [`project`](Self::project). Primal: `y = QᵀG`, `w = t/(1 + tλ)` (from
    /// `Wᵀ V⁻¹ = Q diag(1/(σ²(1 + tλ))) Qᵀ Wᵀ`). Dual: `y = Λ^{1/2} Pᵀ W G`,
    /// `w = t/(λ(1 + tλ))` over `λ_j > NULL_DIRECTION · λ_max` (`W G` lies in their span).
    pub(crate) fn coordinates(&self, lr: &LowRank, g: &DMatrix<f64>) -> DMatrix<f64> {
        match &self.basis {
            Basis::Primal { qt, .. } => qt * g,
            Basis::Dual { wqt, .. } => wqt * lr.w(g),
        }
    }

    /// The weights `w` of [`coordinates`](Self::coordinates) at `t`.
    fn cross_weights(&self, t: f64) -> DVector<f64> {
        match &self.basis {
            Basis::Primal { .. } => self.lambda.map(|l| t / (1.0 + t * l)),
            Basis::Dual { .. } => {
                let cut = NULL_DIRECTION * self.lambda_max();
                self.lambda.map(|l| match l > cut {
                    true => t / (l * (1.0 + t * l)),
                    false => 0.0,
                })
            }
        }
    }

    /// `s C V⁻¹ Cᵀ` for cross covariances `Cᵀ = W G` given by their coordinates `G`
    /// (`R x K`, [`LowRank::factor_coordinates`]): `yᵀ diag(tλ/(1+tλ)) y` with `y = QᵀG`
    /// in the primal form, `Σ_j t z_j z_jᵀ / (λ_j (1 + tλ_j))` with `z = Λ^{1/2} Pᵀ W G` in
    /// the dual one (over `λ_j > NULL_DIRECTION · λ_max`; `W G` has no part outside them).
    /// Every term is non-negative and at most `y_j²`: unlike Woodbury's
    /// `(C Cᵀ − t zᵀ(I + tΛ)⁻¹ z) / σ²`, nothing large is subtracted.
    ///
    /// ```
    /// use bamudi::internals::{CoefficientPrior, LowRank, Spectrum};
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(5, 1, |i, _| i as f64);
    /// let prior = CoefficientPrior {
    ///     kernel: gp::Kernel::Matern52 { ard: false },
    ///     length_scales: vec![1.0],
    ///     level_variance: 0.0,
    /// };
    /// let amps = DMatrix::from_element(5, 1, 1.0);
    /// let lr = LowRank::new(&[prior], &x, &amps, &DMatrix::from_element(1, 1, 1.0)).unwrap();
    /// let g = DMatrix::from_fn(lr.rank(), 1, |i, _| 1.0 / (1.0 + i as f64));
    /// let t = 3.0;
    /// // against t Gᵀ M (I + tM)⁻¹ G with M = WᵀW, solved densely
    /// let w = lr.w(&DMatrix::identity(lr.rank(), lr.rank()));
    /// let m = w.tr_mul(&w);
    /// let id = DMatrix::identity(lr.rank(), lr.rank());
    /// let dense = g.tr_mul(&(&m * t + id).lu().solve(&(&m * &g)).unwrap()) * t;
    /// let ours = Spectrum::new(&lr).unwrap().explained(&lr, &g, t);
    /// assert!((ours - dense).amax() < 1e-9);
    /// ```
    pub fn explained(&self, lr: &LowRank, g: &DMatrix<f64>, t: f64) -> DMatrix<f64> {
        self.explained_of(&self.coordinates(lr, g), t)
    }

    /// [`explained`](Self::explained) from the coordinates `y` of `G`
    /// ([`coordinates`](Self::coordinates)).
    pub(crate) fn explained_of(&self, y: &DMatrix<f64>, t: f64) -> DMatrix<f64> {
        let weight = self.cross_weights(t);
        // Qᵀ Wᵀ (W G): Λ y in the primal form, y itself in the dual one
        let scaled = match &self.basis {
            Basis::Primal { .. } => DMatrix::from_fn(y.nrows(), y.ncols(), |j, c| {
                y[(j, c)] * weight[j] * self.lambda[j]
            }),
            Basis::Dual { .. } => {
                DMatrix::from_fn(y.nrows(), y.ncols(), |j, c| y[(j, c)] * weight[j])
            }
        };
        y.tr_mul(&scaled)
    }

    /// `s C V⁻¹ v` for cross covariances `Cᵀ = W G` (coordinates `G`, `R x K`) and
    /// observations given by their projections `qv = Qᵀ Wᵀ v` ([`project`](Self::project)):
    /// `yᵀ diag(w) qv` (`K x c`, [`coordinates`](Self::coordinates)). The
    /// coefficients' posterior mean is this with `v` the residual of the model. Unlike
    /// `s C (V⁻¹ v)` with Woodbury's `V⁻¹ v = (v − t W Q (I + tΛ)⁻¹ Qᵀ Wᵀ v)/σ²`, whose
    /// components along the well-seen directions are small differences of large terms, no
    /// term is a difference, so the mean keeps its accuracy when `t λ_max` is large and `C`
    /// lies along those very directions.
    ///
    /// ```
    /// use bamudi::internals::{CoefficientPrior, LowRank, Spectrum};
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(5, 1, |i, _| i as f64);
    /// let prior = CoefficientPrior {
    ///     kernel: gp::Kernel::Matern52 { ard: false },
    ///     length_scales: vec![1.0],
    ///     level_variance: 0.0,
    /// };
    /// let amps = DMatrix::from_element(5, 1, 1.0);
    /// let lr = LowRank::new(&[prior], &x, &amps, &DMatrix::from_element(1, 1, 1.0)).unwrap();
    /// let g = DMatrix::from_fn(lr.rank(), 1, |i, _| 1.0 / (1.0 + i as f64));
    /// let v = DMatrix::from_fn(5, 1, |i, _| (i as f64).cos());
    /// let (s, sigma2) = (3.0, 0.5);
    /// // against s (W G)ᵀ (s W Wᵀ + σ² I)⁻¹ v, solved densely
    /// let w = lr.w(&DMatrix::identity(lr.rank(), lr.rank()));
    /// let vm = &w * w.transpose() * s + DMatrix::identity(5, 5) * sigma2;
    /// let dense = (&w * &g).tr_mul(&vm.lu().solve(&v).unwrap()) * s;
    /// let spectrum = Spectrum::new(&lr).unwrap();
    /// let ours = spectrum.explained_cross(&lr, &g, &spectrum.project(&lr, &v), s / sigma2);
    /// assert!((ours - dense).amax() < 1e-9);
    /// ```
    pub fn explained_cross(
        &self,
        lr: &LowRank,
        g: &DMatrix<f64>,
        qv: &DMatrix<f64>,
        t: f64,
    ) -> DMatrix<f64> {
        self.explained_cross_of(&self.coordinates(lr, g), qv, t)
    }

    /// [`explained_cross`](Self::explained_cross) from the coordinates `y` of `G`
    /// ([`coordinates`](Self::coordinates)).
    pub(crate) fn explained_cross_of(
        &self,
        y: &DMatrix<f64>,
        qv: &DMatrix<f64>,
        t: f64,
    ) -> DMatrix<f64> {
        let weight = self.cross_weights(t);
        let scaled = DMatrix::from_fn(qv.nrows(), qv.ncols(), |j, c| qv[(j, c)] * weight[j]);
        y.tr_mul(&scaled)
    }

    /// `(I + tΛ)⁻¹ z`.
    fn shrink(&self, z: &DMatrix<f64>, t: f64) -> DMatrix<f64> {
        DMatrix::from_fn(z.nrows(), z.ncols(), |i, j| {
            z[(i, j)] / (1.0 + t * self.lambda[i])
        })
    }

    /// The Gram matrix `Uᵀ V⁻¹ U` from `qwu = Qᵀ Wᵀ U` and `uu = UᵀU`.
    pub(crate) fn gram(
        &self,
        qwu: &DMatrix<f64>,
        uu: &DMatrix<f64>,
        t: f64,
        sigma2: f64,
    ) -> DMatrix<f64> {
        (uu - self.core(qwu, qwu, t) * t) / sigma2
    }

    /// `V⁻¹ v` for the columns of `v`.
    pub fn inv_apply(&self, lr: &LowRank, v: &DMatrix<f64>, t: f64, sigma2: f64) -> DMatrix<f64> {
        let shrunk = self.shrink(&self.project(lr, v), t);
        (v - self.expand(lr, &shrunk) * t) / sigma2
    }
}
