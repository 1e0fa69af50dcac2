//! What Module 4 needs of the marginal mode: the coefficients' posterior at new inputs.

use super::{Covariance, LowRank, MarginalFit, MarginalNode, supported_basis};
use crate::error::{BamudiError, Result};
use crate::surrogate::training::LinearParts;
use nalgebra::{DMatrix, DVector};

/// The factored covariance of a marginal-mode calibration and its (supported) basis, rebuilt
/// from the stored fit rather than stored.
#[derive(Debug, Clone)]
pub struct MarginalState {
    cov: Covariance,
    l: DMatrix<f64>,
    b: DMatrix<f64>,
    /// The Woodbury terms of `V' = V + J Jᵀ` with declared tolerances.
    tolerance_terms: Option<ToleranceTerms>,
}

/// The declared tolerances' columns `J` as the coefficients' posterior needs them.
#[derive(Debug, Clone)]
struct ToleranceTerms {
    /// `Qᵀ Wᵀ J` ([`Spectrum::project`](super::Spectrum::project)), for `s Cy V⁻¹ J`.
    projected: DMatrix<f64>,
    /// `V⁻¹ J` (`N_s x P`).
    vj: DMatrix<f64>,
    /// `M⁻¹ = (I + Jᵀ V⁻¹ J)⁻¹` (`P x P`).
    m_inv: DMatrix<f64>,
}

/// The `θ` nodes' data in the form the coefficients' posterior mean at new inputs needs
/// ([`MarginalState::node_terms`]), every node's two columns side by side.
#[derive(Debug, Clone)]
pub struct NodeTerms {
    /// `Qᵀ Wᵀ [c_j a_j]` for every node `j` (`2 n` columns).
    projected: DMatrix<f64>,
    /// With declared tolerances: `M⁻¹ Jᵀ V⁻¹ [c_j a_j]` (`P x 2 n`).
    tolerance: Option<DMatrix<f64>>,
}

/// The prior covariances between the coefficients at one input and at the experiments
/// ([`MarginalState::cross_cov`]).
#[derive(Debug, Clone)]
pub struct CrossCov {
    /// `C_k(x, x_i)` (`N_e x K`).
    pub cmat: DMatrix<f64>,
    /// Their coordinates `G` in the columns of `W` (`R x K`): `cmat[:, k] ⊗ b_k = W G[:, k]`.
    pub coords: DMatrix<f64>,
    /// `G` in the spectrum's eigenbasis ([`Spectrum::coordinates`]), computed once for the
    /// mean, the covariance and the tolerances' terms at this input.
    ///
    /// [`Spectrum::coordinates`]: super::Spectrum::coordinates
    projected: DMatrix<f64>,
}

impl MarginalState {
    /// Rebuilds the factorisation of `V` for the experiments `x`, the model's parts and `σ²`.
    pub fn new(
        fit: &MarginalFit,
        x: &DMatrix<f64>,
        parts: &LinearParts,
        sigma2: f64,
    ) -> Result<Self> {
        let (l, b) = supported_basis(parts, fit.support.as_deref(), fit.orthonormal_basis)?;
        let lr = LowRank::new(&fit.priors, x, &fit.amplitudes, &b)?;
        if let Some(j) = &fit.tolerance_columns
            && j.nrows() != lr.n_obs()
        {
            return Err(BamudiError::dim(
                "tolerance columns of the marginal fit (rows) vs the observations",
                lr.n_obs(),
                j.nrows(),
            ));
        }
        let cov = Covariance::new(lr, fit.amplitude, sigma2)?
            .with_tolerances(fit.tolerance_columns.clone());
        let tolerance_terms = match (cov.tolerance_solve()?, cov.tolerance_columns()) {
            (Some((vj, m)), Some(j)) => Some(ToleranceTerms {
                projected: cov.spectrum.project(&cov.lr, j),
                m_inv: m.solve(&DMatrix::identity(j.ncols(), j.ncols()))?,
                vj,
            }),
            _ => None,
        };
        Ok(Self {
            cov,
            l,
            b,
            tolerance_terms,
        })
    }

    /// The prior covariances between the coefficients at `x` (scales `ax`) and at the
    /// experiments, consistent with the truncated prior the data were conditioned on
    /// ([`LowRank`] keeps each kernel matrix's leading eigen-pairs): each coefficient's
    /// correlation part projected onto its kept eigenvectors, its level part exact
    /// ([`LowRank::factor_coordinates`]).
    pub fn cross_cov(
        &self,
        fit: &MarginalFit,
        x: &[f64],
        ax: &[f64],
        experiments: &DMatrix<f64>,
    ) -> CrossCov {
        let lr = &self.cov.lr;
        let n_e = experiments.nrows();
        let rows: Vec<Vec<f64>> = (0..n_e)
            .map(|i| experiments.row(i).iter().copied().collect())
            .collect();
        let mut cross = CrossCov {
            cmat: DMatrix::zeros(n_e, fit.priors.len()),
            coords: DMatrix::zeros(lr.rank(), fit.priors.len()),
            projected: DMatrix::zeros(0, 0),
        };
        for (k, prior) in fit.priors.iter().enumerate() {
            let scale = |i: usize| ax[k] * fit.amplitudes[(i, k)];
            let corr = DVector::from_fn(n_e, |i, _| scale(i) * prior.correlation(x, &rows[i]));
            let level = (prior.level_variance > 0.0).then(|| ax[k] * prior.level_variance.sqrt());
            let g = lr.factor_coordinates(k, &corr, level);
            let (f, offset) = lr.factor(k);
            cross.cmat.set_column(k, &(f * &g));
            cross
                .coords
                .view_mut((offset, k), (g.len(), 1))
                .copy_from(&g);
        }
        cross.projected = self.cov.spectrum.coordinates(lr, &cross.coords);
        cross
    }

    /// The factored marginal covariance `V` of the observations.
    pub(crate) fn covariance(&self) -> &Covariance {
        &self.cov
    }

    /// The discrepancy basis `L` and `B = A L` restricted to the support (`C N_u x K`,
    /// `N_o x K`).
    pub fn basis(&self) -> (&DMatrix<f64>, &DMatrix<f64>) {
        (&self.l, &self.b)
    }

    /// Posterior covariance of the coefficients at `x` given the data (`K x K`; the same at
    /// every `θ` and `ρ`): `s P − s² Cy V'⁻¹ Cyᵀ` (`V' = V + J Jᵀ` with declared tolerances), with `P` the prior correlation at `x`
    /// scaled by `ax`, `Cy` the prior covariance between the coefficients at `x` and the
    /// observations, from `cross` ([`cross_cov`](Self::cross_cov): consistent with the
    /// truncated prior the data were conditioned on).
    ///
    /// `s² Cy V⁻¹ Cyᵀ` is taken from the coordinates `G` of `Cᵀ = W G` in the eigenbasis of
    /// `W` ([`Spectrum::explained`]), a sum of non-negative terms. Woodbury's form
    /// `(C Cᵀ − t zᵀ (I + tΛ)⁻¹ z) / σ²`, used before, subtracts two terms up to `tλ_max` times
    /// larger than their difference, and it took `C` from the exact kernel, whose part outside
    /// the span of `W` (the truncated eigen-directions) the data were never conditioned on
    /// and which it amplified by `t`. With informative data the result was grossly
    /// indefinite (smallest eigenvalue −7.3e13 against a largest 5.9e13 on an FE-gate record
    /// with thermal strain, which stopped `bamudi close-loop`). Now the joint prior of `α(x)`
    /// and the data is that of the truncated process (correlation part: the Nyström inequality
    /// `k(x,x) ≥ k(x,X) U Λ⁻¹ Uᵀ k(X,x)`; level part: exact), so in exact arithmetic the
    /// result is a posterior covariance: positive semi-definite and below the prior.
    ///
    /// [`Spectrum::explained`]: super::Spectrum::explained
    pub fn coefficient_cov(
        &self,
        fit: &MarginalFit,
        x: &[f64],
        ax: &[f64],
        cross: &CrossCov,
    ) -> DMatrix<f64> {
        let (cov, s) = (&self.cov, fit.amplitude);
        let k = fit.priors.len();
        // s² Cy V⁻¹ Cyᵀ, without Woodbury's cancellation (see above)
        let mut explained = cov.spectrum.explained_of(&cross.projected, cov.t()) * s;
        if let Some(tol) = &self.tolerance_terms {
            // Woodbury: s² Cy V'⁻¹ Cyᵀ = s² Cy V⁻¹ Cyᵀ − D M⁻¹ Dᵀ, D = s Cy V⁻¹ J
            let d = self.cy_vinv_j(tol, cross);
            explained -= &d * &tol.m_inv * d.transpose();
        }
        let prior = DMatrix::from_fn(k, k, |i, j| match i == j {
            true => ax[i] * ax[i] * fit.priors[i].cov(x, x),
            false => 0.0,
        });
        prior * s - explained
    }

    /// With declared tolerances, their deviations' joint posterior with the coefficients at
    /// `x` (`cross` from [`cross_cov`](Self::cross_cov)): `Cov(α(x), η | y) = −s Cy V'⁻¹ J =
    /// −(s Cy V⁻¹ J) M⁻¹` (`K x P`; the prior has no covariance between the two) and
    /// `Var(η | y) = M⁻¹` (`P x P`). `None` when none were declared.
    pub fn tolerance_cross(&self, cross: &CrossCov) -> Option<(DMatrix<f64>, &DMatrix<f64>)> {
        let tol = self.tolerance_terms.as_ref()?;
        let d = self.cy_vinv_j(tol, cross);
        Some((-(d * &tol.m_inv), &tol.m_inv))
    }

    /// `s Cy V⁻¹ J` (`K x P`) in the eigenbasis ([`Spectrum::explained_cross`]).
    ///
    /// [`Spectrum::explained_cross`]: super::Spectrum::explained_cross
    fn cy_vinv_j(&self, tol: &ToleranceTerms, cross: &CrossCov) -> DMatrix<f64> {
        let cov = &self.cov;
        cov.spectrum
            .explained_cross_of(&cross.projected, &tol.projected, cov.t())
    }

    /// The nodes' residual columns `c = y − b(θ)` and `a = A g(θ)` projected on the
    /// eigenbasis, and with declared tolerances `M⁻¹ Jᵀ V⁻¹ [c a]`: computed once, used at
    /// every input by [`coefficient_means`](Self::coefficient_means). An error when a node's
    /// columns do not have one entry per observation (an edited calibration file).
    pub fn node_terms(&self, nodes: &[MarginalNode]) -> Result<NodeTerms> {
        let n_s = self.cov.lr.n_obs();
        let mut cols = Vec::with_capacity(2 * nodes.len());
        for (j, node) in nodes.iter().enumerate() {
            if let Some((what, len)) = node.column_mismatch(n_s) {
                return Err(BamudiError::dim(
                    format!("column `{what}` of marginal node {j} vs the observations"),
                    n_s,
                    len,
                ));
            }
            cols.extend([node.c.clone(), node.a.clone()]);
        }
        let ca = match cols.is_empty() {
            true => DMatrix::zeros(n_s, 0),
            false => DMatrix::from_columns(&cols),
        };
        let tolerance = self
            .tolerance_terms
            .as_ref()
            .map(|tol| &tol.m_inv * tol.vj.tr_mul(&ca));
        Ok(NodeTerms {
            projected: self.cov.spectrum.project(&self.cov.lr, &ca),
            tolerance,
        })
    }

    /// The coefficients' posterior mean at `x` given each node `j` and its `ρ_j`, and its
    /// derivative in `ρ` (`K` each): `s Cy V'⁻¹ (c_j − ρ_j a_j)` from [`NodeTerms`] and
    /// `cross` ([`cross_cov`](Self::cross_cov)), in the eigenbasis
    /// ([`Spectrum::explained_cross`], one product for all nodes). With informative data the
    /// coefficients' means can be large and cancel in `B α` (more coefficients than gauges),
    /// so `V⁻¹ (c − ρ a)` by Woodbury's subtraction, used before, was not accurate enough (on
    /// an hourly FE-gate record with thermal strain, `t λ_max` 5e13, it put predictions
    /// 3e4 µε off data of 1e2 µε).
    ///
    /// [`Spectrum::explained_cross`]: super::Spectrum::explained_cross
    pub fn coefficient_means(
        &self,
        cross: &CrossCov,
        terms: &NodeTerms,
        rhos: &[f64],
    ) -> Vec<(DVector<f64>, DVector<f64>)> {
        let cov = &self.cov;
        let mut e = cov
            .spectrum
            .explained_cross_of(&cross.projected, &terms.projected, cov.t());
        if let (Some(tol), Some(jr)) = (&self.tolerance_terms, &terms.tolerance) {
            // s Cy V'⁻¹ v = s Cy V⁻¹ v − (s Cy V⁻¹ J) M⁻¹ Jᵀ V⁻¹ v
            e -= self.cy_vinv_j(tol, cross) * jr;
        }
        rhos.iter()
            .enumerate()
            .map(|(j, rho)| {
                let (c, a) = (e.column(2 * j), e.column(2 * j + 1));
                (c - a * *rho, -a)
            })
            .collect()
    }
}

impl MarginalFit {
    /// `C_k(x, x_i)` of the exact kernel for every experiment and coefficient (`N_e x K`), with
    /// the scales `ax` of the coefficients at `x`: the tests' reference for
    /// [`MarginalState::cross_cov`], which is consistent with the truncated prior.
    #[cfg(test)]
    pub(crate) fn cross_cov(
        &self,
        x: &[f64],
        ax: &[f64],
        experiments: &DMatrix<f64>,
    ) -> DMatrix<f64> {
        DMatrix::from_fn(experiments.nrows(), self.priors.len(), |i, k| {
            let xi: Vec<f64> = experiments.row(i).iter().copied().collect();
            ax[k] * self.amplitudes[(i, k)] * self.priors[k].cov(x, &xi)
        })
    }

    /// The nodes grouped into at most `max` equal-mass groups of neighbouring `θ` (scalar `θ`;
    /// each group's data mass-weighted), or as stored.
    pub(crate) fn grouped_nodes(&self, max: usize) -> Vec<MarginalNode> {
        if self.nodes.len() <= max || self.nodes.first().is_none_or(|n| n.theta.len() != 1) {
            return self.nodes.clone();
        }
        let mut order: Vec<&MarginalNode> = self.nodes.iter().collect();
        order.sort_by(|a, b| a.theta[0].total_cmp(&b.theta[0]));
        let mut groups: Vec<Vec<&MarginalNode>> = vec![Vec::new(); max];
        let mut cum = 0.0;
        for n in order {
            let g = (((cum + 0.5 * n.weight) * max as f64) as usize).min(max - 1);
            groups[g].push(n);
            cum += n.weight;
        }
        groups
            .into_iter()
            .filter(|g| !g.is_empty())
            .map(|g| merge_nodes(&g))
            .collect()
    }
}

/// The mass-weighted mean of `nodes` (their second moment of `ρ` kept).
fn merge_nodes(nodes: &[&MarginalNode]) -> MarginalNode {
    let w: f64 = nodes.iter().map(|n| n.weight).sum();
    let avg =
        |f: &dyn Fn(&MarginalNode) -> f64| nodes.iter().map(|n| n.weight * f(n)).sum::<f64>() / w;
    let avg_v = |f: &dyn Fn(&MarginalNode) -> &DVector<f64>| {
        nodes
            .iter()
            .fold(DVector::zeros(f(nodes[0]).len()), |acc, n| {
                acc + f(n) * (n.weight / w)
            })
    };
    let rho_mean = avg(&|n| n.rho_mean);
    let second = avg(&|n| n.rho_var + n.rho_mean * n.rho_mean);
    MarginalNode {
        theta: vec![avg(&|n| n.theta[0])],
        weight: w,
        rho_mean,
        rho_var: (second - rho_mean * rho_mean).max(0.0),
        c: avg_v(&|n| &n.c),
        a: avg_v(&|n| &n.a),
    }
}
