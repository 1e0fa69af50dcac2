//! Module 3 with the discrepancy coefficients integrated out
//! ([`CoefficientMode::Marginal`](crate::CoefficientMode::Marginal); not in the paper): the
//! Kennedy-O'Hagan treatment of BA-MUDI's discrepancy, and the default.
//!
//! # The model
//!
//! For a linear observable model the observations of experiment `i` are
//! `y_i = ρ A g(x_i, θ) + b(x_i, θ) + B α(x_i) + ε_i`, `ε_i ~ N(0, σ² I)`. Each coefficient
//! function gets a Gaussian-process prior `α_k(x) = √s a_k(x) (z_k(x) + β_k)`: `z_k` a
//! stationary process of unit variance ([`MarginalPrior::kernel`], Matérn 5/2 by default),
//! `β_k ~ N(0, c)` an optional unknown level ([`MarginalPrior::level_variance`]; `0` by
//! default), `a_k(x)` a scale ([`CoefficientScales`]) and `s` one amplitude. Integrating `α`
//! out gives `y ~ N(ρ a(θ) + b(θ), V)` with `V = s Σ_k K_k ⊗ b_k b_kᵀ + σ² I`: the structure
//! of Eq. 51 with prior covariances in place of posterior ones.
//!
//! The default prior is **isotropic in the response's units**
//! ([`CoefficientScales::Isotropic`]): the basis supported above the gap is orthonormalised
//! in the response's own metric ([`orthonormalised`]: a unit coefficient is a correction of
//! unit root mean square), every coefficient shares one scale `a(x)` (the nominal response's
//! root mean square at `x`: the discrepancy grows with the load) and one correlation
//! function (length scales half the range the experiments span, times a fitted factor). Then
//! no direction of the correction is cheaper than another, and the posterior mean of `α(x)`
//! lies in the row space of `B` at every input: the correction is the least force that
//! explains what the gauges see, and the directions they cannot see keep their prior (mean
//! zero, the prior's band). With the earlier per-component scales (each component's range
//! from the nominal response's size) a normal-force discrepancy was partly explained by
//! tangential coefficients, and the reconstructed discrepancy was 2-11x worse than none.
//!
//! Where the model says the response is zero by construction at `θ`
//! ([`UnobservableModel::discrepancy_support`]; for the gate, the gap below `θ`), the basis
//! is zeroed ([`MarginalPrior::mask_outside_support`]): a discrepancy corrects a response
//! where there is one. The support is taken at the mode `θ̂` of the posterior and held over
//! the grid (one `B`, one factorisation); the posterior's width is far below the support's
//! resolution (a quoin cell), and the coverage study checks the result.
//!
//! # What the data identify
//!
//! `ρ` of the split `ρ g + δ` is not identified: a discrepancy along `g` is the same data as a
//! different `ρ` (Kennedy-O'Hagan's confounding), and only the discrepancy's prior chooses
//! between them. What the data fix is `ρ⊥` ([`MarginalFit::rho_projection`]), the `ρ` that
//! leaves the discrepancy's strains orthogonal to the model's (the least-squares projection of
//! Tuo & Wu; Plumlee's orthogonality in the observations' metric), and the corrected response
//! `ρ g + L α` itself. Near the gap's edge that response changes by thousands of lbf/in per
//! inch of `θ`, so `θ`'s posterior spread, not the discrepancy, sets the corrected force's
//! error there (`bamudi_gate::baselines` measures both). The measured comparison of the priors
//! tried is in `docs/results/validation.md`.
//!
//! # What is integrated, what is estimated
//!
//! * `α` (every coefficient direction, including those the gauges cannot see, and the
//!   levels `β` when `level_variance > 0`): analytically; each level is one more column of
//!   the low-rank factor.
//! * `ρ`: analytically over its uniform prior (the sampling rule's `rho_range`; [`rho`]).
//! * the declared tolerances of the system's build, when the model declares any
//!   ([`mlmodel::MultiLevelModel::with_tolerances`]): analytically, each deviation `N(0, 1)`
//!   in its standard deviations and the observables linear in it ([`nuisance`]); their
//!   posterior is reported ([`ToleranceEstimate`]).
//! * `θ`: on the grid (or by MCMC) of [`super::grid`].
//! * `σ_ε`, `s` and the length-scale factor: type-II maximum likelihood at `θ̂`, alternating
//!   with `θ̂` itself ([`HYPER_ROUNDS`]); `σ_ε` is held when configured, `s` and the factor
//!   when [`MarginalPrior::fixed`] says so (simulation-based calibration). Maximising the
//!   marginal likelihood accounts for the degrees of freedom the discrepancy uses, unlike a
//!   residual RMS. With `N_s = N_e N_o` observations their posteriors are narrow (relative sd
//!   of `σ` about `1/√(2 N_s)`); the coverage study measures what holding them costs.
//!
//! # Computation
//!
//! Each `K_k` (`N_e x N_e`) is replaced by its eigen-expansion without the eigenvalues below
//! `1e-7` of the largest ([`lowrank::LowRank`]), and `WᵀW` (`R x R`) or, when the rank `R`
//! exceeds the observations `N_s`, `W Wᵀ` (`N_s x N_s`) is decomposed once per factor
//! ([`lowrank::Spectrum`]): every `s`, `σ²` and `θ` then costs matrix-vector work.

mod lowrank;
pub mod nuisance;

mod state;

pub use lowrank::{LowRank, Spectrum};
pub use state::{MarginalState, NodeTerms};

use super::average::ModelAverage;
use super::grid::{self, LogPosteriors, coarse_nodes};
use super::likelihood::FactorReport;
use super::no_discrepancy::{self, NoDiscrepancyFit};
use super::rho::{ThetaTerms, truncated_moments};
use super::theta::{SupportPolicy, ThetaPosterior};
use super::{MarginalModeFit, ModeFit, Module3, model_rows};
use crate::error::{BamudiError, Result};
use crate::optim::Brent;
use crate::params::{CoefficientKernel, CoefficientScales, DiscrepancyPresence, MarginalPrior};
use crate::surrogate::training::{LinearParts, XContext};
use crate::surrogate::{Module2, Problem};
use mlmodel::{DiscrepancyBasis, LinearObservableModel, UnobservableModel};
use nalgebra::{DMatrix, DVector};
use nuisance::Nuisance;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::cell::RefCell;
use std::collections::HashMap;
use std::sync::RwLock;

/// The correlation function of one coefficient function `α_k(x)` (unit variance).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoefficientPrior {
    /// Module 2's kernel.
    pub kernel: gp::Kernel,
    /// Length scale per input (input units).
    pub length_scales: Vec<f64>,
    /// Prior variance of the function's unknown level, relative to the process variance
    /// ([`MarginalPrior::level_variance`]; `0` in files written before it existed).
    #[serde(default)]
    pub level_variance: f64,
}

impl CoefficientPrior {
    /// The correlation function of a Module-2 coefficient GP.
    pub fn of(model: &gp::GpModel) -> Self {
        Self {
            kernel: model.spec().0,
            length_scales: model.hyperparameters().length_scales,
            level_variance: 0.0,
        }
    }

    /// Prior covariance of `z(a) + β` and `z(b) + β`: the correlation plus the level's
    /// variance.
    pub fn cov(&self, a: &[f64], b: &[f64]) -> f64 {
        self.correlation(a, b) + self.level_variance
    }

    /// Correlation between `z(a)` and `z(b)` (the level left out).
    pub fn correlation(&self, a: &[f64], b: &[f64]) -> f64 {
        let r2: f64 = a
            .iter()
            .zip(b)
            .zip(&self.length_scales)
            .map(|((u, v), l)| ((u - v) / l).powi(2))
            .sum();
        self.kernel.correlation(r2)
    }

    /// The covariance matrix ([`cov`](Self::cov)) between the rows of `x1` and `x2`.
    pub fn matrix(&self, x1: &DMatrix<f64>, x2: &DMatrix<f64>) -> DMatrix<f64> {
        self.correlation_matrix(x1, x2)
            .add_scalar(self.level_variance)
    }

    /// The correlation matrix between the rows of `x1` and `x2` (the level left out).
    pub(crate) fn correlation_matrix(&self, x1: &DMatrix<f64>, x2: &DMatrix<f64>) -> DMatrix<f64> {
        let rows = |x: &DMatrix<f64>| -> Vec<Vec<f64>> {
            (0..x.nrows())
                .map(|i| x.row(i).iter().copied().collect())
                .collect()
        };
        let (r1, r2) = (rows(x1), rows(x2));
        DMatrix::from_fn(x1.nrows(), x2.nrows(), |i, j| {
            self.correlation(&r1[i], &r2[j])
        })
    }
}

/// The Module-3 result of the marginal mode, kept for Module 4.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MarginalFit {
    /// The coefficients' correlation functions (length scales fitted).
    pub priors: Vec<CoefficientPrior>,
    /// The amplitude `s` (type-II maximum likelihood).
    pub amplitude: f64,
    /// The factor on Module 2's length scales (type-II maximum likelihood).
    pub length_scale_factor: f64,
    /// The uniform prior of `ρ`.
    pub rho_prior: (f64, f64),
    /// Posterior mean of `ρ`.
    pub rho_mean: f64,
    /// Posterior standard deviation of `ρ`.
    pub rho_sd: f64,
    /// The identified scale of the model's response: `ρ⊥ = Σ aᵀ(y − b) / Σ aᵀa` over the
    /// experiments (`a = A g(θ)`), the `ρ` that leaves the discrepancy's strains orthogonal to
    /// the model's (the least-squares, or L2-projection, `ρ` of Tuo & Wu; Plumlee's
    /// orthogonality in the observations' metric), mixed over the `θ` posterior: mean and sd
    /// (`[0, 0]` in files written before it existed). Unlike `ρ` of the split
    /// `ρ g + δ`, which the data cannot tell from a discrepancy along `g` and which only the
    /// discrepancy's prior pins down, `ρ⊥` is fixed by the data: its sd is the gauges' noise
    /// and `θ`'s spread. The coverage study checks it against the truth's `ρ⊥`.
    #[serde(default)]
    pub rho_projection: [f64; 2],
    /// Columns `R` of the low-rank factor of the prior covariance.
    pub rank: usize,
    /// The prior scale `a_k(x_i)` of each coefficient at each experiment (`N_e x K`).
    pub amplitudes: DMatrix<f64>,
    /// The discrepancy's support weights per response point at [`support_theta`](Self::support_theta)
    /// (`None`: everywhere).
    pub support: Option<Vec<f64>>,
    /// The `θ` the support was taken at (the posterior mode).
    pub support_theta: Vec<f64>,
    /// Whether the supported basis was orthonormalised ([`CoefficientScales::Isotropic`];
    /// `false` in files written before it existed).
    #[serde(default)]
    pub orthonormal_basis: bool,
    /// The `θ` posterior's support points with what Module 4 needs at each.
    pub nodes: Vec<MarginalNode>,
    /// The declared tolerances of the system's build, integrated out, with their
    /// posterior (empty when none were declared; `nuisance`).
    #[serde(default)]
    pub tolerances: Vec<ToleranceEstimate>,
    /// Their columns `J` at [`support_theta`](Self::support_theta) (`N_s x P`), kept so that
    /// Module 4 rebuilds `V' = V + J Jᵀ`.
    #[serde(default)]
    pub tolerance_columns: Option<DMatrix<f64>>,
}

/// The posterior of one declared tolerance's deviation, in its standard deviations (prior
/// `N(0, 1)`), given the posterior mode of `θ` and `ρ`'s posterior mean (its sd leaves out
/// their spread).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ToleranceEstimate {
    /// The tolerance's name ([`mlmodel::BuildTolerance::name`]).
    pub name: String,
    /// Posterior mean (prior standard deviations).
    pub mean: f64,
    /// Posterior standard deviation (prior standard deviations; 1: the data say nothing).
    pub sd: f64,
}

/// One support point of the `θ` posterior in the marginal mode.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MarginalNode {
    /// `θ`.
    pub theta: Vec<f64>,
    /// Posterior weight.
    pub weight: f64,
    /// Mean of `ρ` given this `θ`.
    pub rho_mean: f64,
    /// Variance of `ρ` given this `θ`.
    pub rho_var: f64,
    /// `c = y − b(θ)` (`N_s`, experiment-major): with `a`, the coefficients' posterior mean
    /// at any input is `s Cy V⁻¹ (c − ρ a)` (`MarginalState::coefficient_means`). The
    /// columns themselves are stored, free of any basis; `V⁻¹ c` by Woodbury's subtraction,
    /// stored before, was not accurate enough. Missing in files of older versions (then
    /// empty, and loading says so).
    #[serde(default)]
    pub c: DVector<f64>,
    /// `a = A g(θ)` (`N_s`).
    #[serde(default)]
    pub a: DVector<f64>,
}

impl MarginalNode {
    /// The first of the columns `c`, `a` without one entry per observation (`n_s`), with its
    /// length (a calibration file edited, or saved before the nodes kept them).
    pub(crate) fn column_mismatch(&self, n_s: usize) -> Option<(&'static str, usize)> {
        [("c", &self.c), ("a", &self.a)]
            .into_iter()
            .find(|(_, v)| v.len() != n_s)
            .map(|(what, v)| (what, v.len()))
    }
}

/// Most support points stored for Module 4.
const STORED_NODES: usize = 32;

/// Rounds of (best `θ` at the hyper-parameters, support and hyper-parameters at that `θ`)
/// after the first fit at the coarse pass's best node: the hyper-parameters are fitted where
/// the posterior will be, not one coarse spacing away (where the discrepancy would have to
/// absorb the error in `θ`).
pub const HYPER_ROUNDS: usize = 2;

/// Bracket of the natural logarithm of the length-scale factor searched.
const LN_LENGTH_FACTOR: (f64, f64) = (-4.0, 6.0);

/// Half-width of the bracket of the later rounds around the last factor's logarithm (a factor
/// of e either way).
const LN_LENGTH_STEP: f64 = 1.0;

/// `B` (and `L`) with the rows of response points outside the support weighted, and with
/// `orthonormal` the supported `L` orthonormalised in the response's own metric
/// ([`orthonormalised`]).
pub fn supported_basis(
    parts: &LinearParts,
    support: Option<&[f64]>,
    orthonormal: bool,
) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
    let mut l = match support {
        None => parts.l.clone(),
        Some(w) => {
            let n_u = w.len().max(1);
            DMatrix::from_fn(parts.l.nrows(), parts.l.ncols(), |r, k| {
                parts.l[(r, k)] * w[r % n_u]
            })
        }
    };
    if orthonormal {
        l = orthonormalised(&l)?;
    } else if support.is_none() {
        return Ok((l, parts.b.clone()));
    }
    let b = &parts.a * &l;
    Ok((l, b))
}

/// Directions of the basis's Gram matrix below this fraction of its largest eigenvalue carry
/// no response (a basis function zeroed by the support): their columns are zeroed.
const GRAM_TOL: f64 = 1e-12;

/// `L G^{-1/2}` with `G = Lᵀ L / n` (`n` rows): columns orthonormal in the mean over the
/// response's points, so a unit coefficient is a correction of unit root mean square, and the
/// symmetric square root keeps each new column as close as possible to the old one (its
/// polynomial order). Directions with no response (`GRAM_TOL`) are zeroed, not inverted.
pub fn orthonormalised(l: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    let g = l.tr_mul(l) / l.nrows().max(1) as f64;
    let eig = numerics::SymmetricEigen::new(&g, "Gram matrix of the supported basis")?;
    let top = eig.values.max().max(0.0);
    let inv_sqrt = DVector::from_fn(eig.values.len(), |i, _| {
        let v = eig.values[i];
        if v > GRAM_TOL * top {
            v.sqrt().recip()
        } else {
            0.0
        }
    });
    let root = &eig.vectors * DMatrix::from_diagonal(&inv_sqrt) * eig.vectors.transpose();
    Ok(l * root)
}

/// The model rows at one `θ` as stacked vectors: `a = A g(x_i, θ)` and `c = y − b(x_i, θ)`
/// (`N_s` each, experiment-major).
#[derive(Debug, Clone)]
struct Stacked {
    ac: DMatrix<f64>,
}

/// `V⁻¹ J` and the factored `I + Jᵀ V⁻¹ J` ([`Covariance::tolerance_solve`]).
pub(crate) type TolerancesSolved = (DMatrix<f64>, numerics::Cholesky);

/// The factor of `V` with its spectrum, amplitude and noise, and the declared tolerances'
/// columns (`V' = V + J Jᵀ`; [`nuisance`]).
#[derive(Debug, Clone)]
pub(crate) struct Covariance {
    lr: LowRank,
    spectrum: Spectrum,
    s: f64,
    sigma2: f64,
    nuisance: Option<Nuisance>,
}

impl Covariance {
    pub(crate) fn new(lr: LowRank, s: f64, sigma2: f64) -> Result<Self> {
        let spectrum = Spectrum::new(&lr)?;
        Ok(Self {
            lr,
            spectrum,
            s,
            sigma2,
            nuisance: None,
        })
    }

    /// The same covariance plus `J Jᵀ` (`None`: without).
    pub(crate) fn with_tolerances(mut self, j: Option<DMatrix<f64>>) -> Self {
        self.nuisance = j.map(|j| Nuisance::new(j, &self.lr, &self.spectrum));
        self
    }

    pub(crate) fn t(&self) -> f64 {
        self.s / self.sigma2
    }

    /// The noise variance `σ²` (output units squared).
    pub(crate) fn sigma2(&self) -> f64 {
        self.sigma2
    }

    /// The declared tolerances' columns `J`, if any.
    pub(crate) fn tolerance_columns(&self) -> Option<&DMatrix<f64>> {
        self.nuisance.as_ref().map(Nuisance::columns)
    }

    /// `Z` with `V'⁻¹ = σ⁻² (I − t Z Zᵀ)` (`N_s` rows): `W Q (I + tΛ)^{-1/2}`, and with
    /// tolerances the columns `σ t^{-1/2} V⁻¹ J L⁻ᵀ` appended (`M = L Lᵀ`).
    pub(crate) fn whitened_factor(&self) -> Result<DMatrix<f64>> {
        let z = self.spectrum.whitened_factor(&self.lr, self.t());
        let Some((vj, m)) = self.tolerance_solve()? else {
            return Ok(z);
        };
        let u = m
            .l()
            .solve_lower_triangular(&vj.transpose())
            .ok_or_else(|| BamudiError::Numerical {
                context: "whitened factor of the declared tolerances".into(),
                reason: "singular Cholesky factor of I + Jᵀ V⁻¹ J".into(),
            })?
            .transpose()
            * (self.sigma2 / self.t()).sqrt();
        let mut cols: Vec<DVector<f64>> = z.column_iter().map(|c| c.into_owned()).collect();
        cols.extend(u.column_iter().map(|c| c.into_owned()));
        Ok(DMatrix::from_columns(&cols))
    }

    /// `ln |V'|`.
    fn log_det(&self) -> Result<f64> {
        let ld = self
            .spectrum
            .log_det(self.lr.n_obs(), self.t(), self.sigma2);
        match &self.nuisance {
            None => Ok(ld),
            Some(nu) => Ok(ld + nu.m(&self.spectrum, self.t(), self.sigma2)?.log_det()),
        }
    }

    /// `V⁻¹ J` and the factored `M = I + Jᵀ V⁻¹ J` of the declared tolerances (`None`: none
    /// declared): what every Woodbury form of `V'` needs.
    pub(crate) fn tolerance_solve(&self) -> Result<Option<TolerancesSolved>> {
        let Some(nu) = &self.nuisance else {
            return Ok(None);
        };
        let (t, sigma2) = (self.t(), self.sigma2);
        let vj = self.spectrum.inv_apply(&self.lr, nu.columns(), t, sigma2);
        Ok(Some((vj, nu.m(&self.spectrum, t, sigma2)?)))
    }

    /// `V'⁻¹ v` for the columns of `v`, with the tolerances' terms of
    /// [`tolerance_solve`](Self::tolerance_solve) computed once by the caller (the tests'
    /// reference for the Woodbury terms; the computations themselves avoid `V⁻¹ v`, see
    /// [`Spectrum::explained_cross`]).
    #[cfg(test)]
    fn inv_apply(
        &self,
        v: &DMatrix<f64>,
        solved: Option<&TolerancesSolved>,
    ) -> Result<DMatrix<f64>> {
        let inv = self.spectrum.inv_apply(&self.lr, v, self.t(), self.sigma2);
        match solved {
            None => Ok(inv),
            Some((vj, m)) => Ok(inv - vj * m.solve(&vj.tr_mul(v))?),
        }
    }

    /// `Uᵀ V'⁻¹ U` and `ln |V'|` at `t` and `σ²` (the hyper-parameter search's trial values)
    /// from `u`, its projection `qu` and `uu = UᵀU`.
    fn gram_at(
        &self,
        u: &DMatrix<f64>,
        qu: &DMatrix<f64>,
        uu: &DMatrix<f64>,
        t: f64,
        sigma2: f64,
    ) -> Result<(DMatrix<f64>, f64)> {
        let g = self.spectrum.gram(qu, uu, t, sigma2);
        let ld = self.spectrum.log_det(self.lr.n_obs(), t, sigma2);
        match &self.nuisance {
            None => Ok((g, ld)),
            Some(nu) => {
                let gj = nu.cross(&self.spectrum, u, qu, t, sigma2);
                nu.reduce(&self.spectrum, (g, ld), &gj, t, sigma2)
            }
        }
    }

    /// `[a c]ᵀ V'⁻¹ [a c]` and the `ρ`-integrated terms.
    fn terms(&self, st: &Stacked, rho: (f64, f64)) -> Result<ThetaTerms> {
        let qw = self.spectrum.project(&self.lr, &st.ac);
        let (g, ld) = self.gram_at(&st.ac, &qw, &st.ac.tr_mul(&st.ac), self.t(), self.sigma2)?;
        Ok(ThetaTerms::new(&g, ld, self.lr.n_obs(), rho))
    }
}

/// The log densities of the marginal mode at fixed hyper-parameters, with the model rows of
/// every `θ` evaluated cached (the coarse pass, the refinements and the grid share them).
struct MarginalLikelihood<'a, 'p, U, O> {
    p: &'a Problem<'p, U, O>,
    /// The mode's prior.
    prior: &'a MarginalPrior,
    cov: Covariance,
    y: DVector<f64>,
    cache: RwLock<HashMap<Vec<u64>, Stacked>>,
}

impl<U: UnobservableModel, O: LinearObservableModel> MarginalLikelihood<'_, '_, U, O> {
    /// `[a c]` at `θ` (cached).
    fn stacked(&self, theta: &[f64]) -> Result<Stacked> {
        let key: Vec<u64> = theta.iter().map(|t| t.to_bits()).collect();
        if let Some(s) = self.cache.read().ok().and_then(|c| c.get(&key).cloned()) {
            return Ok(s);
        }
        let rows = model_rows(self.p, theta)?;
        let n_s = self.y.len();
        let flat = |m: &DMatrix<f64>| DVector::from_iterator(n_s, m.transpose().iter().copied());
        let a = flat(&rows.ag);
        let c = &self.y - flat(&rows.b);
        let s = Stacked {
            ac: DMatrix::from_columns(&[a, c]),
        };
        if let Ok(mut cache) = self.cache.write() {
            cache.insert(key, s.clone());
        }
        Ok(s)
    }

    fn rho_range(&self) -> (f64, f64) {
        self.p.cfg.sampling.rho_range
    }

    /// The declared tolerances' columns at `θ̄` and `ρ`'s conditional mean there under the
    /// current covariance ([`nuisance`]).
    fn tolerance_columns(&self, theta: &[f64]) -> Result<Option<DMatrix<f64>>> {
        if self.p.model.tolerances.is_empty() {
            return Ok(None);
        }
        let terms = self.cov.terms(&self.stacked(theta)?, self.rho_range())?;
        let (rho, _) = truncated_moments(terms.rho_hat, terms.q2, self.rho_range());
        nuisance::tolerance_columns(self.p, theta, rho)
    }
}

impl<U: UnobservableModel, O: LinearObservableModel> LogPosteriors
    for MarginalLikelihood<'_, '_, U, O>
{
    fn log_posteriors(&self, theta: &[f64]) -> Result<(f64, f64)> {
        let lp = self.p.model.prior.ln_pdf(theta);
        if !lp.is_finite() {
            return Ok((f64::NEG_INFINITY, f64::NEG_INFINITY));
        }
        let st = self.stacked(theta)?;
        let with = lp + self.cov.terms(&st, self.rho_range())?.log_lik;
        let (a, c) = (st.ac.column(0), st.ac.column(1));
        let without = no_discrepancy::fit_at(
            a.as_slice(),
            c.as_slice(),
            self.rho_range(),
            self.p.cfg.sigma_eps,
        );
        Ok((with, lp + without.log_lik))
    }
}

/// Module 3 in the marginal mode (see the module docs); `sigma0` (output units) starts the
/// noise estimate.
pub fn posterior<U, O>(
    p: &Problem<'_, U, O>,
    m2: &Module2,
    ctx: &[XContext],
    sigma0: f64,
    prior: &MarginalPrior,
) -> Result<Module3>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let (priors, amps) = coefficient_priors(m2, ctx, &p.exps.x, &p.model.basis, prior);
    let lr = LowRank::new(&priors, &p.exps.x, &amps, &p.parts.b)?;
    let mut lik = MarginalLikelihood {
        p,
        prior,
        cov: Covariance::new(lr, 1.0, sigma0 * sigma0)?,
        y: DVector::from_iterator(p.exps.y.len(), p.exps.y.transpose().iter().copied()),
        cache: RwLock::new(HashMap::new()),
    };
    let (fitted, theta_hat) = fit_rounds(&mut lik, &priors, &amps)?;
    log_fit(&fitted, &lik.cov, &theta_hat);
    let bounds = p.model.prior.bounds();
    let starts = |n, seed| p.model.prior.sample(n, seed);
    let (post, post_without) = grid::posteriors(&lik, &bounds, starts, p.cfg, p.observer)?;
    let nodes = node_fits(&lik, &post)?;
    let (rho_mean, rho_sd) = rho_mixture(&nodes);
    let rho_projection = projection_rho(&nodes, lik.cov.sigma2);
    let tolerances = tolerance_estimates(&lik, &theta_hat, rho_mean)?;
    // with declared tolerances the discrepancy model's evidence integrates them and the fit
    // without one does not: the comparison would not be of the discrepancy alone
    let no_tolerances = p.model.tolerances.is_empty();
    let averaged = match (prior.presence, p.cfg.no_discrepancy_fit, no_tolerances) {
        (DiscrepancyPresence::Weighed, true, true) => {
            // the amplitude and the length-scale factor, unless held
            let hyper = if prior.fixed.is_some() { 0 } else { 2 };
            ModelAverage::weigh(&post, &post_without, lik.y.len(), hyper)?
        }
        _ => None,
    };
    Ok(Module3 {
        rho_star: rho_mean,
        sigma_eps: lik.cov.sigma2.sqrt(),
        sigma_eps_estimated: p.cfg.sigma_eps.is_none(),
        covariance: FactorReport {
            size: lik.y.len(),
            log_det: lik.cov.log_det()?,
            jitter: 0.0,
        },
        no_discrepancy: match p.cfg.no_discrepancy_fit {
            true => Some(NoDiscrepancyFit::new(p, &post_without)?),
            false => None,
        },
        posterior: post,
        posterior_no_discrepancy: post_without,
        mode: ModeFit::Marginal(Box::new(MarginalModeFit {
            fit: MarginalFit {
                priors: fitted.priors,
                amplitude: lik.cov.s,
                length_scale_factor: fitted.length_factor,
                rho_prior: p.cfg.sampling.rho_range,
                rho_mean,
                rho_sd,
                rho_projection,
                rank: lik.cov.lr.rank(),
                amplitudes: amps,
                support: fitted.support,
                support_theta: theta_hat,
                orthonormal_basis: prior.scales == CoefficientScales::Isotropic,
                nodes,
                tolerances,
                tolerance_columns: lik.cov.tolerance_columns().cloned(),
            },
            averaged,
        })),
    })
}

/// The hyper-parameters, support and tolerance columns fitted in [`HYPER_ROUNDS`] + 1 rounds
/// alternating with the posterior mode `θ̂`, starting from the coarse pass's best node; `lik`
/// is left with the last round's covariance. Returns the fit and `θ̂`.
fn fit_rounds<U, O>(
    lik: &mut MarginalLikelihood<'_, '_, U, O>,
    priors: &[CoefficientPrior],
    amps: &DMatrix<f64>,
) -> Result<(Hyper, Vec<f64>)>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let p = lik.p;
    let mut theta_hat = coarse_best(lik)?;
    let (mut round, mut bracket, mut start) = (0, LN_LENGTH_FACTOR, 0.0);
    loop {
        let support = match lik.prior.mask_outside_support {
            true => p.model.unobservable.discrepancy_support(&theta_hat),
            false => None,
        };
        let orthonormal = lik.prior.scales == CoefficientScales::Isotropic;
        let (_, b) = supported_basis(&p.parts, support.as_deref(), orthonormal)?;
        let tolerances = lik.tolerance_columns(&theta_hat)?;
        let search = (bracket, start);
        let mut fitted = fit_hyper(
            lik,
            priors,
            amps,
            &b,
            &theta_hat,
            search,
            tolerances.as_ref(),
        )?;
        // later rounds move θ̂ by less than a coarse spacing: search near the last factor
        start = fitted.length_factor.ln();
        bracket = (
            (start - LN_LENGTH_STEP).max(LN_LENGTH_FACTOR.0),
            (start + LN_LENGTH_STEP).min(LN_LENGTH_FACTOR.1),
        );
        lik.cov = fitted.cov.take().ok_or_else(|| {
            BamudiError::Calibration("marginal hyper-parameter fit left no covariance".into())
        })?;
        fitted.support = support;
        if round == HYPER_ROUNDS {
            return Ok((fitted, theta_hat));
        }
        theta_hat = refine_theta(lik, &theta_hat)?;
        round += 1;
    }
}

fn log_fit(h: &Hyper, cov: &Covariance, theta_hat: &[f64]) {
    log::info!(
        "marginal Module 3 at theta {theta_hat:?}: length-scale factor {:.3}, amplitude {:.3e}, \
         sigma {:.4}, rank {}, support {:.1} of {} points",
        h.length_factor,
        cov.s,
        cov.sigma2.sqrt(),
        cov.lr.rank(),
        h.support
            .as_ref()
            .map_or(f64::NAN, |w| w.iter().sum::<f64>()),
        h.support.as_ref().map_or(0, Vec::len),
    );
}

/// The coefficients' correlation functions (Module 2's, or with
/// [`CoefficientScales::Isotropic`] one shared by all: [`shared_prior`]) and their prior
/// scales at the experiments ([`prior_scales`]).
fn coefficient_priors(
    m2: &Module2,
    ctx: &[XContext],
    x: &DMatrix<f64>,
    basis: &DiscrepancyBasis,
    prior: &MarginalPrior,
) -> (Vec<CoefficientPrior>, DMatrix<f64>) {
    let mut priors: Vec<CoefficientPrior> = match prior.scales {
        CoefficientScales::Isotropic => vec![shared_prior(m2, x); m2.gps.models.len()],
        _ => m2.gps.models.iter().map(CoefficientPrior::of).collect(),
    };
    if prior.kernel == CoefficientKernel::Matern52 {
        let ard = priors.first().is_some_and(|p| p.length_scales.len() > 1);
        priors
            .iter_mut()
            .for_each(|p| p.kernel = gp::Kernel::Matern52 { ard });
    }
    priors
        .iter_mut()
        .for_each(|p| p.level_variance = prior.level_variance);
    let rows: Vec<Vec<f64>> = ctx
        .iter()
        .map(|c| prior_scales(c, basis, prior.scales))
        .collect();
    let amps = DMatrix::from_fn(ctx.len(), priors.len(), |i, k| rows[i][k]);
    (priors, amps)
}

/// The one correlation function of every coefficient under [`CoefficientScales::Isotropic`]:
/// Module 2's kernel family with, per input, half the range the experiments span (the
/// length-scale factor fitted by type-II maximum likelihood then scales them all).
fn shared_prior(m2: &Module2, x: &DMatrix<f64>) -> CoefficientPrior {
    let kernel = m2
        .gps
        .models
        .first()
        .map_or(gp::Kernel::Matern52 { ard: true }, |m| m.spec().0);
    let length_scales = (0..x.ncols())
        .map(|j| {
            let col = x.column(j);
            let half = 0.5 * (col.max() - col.min());
            if half > 0.0 { half } else { 1.0 }
        })
        .collect();
    CoefficientPrior {
        kernel,
        length_scales,
        level_variance: 0.0,
    }
}

/// The prior standard deviations `a_k(x)` of the coefficients at one input from its context:
/// from the sampling rule's half-widths `h_k(x)`, `h_k/√3` (the sd of the uniform range the
/// estimator of Eq. 29 learns under), shared within each response component when `rule`
/// says so; or, [`CoefficientScales::Isotropic`], the nominal response's root mean square
/// for every coefficient.
pub fn prior_scales(ctx: &XContext, basis: &DiscrepancyBasis, rule: CoefficientScales) -> Vec<f64> {
    let half_width = &ctx.alpha_half_width;
    if rule == CoefficientScales::Isotropic {
        return vec![ctx.response_rms; half_width.len()];
    }
    let mut a: Vec<f64> = half_width.iter().map(|h| h / 3f64.sqrt()).collect();
    if rule == CoefficientScales::SharedPerComponent {
        for c in 0..basis.components() {
            let block = basis.coefficient_offset(c)..basis.coefficient_offset(c) + basis.terms()[c];
            let largest = a[block.clone()].iter().copied().fold(0.0f64, f64::max);
            a[block].fill(largest);
        }
    }
    a
}

/// The best `θ` of a coarse pass (the first grid pass for scalar `θ`, 16 prior draws
/// otherwise) at the starting hyper-parameters.
fn coarse_best<U, O>(lik: &MarginalLikelihood<'_, '_, U, O>) -> Result<Vec<f64>>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let (p, bounds) = (lik.p, lik.p.model.prior.bounds());
    let nodes: Vec<Vec<f64>> = match bounds[..] {
        [(lo, hi)] => {
            let n0 = coarse_nodes(p.cfg);
            (0..n0)
                .map(|i| vec![lo + (hi - lo) * i as f64 / (n0 - 1) as f64])
                .collect()
        }
        _ => p.model.prior.sample(16, p.cfg.seed),
    };
    let vals = nodes
        .par_iter()
        .map(|t| lik.log_posteriors(t).map(|v| v.0))
        .collect::<Result<Vec<_>>>()?;
    let best = (0..nodes.len())
        .max_by(|&a, &b| vals[a].total_cmp(&vals[b]))
        .ok_or_else(|| BamudiError::DegeneratePosterior("no coarse θ node".into()))?;
    Ok(nodes[best].clone())
}

/// The maximiser of the log posterior within one coarse spacing of `theta0` (scalar `θ`;
/// `θ` of other dimensions is returned as given).
fn refine_theta<U, O>(lik: &MarginalLikelihood<'_, '_, U, O>, theta0: &[f64]) -> Result<Vec<f64>>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let bounds = lik.p.model.prior.bounds();
    let [(lo, hi)] = bounds[..] else {
        return Ok(theta0.to_vec());
    };
    let h = (hi - lo) / (coarse_nodes(lik.p.cfg).max(2) - 1) as f64;
    let brent = Brent {
        bracket: ((theta0[0] - h).max(lo), (theta0[0] + h).min(hi)),
        start: theta0[0],
        rel_tol: 1e-6,
        abs_tol: 1e-3 * h,
        max_iters: 40,
    };
    let (t, _) = brent.minimise("marginal posterior mode", |t| {
        lik.log_posteriors(&[t]).map(|v| -v.0)
    })?;
    Ok(vec![t])
}

/// The hyper-parameters of the marginal covariance fitted by type-II maximum likelihood.
struct Hyper {
    priors: Vec<CoefficientPrior>,
    length_factor: f64,
    cov: Option<Covariance>,
    support: Option<Vec<f64>>,
}

/// The amplitude `s`, the noise variance `σ²` and a common factor on Module 2's length scales
/// maximising the marginal likelihood at `θ` with basis `b` (`σ` held when configured).
/// Module 2's length scales describe `α̂` fitted at `ρ*` with `θ` averaged over its prior,
/// which is smoother or rougher than the discrepancy the data need; one factor lets the data
/// say which.
fn fit_hyper<U, O>(
    lik: &MarginalLikelihood<'_, '_, U, O>,
    priors: &[CoefficientPrior],
    amps: &DMatrix<f64>,
    b: &DMatrix<f64>,
    theta: &[f64],
    (bracket, start): ((f64, f64), f64),
    tolerances: Option<&DMatrix<f64>>,
) -> Result<Hyper>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    if let Some(fixed) = &lik.prior.fixed {
        let pr = scale_lengths(priors, fixed.length_scale_factor);
        let lr = LowRank::new(&pr, &lik.p.exps.x, amps, b)?;
        // `fixed` is accepted only with σ_ε configured (`CalibrationParams::check`)
        let sigma2 = lik.p.cfg.sigma_eps.map_or(lik.cov.sigma2, |s| s * s);
        let cov =
            Covariance::new(lr, fixed.amplitude, sigma2)?.with_tolerances(tolerances.cloned());
        return Ok(Hyper {
            priors: pr,
            length_factor: fixed.length_scale_factor,
            cov: Some(cov),
            support: None,
        });
    }
    let st = lik.stacked(theta)?;
    let at = |ln_c: f64| -> Result<(Vec<CoefficientPrior>, Covariance, f64)> {
        let pr = scale_lengths(priors, ln_c.exp());
        let lr = LowRank::new(&pr, &lik.p.exps.x, amps, b)?;
        let (cov, ll) = fit_scales(
            lr,
            &st,
            lik.rho_range(),
            lik.p.cfg.sigma_eps,
            lik.cov.sigma2,
            tolerances,
        )?;
        Ok((pr, cov, ll))
    };
    let brent = Brent {
        bracket,
        start,
        rel_tol: 1e-3,
        abs_tol: 1e-2,
        max_iters: 40,
    };
    // the best evaluation is kept, so the maximiser is not factored a second time (each
    // evaluation costs the eigen-decompositions of the K_k and of WᵀW or W Wᵀ)
    let best: RefCell<Option<Evaluated>> = RefCell::new(None);
    let (ln_c, _) = brent.minimise("marginal likelihood length scales", |ln_c| {
        let (priors, cov, log_lik) = at(ln_c)?;
        let mut kept = best.borrow_mut();
        if kept.as_ref().is_none_or(|b| log_lik > b.log_lik) {
            *kept = Some(Evaluated {
                ln_c,
                priors,
                cov,
                log_lik,
            });
        }
        Ok(-log_lik)
    })?;
    let (priors, cov) = match best.into_inner() {
        Some(b) if b.ln_c.to_bits() == ln_c.to_bits() => (b.priors, b.cov),
        _ => at(ln_c).map(|(pr, cov, _)| (pr, cov))?,
    };
    Ok(Hyper {
        priors,
        length_factor: ln_c.exp(),
        cov: Some(cov),
        support: None,
    })
}

/// One evaluation of the length-scale search: the factor's logarithm, the priors and
/// covariance it gives, and their log likelihood.
struct Evaluated {
    ln_c: f64,
    priors: Vec<CoefficientPrior>,
    cov: Covariance,
    log_lik: f64,
}

/// `priors` with every length scale multiplied by `factor`.
fn scale_lengths(priors: &[CoefficientPrior], factor: f64) -> Vec<CoefficientPrior> {
    priors
        .iter()
        .map(|p| CoefficientPrior {
            length_scales: p.length_scales.iter().map(|l| l * factor).collect(),
            ..p.clone()
        })
        .collect()
}

/// Amplitude `s` and noise variance `σ²` maximising the likelihood for the factor `lr` and
/// the rows `st` (one [`Spectrum`] serves the whole search); `σ` held when
/// configured, otherwise at its closed-form maximiser for each `t = s/σ²` (the `ρ` prior's
/// truncation aside). Returns the covariance and its log likelihood.
fn fit_scales(
    lr: LowRank,
    st: &Stacked,
    rho: (f64, f64),
    sigma: Option<f64>,
    sigma2_start: f64,
    tolerances: Option<&DMatrix<f64>>,
) -> Result<(Covariance, f64)> {
    let mut cov = Covariance::new(lr, 1.0, 1.0)?.with_tolerances(tolerances.cloned());
    let qw = cov.spectrum.project(&cov.lr, &st.ac);
    let acac = st.ac.tr_mul(&st.ac);
    let n_s = cov.lr.n_obs();
    let ll_at = |t: f64, sigma2: f64| -> Result<f64> {
        let (g, ld) = cov.gram_at(&st.ac, &qw, &acac, t, sigma2)?;
        Ok(ThetaTerms::new(&g, ld, n_s, rho).log_lik)
    };
    // σ²'s closed-form maximiser without the tolerances' P columns (they take P of the N_s
    // degrees of freedom; the likelihood itself is evaluated with them)
    let sigma2_at = |t: f64| -> f64 {
        let g = cov.spectrum.gram(&qw, &acac, t, 1.0);
        let min = g[(1, 1)] - g[(0, 1)].powi(2) / g[(0, 0)].max(1e-300);
        (min / (n_s as f64 - 1.0)).max(1e-300)
    };
    let noise = |t: f64| sigma.map_or_else(|| sigma2_at(t), |s| s * s);
    let t0 = (1.0 / sigma2_start).ln();
    let brent = Brent {
        bracket: (t0 - 12.0, t0 + 12.0),
        start: t0,
        rel_tol: 1e-6,
        abs_tol: 1e-3,
        max_iters: 60,
    };
    let (ln_t, best) = brent.minimise("marginal likelihood scales", |v| {
        let t = v.exp();
        Ok(-ll_at(t, noise(t))?)
    })?;
    let (t, sigma2) = (ln_t.exp(), noise(ln_t.exp()));
    cov.s = t * sigma2;
    cov.sigma2 = sigma2;
    Ok((cov, -best))
}

/// The posterior's support points (at most [`STORED_NODES`]) with `ρ`'s conditional moments
/// and the coefficients' weight vectors.
fn node_fits<U, O>(
    lik: &MarginalLikelihood<'_, '_, U, O>,
    post: &ThetaPosterior,
) -> Result<Vec<MarginalNode>>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let cov = &lik.cov;
    let support = post.support(&SupportPolicy::default().max_nodes(STORED_NODES));
    support
        .par_iter()
        .map(|(theta, weight)| {
            let st = lik.stacked(theta)?;
            let terms = cov.terms(&st, lik.rho_range())?;
            let (rho_mean, rho_var) = truncated_moments(terms.rho_hat, terms.q2, lik.rho_range());
            Ok(MarginalNode {
                theta: theta.clone(),
                weight: *weight,
                rho_mean,
                rho_var,
                c: st.ac.column(1).into_owned(),
                a: st.ac.column(0).into_owned(),
            })
        })
        .collect()
}

/// The posterior of the declared tolerances' deviations at `θ̄` and `ρ̄`: precision
/// `M = I + Jᵀ V⁻¹ J`, mean `M⁻¹ Jᵀ V⁻¹ (c − ρ̄ a)` ([`nuisance`]).
fn tolerance_estimates<U, O>(
    lik: &MarginalLikelihood<'_, '_, U, O>,
    theta: &[f64],
    rho: f64,
) -> Result<Vec<ToleranceEstimate>>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let tols = &lik.p.model.tolerances;
    let Some((vj, m)) = lik.cov.tolerance_solve()? else {
        return Ok(Vec::new());
    };
    let st = lik.stacked(theta)?;
    let r = st.ac.column(1) - st.ac.column(0) * rho;
    let r = DMatrix::from_column_slice(r.len(), 1, r.as_slice());
    let mean = m.solve(&vj.tr_mul(&r))?;
    let var = m.solve(&DMatrix::identity(tols.len(), tols.len()))?;
    Ok(tols
        .iter()
        .enumerate()
        .map(|(p, tol)| ToleranceEstimate {
            name: tol.name.clone(),
            mean: mean[(p, 0)],
            sd: var[(p, p)].max(0.0).sqrt(),
        })
        .collect())
}

/// [`MarginalFit::rho_projection`] from the nodes' columns and the noise variance `σ²`:
/// per node `N(aᵀc / aᵀa, σ² / aᵀa)`, mixed with the nodes' weights.
fn projection_rho(nodes: &[MarginalNode], sigma2: f64) -> [f64; 2] {
    let per: Vec<(f64, f64, f64)> = nodes
        .iter()
        .map(|n| {
            let aa = n.a.norm_squared().max(1e-300);
            (n.weight, n.a.dot(&n.c) / aa, sigma2 / aa)
        })
        .collect();
    let w: f64 = per.iter().map(|p| p.0).sum::<f64>().max(1e-300);
    let mean = per.iter().map(|p| p.0 * p.1).sum::<f64>() / w;
    let second = per.iter().map(|p| p.0 * (p.2 + p.1 * p.1)).sum::<f64>() / w;
    [mean, (second - mean * mean).max(0.0).sqrt()]
}

/// Mean and sd of `ρ` over the mixture of the nodes' conditionals.
fn rho_mixture(nodes: &[MarginalNode]) -> (f64, f64) {
    let mean: f64 = nodes.iter().map(|n| n.weight * n.rho_mean).sum();
    let second: f64 = nodes
        .iter()
        .map(|n| n.weight * (n.rho_var + n.rho_mean * n.rho_mean))
        .sum();
    (mean, (second - mean * mean).max(0.0).sqrt())
}

/// The starting noise sd (output units): the configured `σ_ε`, else the sampling rule's
/// training-output noise, else the root-mean-square residual of Module 2's prior-averaged fit
/// (too large: it also carries the prior-averaging of `θ`; the search moves from there).
pub fn initial_sigma<U, O>(p: &Problem<'_, U, O>, m2: &Module2, ctx: &[XContext]) -> Result<f64>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    if let Some(s) = p.cfg.sigma_eps {
        return Ok(s);
    }
    if p.cfg.sampling.noise_sd > 0.0 {
        return Ok(p.cfg.sampling.noise_sd);
    }
    let (mean, _) = m2.gps.predict(&p.exps.x)?;
    let pred = crate::surrogate::rho::predicted_outputs(m2.rho.rho_star, &mean, ctx, &p.parts);
    let y = &p.exps.y;
    let ss: f64 = (y - pred).iter().map(|r| r * r).sum();
    Ok((ss / (y.nrows() * y.ncols()) as f64).sqrt().max(1e-12))
}

#[cfg(test)]
mod tests {
    use super::*;
    use numerics::Cholesky;

    /// With and without the level (whose column the low-rank factor appends, while the dense
    /// reference adds it to the covariance matrix).
    #[test]
    fn spectral_solves_and_log_determinant_match_the_dense_covariance() {
        for level_variance in [0.0, 2.5] {
            spectral_matches_dense(level_variance);
        }
    }

    fn spectral_matches_dense(level_variance: f64) {
        let x = DMatrix::from_fn(12, 1, |i, _| i as f64 / 3.0);
        let prior = CoefficientPrior {
            kernel: gp::Kernel::SquaredExponential { ard: false },
            length_scales: vec![1.5],
            level_variance,
        };
        let b = DMatrix::from_row_slice(3, 2, &[1.0, 0.5, -0.3, 2.0, 0.7, 0.1]);
        let amps = DMatrix::from_fn(12, 2, |i, k| 1.0 + 0.1 * (i + k) as f64);
        // the algebra (Woodbury solves, log determinant) is checked on a factor that keeps
        // every eigenvalue above 1e-14 of the largest, so the dense V is reproduced to rounding
        let lr =
            LowRank::with_tolerance(&[prior.clone(), prior.clone()], &x, &amps, &b, 1e-14).unwrap();
        let (s, sigma2) = (1.7, 0.3);
        let k = prior.matrix(&x, &x);
        let mut v = DMatrix::identity(36, 36) * sigma2;
        for c in 0..2 {
            let bb = b.column(c) * b.column(c).transpose();
            v += DMatrix::from_fn(36, 36, |r, q| {
                let (i, j) = (r / 3, q / 3);
                s * amps[(i, c)] * amps[(j, c)] * k[(i, j)] * bb[(r % 3, q % 3)]
            });
        }
        let cov = Covariance::new(lr, s, sigma2).unwrap();
        let rhs = DMatrix::from_fn(36, 2, |i, j| ((i * 7 + j * 5) % 11) as f64 - 5.0);
        let ours = cov.spectrum.inv_apply(&cov.lr, &rhs, cov.t(), sigma2);
        // the dense reference: the residual of V x = rhs, relative to rhs (a 36 x 36 system
        // with condition number about 1e3: rounding stays far below 1e-6)
        assert!((&v * &ours - &rhs).amax() < 1e-6 * rhs.amax());
        let dense = Cholesky::new(&v, "V").unwrap().log_det();
        assert!(
            (cov.log_det().unwrap() - dense).abs() < 1e-6,
            "{} vs {dense}",
            cov.log_det().unwrap()
        );
    }

    /// The dual form (`W Wᵀ`, chosen when the rank exceeds the observations) and the primal
    /// form (`WᵀW`) of one factor give the same solves, log determinant, projections and
    /// whitened factor: the marginal mode's numbers do not depend on which was decomposed. The
    /// factor here has rank up to 3 x (12 + 1 level) = 39 against 24 observations (12
    /// experiments x 2 gauges), so `new` picks the dual.
    #[test]
    fn the_dual_spectrum_agrees_with_the_primal_one() {
        let x = DMatrix::from_fn(12, 2, |i, j| {
            if j == 0 {
                i as f64 / 3.0
            } else {
                ((i * 5) % 12) as f64 / 4.0
            }
        });
        let prior = CoefficientPrior {
            kernel: gp::Kernel::Matern52 { ard: true },
            length_scales: vec![0.4, 0.7],
            level_variance: 0.5,
        };
        let b = DMatrix::from_row_slice(2, 3, &[1.0, 0.4, 0.2, -0.6, 1.3, 0.9]);
        let amps = DMatrix::from_fn(12, 3, |i, k| 1.0 + 0.05 * (i * (k + 1)) as f64);
        let priors = vec![prior; 3];
        let lr = LowRank::with_tolerance(&priors, &x, &amps, &b, 1e-14).unwrap();
        assert!(
            lr.rank() > lr.n_obs(),
            "rank {} of {}",
            lr.rank(),
            lr.n_obs()
        );
        let (dual, primal) = (Spectrum::new(&lr).unwrap(), Spectrum::primal(&lr).unwrap());
        let (t, sigma2) = (2.3, 0.4);
        let v = DMatrix::from_fn(24, 2, |i, j| ((i * 5 + j * 3) % 7) as f64 - 3.0);
        let cmat = DMatrix::from_fn(12, 3, |i, k| 0.3 + 0.1 * ((i + 2 * k) % 5) as f64);
        // every quantity is O(1)-O(100); both forms are exact up to the eigen-solver's rounding
        // (about 1e-15 of the largest eigenvalue per direction, including the near-null
        // directions of the larger Gram matrix), far below 1e-9 relative, while a wrong formula
        // (a missing Λ^{1/2}, a transpose, a wrong stacking) changes them by O(1)
        let close = |a: &DMatrix<f64>, b: &DMatrix<f64>, what: &str| {
            let err = (a - b).amax();
            assert!(err <= 1e-9 * b.amax().max(1.0), "{what}: {err:e}");
        };
        close(
            &dual.inv_apply(&lr, &v, t, sigma2),
            &primal.inv_apply(&lr, &v, t, sigma2),
            "V⁻¹ v",
        );
        let gram = |s: &Spectrum| s.gram(&s.project(&lr, &v), &v.tr_mul(&v), t, sigma2);
        close(&gram(&dual), &gram(&primal), "vᵀ V⁻¹ v");
        // mixed with the observations' projection too: a sign error in one projection would
        // cancel in a square
        let cross = |s: &Spectrum| {
            let z = s.project_cross(&lr, &cmat);
            let mut both = s.core(&z, &z, t);
            both.extend(s.core(&z, &s.project(&lr, &v), t).column_iter());
            both
        };
        close(&cross(&dual), &cross(&primal), "cross covariances");
        let zzt = |s: &Spectrum| {
            let z = s.whitened_factor(&lr, t);
            &z * z.transpose()
        };
        close(&zzt(&dual), &zzt(&primal), "Z Zᵀ");
        let (ld, lp) = (dual.log_det(24, t, sigma2), primal.log_det(24, t, sigma2));
        assert!((ld - lp).abs() < 1e-9 * lp.abs().max(1.0), "{ld} vs {lp}");
        // Module 4's explained part `t Gᵀ M (I + tM)⁻¹ G` (`M = WᵀW`) from coordinates `G`, in
        // both forms against a dense solve (the dual form weights `1/λ`: a wrong power of `Λ`
        // or a missing cut would show here)
        let r = lr.rank();
        let g = DMatrix::from_fn(r, 3, |i, k| ((i * 3 + k * 7) % 11) as f64 / 11.0 - 0.4);
        let w = lr.w(&DMatrix::identity(r, r));
        let m = w.tr_mul(&w);
        let solved = (&m * t + DMatrix::identity(r, r))
            .lu()
            .solve(&(&m * &g))
            .unwrap();
        let dense = g.tr_mul(&solved) * t;
        close(&dual.explained(&lr, &g, t), &dense, "explained (dual)");
        close(&primal.explained(&lr, &g, t), &dense, "explained (primal)");
        // and the coefficients' mean `s (W G)ᵀ V⁻¹ v` (`s = t σ²`), densely
        let vm = &w * w.transpose() * (t * sigma2) + DMatrix::identity(24, 24) * sigma2;
        let dense = (&w * &g).tr_mul(&vm.lu().solve(&v).unwrap()) * (t * sigma2);
        let mean = |s: &Spectrum| s.explained_cross(&lr, &g, &s.project(&lr, &v), t);
        close(&mean(&dual), &dense, "explained_cross (dual)");
        close(&mean(&primal), &dense, "explained_cross (primal)");
    }

    /// With declared tolerances `V' = V + J Jᵀ`: the Woodbury forms (solves, the Gram matrix
    /// with its Schur complement, the log determinant, the whitened factor with its appended
    /// columns) equal the dense `V'`, on a primal spectrum (3 gauges, 2 coefficients: rank
    /// below the 36 observations) and a dual one (2 gauges, 3 coefficients: rank up to 39
    /// against 24 observations).
    #[test]
    fn the_tolerances_woodbury_terms_match_the_dense_covariance() {
        let primal = DMatrix::from_row_slice(3, 2, &[1.0, 0.5, -0.3, 2.0, 0.7, 0.1]);
        let dual = DMatrix::from_row_slice(2, 3, &[1.0, 0.4, 0.2, -0.6, 1.3, 0.9]);
        for (b, want_dual) in [(primal, false), (dual, true)] {
            let (n_e, n_o, n_k) = (12, b.nrows(), b.ncols());
            let x = DMatrix::from_fn(n_e, 1, |i, _| i as f64 / 3.0);
            let prior = CoefficientPrior {
                kernel: gp::Kernel::Matern52 { ard: false },
                length_scales: vec![0.6],
                level_variance: 0.7,
            };
            let amps = DMatrix::from_fn(n_e, n_k, |i, k| 1.0 + 0.1 * (i + k) as f64);
            let lr =
                LowRank::with_tolerance(&vec![prior.clone(); n_k], &x, &amps, &b, 1e-14).unwrap();
            let n_s = n_o * n_e;
            assert_eq!(lr.rank() > n_s, want_dual, "rank {} of {n_s}", lr.rank());
            let (s, sigma2) = (1.3, 0.2);
            let k = prior.matrix(&x, &x);
            let mut v = DMatrix::identity(n_s, n_s) * sigma2;
            for c in 0..n_k {
                v += DMatrix::from_fn(n_s, n_s, |r, q| {
                    let (i, j) = (r / n_o, q / n_o);
                    s * amps[(i, c)] * amps[(j, c)] * k[(i, j)] * b[(r % n_o, c)] * b[(q % n_o, c)]
                });
            }
            // two tolerance columns of the size of the data's variation (O(1))
            let j = DMatrix::from_fn(n_s, 2, |r, c| ((r * (c + 2)) % 5) as f64 * 0.4 - 0.6);
            let v_tol = &v + &j * j.transpose();
            let cov = Covariance::new(lr, s, sigma2)
                .unwrap()
                .with_tolerances(Some(j));
            let dense = Cholesky::new(&v_tol, "V'").unwrap();
            let u = DMatrix::from_fn(n_s, 2, |i, c| ((i * 7 + c * 5) % 11) as f64 - 5.0);
            // systems of 24-36 with condition numbers about 1e3-1e4: rounding stays far below
            // 1e-6 relative; a dropped Woodbury term changes every quantity by O(1) (J is of
            // the size of the data)
            let ours = cov
                .inv_apply(&u, cov.tolerance_solve().unwrap().as_ref())
                .unwrap();
            assert!((&v_tol * &ours - &u).amax() < 1e-6 * u.amax(), "V'⁻¹ u");
            let qu = cov.spectrum.project(&cov.lr, &u);
            let (g, ld) = cov
                .gram_at(&u, &qu, &u.tr_mul(&u), cov.t(), sigma2)
                .unwrap();
            let g_dense = u.tr_mul(&dense.solve(&u).unwrap());
            assert!((&g - &g_dense).amax() < 1e-6 * g_dense.amax(), "Gram");
            assert!(
                (ld - dense.log_det()).abs() < 1e-6,
                "{ld} vs {}",
                dense.log_det()
            );
            assert!((cov.log_det().unwrap() - dense.log_det()).abs() < 1e-6);
            let z = cov.whitened_factor().unwrap();
            let inv = (DMatrix::identity(n_s, n_s) - &z * z.transpose() * cov.t()) / sigma2;
            assert!(
                (&v_tol * inv - DMatrix::<f64>::identity(n_s, n_s)).amax() < 1e-6,
                "whitened factor"
            );
        }
    }

    /// The model parts of a discrepancy whose basis is the identity (`L = I`, `A = B = b`).
    fn identity_basis(b: &DMatrix<f64>) -> LinearParts {
        LinearParts {
            a: b.clone(),
            l: DMatrix::identity(b.ncols(), b.ncols()),
            b: b.clone(),
        }
    }

    /// A fit with the test's priors, coefficient scales at the experiments, amplitude `s` and
    /// declared tolerances' columns (no θ nodes: the covariance tests need none).
    fn test_fit(
        priors: Vec<CoefficientPrior>,
        amplitudes: DMatrix<f64>,
        s: f64,
        tolerance_columns: Option<DMatrix<f64>>,
    ) -> MarginalFit {
        MarginalFit {
            priors,
            amplitude: s,
            length_scale_factor: 1.0,
            rho_prior: (0.0, 1.0),
            rho_mean: 0.5,
            rho_sd: 0.1,
            rho_projection: [0.5, 0.1],
            rank: 0,
            amplitudes,
            support: None,
            support_theta: vec![0.0],
            orthonormal_basis: false,
            nodes: Vec::new(),
            tolerances: Vec::new(),
            tolerance_columns,
        }
    }

    /// The coefficients' prior covariance at `xs` (diagonal: independent coefficients, every
    /// one with `prior`, scales `ax`, amplitude `s`).
    fn prior_cov_at(prior: &CoefficientPrior, xs: &[f64], ax: &[f64], s: f64) -> DMatrix<f64> {
        DMatrix::from_fn(ax.len(), ax.len(), |a, c| match a == c {
            true => s * ax[a] * ax[a] * prior.cov(xs, xs),
            false => 0.0,
        })
    }

    /// Module 4's coefficient covariance stays a covariance when the data are informative:
    /// gate-like magnitudes (coefficient scales 6e3 lbf/in, level variance 1e3, `b` entries
    /// about 0.03 µε per lbf/in, 1 µε noise, 60 experiments: `t λ_max` about 1e10). Asserted:
    /// the posterior is positive semi-definite and below the prior (the data never add
    /// variance), both to 1e-9 of the prior's size (an empirical bound, not an error analysis:
    /// the new form subtracts nothing larger than the prior). Woodbury's form `(C Cᵀ − t zᵀ(I + tΛ)⁻¹ z)/σ²`, which `coefficient_cov` used
    /// before, is computed beside it to show the check has power here: its smallest
    /// eigenvalue is −1.4e-5 of the prior's size (measured when written; the FE-gate record
    /// that stopped `bamudi close-loop` reached −1.2 of the largest).
    #[test]
    fn module4_coefficient_covariance_is_a_covariance_with_informative_data() {
        let n_e = 60;
        let x = DMatrix::from_fn(n_e, 1, |i, _| i as f64 / 10.0);
        let prior = CoefficientPrior {
            kernel: gp::Kernel::Matern52 { ard: false },
            length_scales: vec![0.8],
            level_variance: 1e3,
        };
        let b = DMatrix::from_fn(7, 3, |q, k| {
            0.03 * (((q * 3 + k * 5) % 7) as f64 / 3.0 - 1.0)
        });
        let parts = identity_basis(&b);
        let amps = DMatrix::from_fn(n_e, 3, |i, k| 6e3 * (1.0 + 0.01 * (i + k) as f64));
        let (s, sigma2) = (1.0, 1.0);
        let fit = test_fit(vec![prior.clone(); 3], amps, s, None);
        let state = MarginalState::new(&fit, &x, &parts, sigma2).unwrap();
        let mut woodbury_worst = 0.0f64;
        for xs in [0.05, 2.33, 5.9, 7.5] {
            let ax = [6e3, 5e3, 7e3];
            let cross = state.cross_cov(&fit, &[xs], &ax, &x);
            let post = state.coefficient_cov(&fit, &[xs], &ax, &cross);
            let cmat = fit.cross_cov(&[xs], &ax, &x);
            let prior_cov = prior_cov_at(&prior, &[xs], &ax, s);
            let scale = prior_cov.amax();
            let min_eig =
                |m: &DMatrix<f64>| numerics::SymmetricEigen::new(m, "m").unwrap().values[0];
            assert!(min_eig(&post) >= -1e-9 * scale, "x {xs}: {post}");
            assert!(
                min_eig(&(&prior_cov - &post)) >= -1e-9 * scale,
                "x {xs}: {post}"
            );
            // the former Woodbury form, for the record of this test's power
            let cov = state.covariance();
            let bb = b.transpose() * &b;
            let cc = DMatrix::from_fn(3, 3, |i, j| {
                cmat.column(i).dot(&cmat.column(j)) * bb[(i, j)]
            });
            let qz = cov.spectrum.project_cross(&cov.lr, &cmat);
            let q = (cc - cov.spectrum.core(&qz, &qz, cov.t()) * cov.t()) / sigma2;
            let woodbury = &prior_cov - q * (s * s);
            woodbury_worst = woodbury_worst.min(min_eig(&woodbury) / scale);
        }
        assert!(
            woodbury_worst < -1e-6,
            "the former form held here too: {woodbury_worst:e}"
        );
    }

    /// The setting of the declared-tolerance tests: a fit with two tolerance columns `J` of
    /// the data's size (they move every quantity by O(1)) and two `θ` nodes, its state at the
    /// input `xs`, and the dense references: `V' = V + J Jᵀ` factored and `Cy` (`K x N_s`,
    /// `Cy[k, (i, q)] = s cmat[i, k] B[q, k]`). Every eigen-pair of the 8 x 8 kernel matrices
    /// is kept, so the consistent cross covariances are the exact kernel's (asserted) and the
    /// dense reference applies.
    struct ToleranceSetting {
        fit: MarginalFit,
        state: MarginalState,
        cross: state::CrossCov,
        xs: [f64; 1],
        ax: [f64; 2],
        prior: CoefficientPrior,
        j: DMatrix<f64>,
        cy: DMatrix<f64>,
        inv: Cholesky,
    }

    fn tolerance_setting() -> ToleranceSetting {
        let n_e = 8;
        let x = DMatrix::from_fn(n_e, 1, |i, _| i as f64 / 2.0);
        let prior = CoefficientPrior {
            kernel: gp::Kernel::Matern52 { ard: false },
            length_scales: vec![1.3],
            level_variance: 0.5,
        };
        let b = DMatrix::from_row_slice(3, 2, &[1.0, 0.5, -0.3, 2.0, 0.7, 0.1]);
        let parts = identity_basis(&b);
        let amps = DMatrix::from_fn(n_e, 2, |i, k| 1.0 + 0.1 * (i + k) as f64);
        let (s, sigma2, n_s) = (1.3, 0.2, 3 * n_e);
        let j = DMatrix::from_fn(n_s, 2, |r, c| ((r * (c + 2)) % 5) as f64 * 0.4 - 0.6);
        let mut fit = test_fit(vec![prior.clone(); 2], amps.clone(), s, Some(j.clone()));
        let node = |c: usize, rho: f64| MarginalNode {
            theta: vec![c as f64],
            weight: 0.5,
            rho_mean: rho,
            rho_var: 0.0,
            c: DVector::from_fn(n_s, |r, _| ((r * (c + 3)) % 7) as f64 - 3.0),
            a: DVector::from_fn(n_s, |r, _| ((r * (c + 4)) % 5) as f64 * 0.5),
        };
        fit.nodes = vec![node(0, 0.3), node(1, 0.8)];
        let state = MarginalState::new(&fit, &x, &parts, sigma2).unwrap();
        let (xs, ax) = ([1.7], [1.1, 0.9]);
        let cmat = fit.cross_cov(&xs, &ax, &x);
        let cross = state.cross_cov(&fit, &xs, &ax, &x);
        assert!((&cross.cmat - &cmat).amax() < 1e-9 * cmat.amax());
        let k = prior.matrix(&x, &x);
        let mut v = DMatrix::identity(n_s, n_s) * sigma2 + &j * j.transpose();
        for c in 0..2 {
            v += DMatrix::from_fn(n_s, n_s, |r, q| {
                let (i, jj) = (r / 3, q / 3);
                s * amps[(i, c)] * amps[(jj, c)] * k[(i, jj)] * b[(r % 3, c)] * b[(q % 3, c)]
            });
        }
        let cy = DMatrix::from_fn(2, n_s, |c, r| s * cmat[(r / 3, c)] * b[(r % 3, c)]);
        let inv = Cholesky::new(&v, "V'").unwrap();
        ToleranceSetting {
            fit,
            state,
            cross,
            xs,
            ax,
            prior,
            j,
            cy,
            inv,
        }
    }

    /// Module 4's coefficient covariance with declared tolerances,
    /// `s P − s² Cy V'⁻¹ Cyᵀ` from the stored fit, equals the dense computation with
    /// `V' = V + J Jᵀ`; without the Woodbury term it would not (the test's `J` moves it by
    /// O(1) of the prior). So do the tolerances' covariance with the coefficients and their
    /// own posterior variance.
    #[test]
    fn module4_coefficient_covariance_carries_the_tolerances() {
        let ts = tolerance_setting();
        let (cy, inv, j) = (&ts.cy, &ts.inv, &ts.j);
        let ours = ts.state.coefficient_cov(&ts.fit, &ts.xs, &ts.ax, &ts.cross);
        let prior_cov = prior_cov_at(&ts.prior, &ts.xs, &ts.ax, ts.fit.amplitude);
        let dense = prior_cov - cy * inv.solve(&cy.transpose()).unwrap();
        // a 24 x 24 solve with condition number about 1e3: rounding far below 1e-8 of the prior
        assert!(
            (&ours - &dense).amax() < 1e-8 * dense.amax().max(1.0),
            "{ours} vs {dense}"
        );
        // the tolerances' posterior with the coefficients (Module 4's predictions):
        // Cov(α, η | y) = −Cy V'⁻¹ J and Var(η | y) = I − Jᵀ V'⁻¹ J, densely
        let (tol_cross, m_inv) = ts.state.tolerance_cross(&ts.cross).unwrap();
        let v_j = inv.solve(j).unwrap();
        let dense_cross = -(cy * &v_j);
        let dense_var = DMatrix::identity(2, 2) - j.transpose() * &v_j;
        assert!(
            (&tol_cross - &dense_cross).amax() < 1e-8 * dense_cross.amax().max(1.0),
            "{tol_cross} vs {dense_cross}"
        );
        assert!((m_inv - &dense_var).amax() < 1e-8, "{m_inv} vs {dense_var}");
    }

    /// Module 4's coefficient mean with declared tolerances, `s Cy V'⁻¹ (c − ρ a)` at each of
    /// two nodes and its slope in `ρ`, equals the dense solve with `V' = V + J Jᵀ` (same
    /// setting and bound as the covariance's test).
    #[test]
    fn module4_coefficient_mean_carries_the_tolerances() {
        let ts = tolerance_setting();
        let n_s = ts.j.nrows();
        let dense_solve = |v: &DVector<f64>| {
            &ts.cy
                * ts.inv
                    .solve(&DMatrix::from_column_slice(n_s, 1, v.as_slice()))
                    .unwrap()
        };
        let terms = ts.state.node_terms(&ts.fit.nodes).unwrap();
        let means = ts.state.coefficient_means(&ts.cross, &terms, &[0.3, 0.8]);
        for (n, (mean, slope)) in ts.fit.nodes.iter().zip(&means) {
            let dense_mean = dense_solve(&(&n.c - &n.a * n.rho_mean));
            let dense_slope = -dense_solve(&n.a);
            assert!(
                (mean - dense_mean.column(0)).amax() < 1e-8 * dense_mean.amax().max(1.0),
                "{mean} vs {dense_mean}"
            );
            assert!(
                (slope - dense_slope.column(0)).amax() < 1e-8 * dense_slope.amax().max(1.0),
                "{slope} vs {dense_slope}"
            );
        }
    }

    /// `B α̂` by the route Module 4 took before: `α̂_k = s Σ_i C_k(x, x_i) b_kᵀ (V⁻¹ r)_i` with
    /// `V⁻¹ r` given (Woodbury's).
    fn former_route_outputs(
        b: &DMatrix<f64>,
        cmat: &DMatrix<f64>,
        vinv_r: &DMatrix<f64>,
        s: f64,
    ) -> DVector<f64> {
        let n_o = b.nrows();
        let alpha = DVector::from_fn(b.ncols(), |k, _| {
            (0..cmat.nrows())
                .map(|j| {
                    let bv: f64 = (0..n_o).map(|q| b[(q, k)] * vinv_r[(j * n_o + q, 0)]).sum();
                    s * cmat[(j, k)] * bv
                })
                .sum::<f64>()
        });
        b * alpha
    }

    /// Module 4's coefficient mean at the experiments reproduces the in-sample fit: at every
    /// experiment `x_i`, `B α̂(x_i)` equals the smoother `s W Wᵀ V⁻¹ r` at its rows, where
    /// the smoother is `r − σ² V⁻¹ r`. The setting is the one that put an hourly FE-gate
    /// record's predictions 3e4 µε off (12 coefficients seen by 7 gauges through a `B` with
    /// weak directions, smooth priors, coefficient prior sd 2.5e6 lbf/in, 1 µε noise: `t λ_max`
    /// about 1e13), where the coefficients' means are large and cancel in `B α`. Bound:
    /// 1e-6 of the data's size (the two routes share the spectrum and differ by rounding
    /// amplified by that cancellation: 4.6e-9 measured when written). The former route,
    /// `s C (V⁻¹ r)` with Woodbury's subtraction, is computed beside it to show the check's
    /// power: it missed by 66 times the data's size when written (asserted: above 1e-3).
    #[test]
    fn module4_coefficient_mean_reproduces_the_fit_at_the_experiments() {
        let (n_e, n_o, n_k) = (80, 7, 12);
        let x = DMatrix::from_fn(n_e, 1, |i, _| {
            (i as f64 * 0.37).sin() * 3.0 + i as f64 / 40.0
        });
        let prior = CoefficientPrior {
            kernel: gp::Kernel::SquaredExponential { ard: false },
            length_scales: vec![4.0],
            level_variance: 0.3,
        };
        // gate-like B: entries about 0.01-0.1 µε per lbf/in, columns nearly dependent
        let b = DMatrix::from_fn(n_o, n_k, |q, k| {
            0.05 * ((q as f64 + 1.0) * (k as f64 + 1.0) * 0.7).cos() / (1.0 + k as f64 * 0.3)
        });
        let parts = identity_basis(&b);
        let amps = DMatrix::from_fn(n_e, n_k, |i, k| {
            2e4 * (1.0 + 0.2 * ((i + 3 * k) % 5) as f64)
        });
        let (s, sigma2) = (1.6e4, 1.0);
        // data: a smooth strain pattern of 100-1000 µε, the model's response a (ρ = 0.05)
        let c = DVector::from_fn(n_e * n_o, |r, _| {
            let (i, q) = (r / n_o, r % n_o);
            300.0 * (x[(i, 0)] * 0.5 + q as f64).cos()
                + 100.0 * q as f64
                + ((r * 7919) % 13) as f64 / 13.0
        });
        let a = DVector::from_fn(n_e * n_o, |r, _| 1000.0 * ((r % n_o) as f64 - 3.0));
        let rho = 0.05;
        let mut fit = test_fit(vec![prior; n_k], amps.clone(), s, None);
        fit.nodes = vec![MarginalNode {
            theta: vec![0.0],
            weight: 1.0,
            rho_mean: rho,
            rho_var: 0.0,
            c: c.clone(),
            a: a.clone(),
        }];
        let state = MarginalState::new(&fit, &x, &parts, sigma2).unwrap();
        let terms = state.node_terms(&fit.nodes).unwrap();
        let cov = state.covariance();
        let lambda_max = cov.spectrum.lambda_max();
        assert!(
            cov.t() * lambda_max > 1e12,
            "not the ill-conditioned setting: {lambda_max:e}"
        );
        let r = DMatrix::from_column_slice(n_e * n_o, 1, (&c - &a * rho).as_slice());
        let vinv_r = cov.spectrum.inv_apply(&cov.lr, &r, cov.t(), sigma2);
        let smoother = &r - &vinv_r * sigma2;
        let scale = r.amax();
        let (mut ours_worst, mut former_worst) = (0.0f64, 0.0f64);
        for i in 0..n_e {
            let xi = [x[(i, 0)]];
            let ax: Vec<f64> = amps.row(i).iter().copied().collect();
            let cross = state.cross_cov(&fit, &xi, &ax, &x);
            let (mean, _) = state.coefficient_means(&cross, &terms, &[rho]).remove(0);
            let fitted = &b * mean;
            let former = former_route_outputs(&b, &cross.cmat, &vinv_r, s);
            for q in 0..n_o {
                let want = smoother[(i * n_o + q, 0)];
                ours_worst = ours_worst.max((fitted[q] - want).abs() / scale);
                former_worst = former_worst.max((former[q] - want).abs() / scale);
            }
        }
        assert!(
            ours_worst < 1e-6,
            "Module 4's mean vs the fit: {ours_worst:e}"
        );
        assert!(
            former_worst > 1e-3,
            "the former route held here too: {former_worst:e}"
        );
    }

    #[test]
    fn the_supported_basis_zeroes_the_rows_outside_the_support() {
        let parts = LinearParts {
            a: DMatrix::from_row_slice(1, 4, &[1.0, 1.0, 1.0, 1.0]),
            l: DMatrix::from_element(4, 1, 1.0),
            b: DMatrix::from_element(1, 1, 4.0),
        };
        // two points, two components: the first point is outside, the second half in
        let (l, b) = supported_basis(&parts, Some(&[0.0, 0.5]), false).unwrap();
        assert_eq!(l.as_slice(), &[0.0, 0.5, 0.0, 0.5]);
        assert_eq!(b[(0, 0)], 1.0);
        let (l, _) = supported_basis(&parts, None, false).unwrap();
        assert_eq!(l, parts.l);
        // orthonormalised: the supported column rescaled to unit mean square over the 4 rows
        // (0.5² · 2 / 4 = 1/8 before, so times √8), still zero outside the support
        let (l, b) = supported_basis(&parts, Some(&[0.0, 0.5]), true).unwrap();
        let want = 0.5 * 8f64.sqrt();
        assert!((l[(1, 0)] - want).abs() < 1e-12 && l[(0, 0)] == 0.0, "{l}");
        assert!((b[(0, 0)] - 2.0 * want).abs() < 1e-12);
    }
}
