//! Declared tolerances of the system's build, integrated out (not in the paper).
//!
//! A drawing states a plate's thickness or the steel's modulus; the gate in the water differs
//! within a tolerance, and the models with it: the observable model `A`, `b` and, when the
//! build also changes the unobservable response (a stiffer plate carries the load to the
//! quoin differently), `g`. With `P` tolerances ([`mlmodel::BuildTolerance`]: the models at
//! one standard deviation either side), the observations become
//! `y = ρ A g(θ) + b + Σ_p η_p J_p + B α + ε` with `η ~ N(0, I)` and the central differences
//! `J_p = [ρ (A_p⁺ g_p⁺ − A_p⁻ g_p⁻) + b_p⁺ − b_p⁻] / 2` per standard deviation (`g_p^± = g`
//! when the tolerance leaves the unobservable model alone). Linear in `η` over that range,
//! the `η` integrate out exactly: `V' = V + J Jᵀ`. Like the discrepancy's support, `J` is
//! taken at the posterior mode `θ̄` (and `ρ`'s conditional mean `ρ̄` there) and held over the
//! `θ` grid: its change across the posterior's width is second order (`η` times the change of
//! `J` with `θ`).
//!
//! Every quantity of `V'` follows from `V`'s spectrum by Woodbury with the `P x P` matrix
//! `M = I + Jᵀ V⁻¹ J`: `Uᵀ V'⁻¹ U = Uᵀ V⁻¹ U − (Uᵀ V⁻¹ J) M⁻¹ (Jᵀ V⁻¹ U)` and
//! `ln |V'| = ln |V| + ln |M|`.

use super::lowrank::{LowRank, Spectrum};
use crate::error::{BamudiError, Result};
use crate::surrogate::Problem;
use mlmodel::{LinearObservableModel, MultiLevelModel, UnobservableModel};
use nalgebra::{DMatrix, DVector};
use numerics::Cholesky;
use rayon::prelude::*;

/// The columns `J` (`N_s x P`) of the declared tolerances and their projection on one
/// spectrum.
#[derive(Debug, Clone)]
pub(crate) struct Nuisance {
    j: DMatrix<f64>,
    /// `Qᵀ Wᵀ J`.
    qj: DMatrix<f64>,
    /// `Jᵀ J`.
    jtj: DMatrix<f64>,
}

impl Nuisance {
    /// `j` projected on `spectrum` of `lr`.
    pub(crate) fn new(j: DMatrix<f64>, lr: &LowRank, spectrum: &Spectrum) -> Self {
        Self {
            qj: spectrum.project(lr, &j),
            jtj: j.tr_mul(&j),
            j,
        }
    }

    /// The columns `J`.
    pub(crate) fn columns(&self) -> &DMatrix<f64> {
        &self.j
    }

    /// `M = I + Jᵀ V⁻¹ J` factored, at `t = s/σ²` and `σ²`.
    pub(crate) fn m(&self, spectrum: &Spectrum, t: f64, sigma2: f64) -> Result<Cholesky> {
        let p = self.j.ncols();
        let m = DMatrix::identity(p, p) + spectrum.gram(&self.qj, &self.jtj, t, sigma2);
        Ok(Cholesky::new(
            &m,
            "I + Jᵀ V⁻¹ J of the declared tolerances",
        )?)
    }

    /// `Uᵀ V⁻¹ J` from `u`, its projection `qu` and the spectrum at `t`, `σ²`.
    pub(crate) fn cross(
        &self,
        spectrum: &Spectrum,
        u: &DMatrix<f64>,
        qu: &DMatrix<f64>,
        t: f64,
        sigma2: f64,
    ) -> DMatrix<f64> {
        (u.tr_mul(&self.j) - spectrum.core(qu, &self.qj, t) * t) / sigma2
    }

    /// `Uᵀ V'⁻¹ U` and `ln |V'|` from `Uᵀ V⁻¹ U` (`g`), `ln |V|` and the cross terms
    /// `Uᵀ V⁻¹ J` (`gj`).
    pub(crate) fn reduce(
        &self,
        spectrum: &Spectrum,
        (g, log_det): (DMatrix<f64>, f64),
        gj: &DMatrix<f64>,
        t: f64,
        sigma2: f64,
    ) -> Result<(DMatrix<f64>, f64)> {
        let m = self.m(spectrum, t, sigma2)?;
        let reduced = g - gj * m.solve(&gj.transpose())?;
        Ok((reduced, log_det + m.log_det()))
    }
}

/// The columns `J` of the model's declared tolerances at `θ̄` and `ρ̄` (`N_s x P`,
/// experiment-major like the observations), or `None` when it declares none. Errors: a
/// tolerance whose matrix has another shape than the nominal model's (naming it), a failed
/// model evaluation.
pub(crate) fn tolerance_columns<U, O>(
    p: &Problem<'_, U, O>,
    theta: &[f64],
    rho: f64,
) -> Result<Option<DMatrix<f64>>>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let tols = &p.model.tolerances;
    if tols.is_empty() {
        return Ok(None);
    }
    let shape = p.parts.a.shape();
    for t in tols {
        for m in [&t.low, &t.high] {
            if m.matrix().shape() != shape {
                return Err(BamudiError::InvalidConfig {
                    name: "tolerances",
                    reason: format!(
                        "tolerance `{}`: observable matrix {:?}, the nominal model's is {shape:?}",
                        t.name,
                        m.matrix().shape()
                    ),
                });
            }
        }
    }
    let (n_e, n_o) = (p.exps.len(), p.exps.y.ncols());
    let rows = (0..n_e)
        .into_par_iter()
        .map(|i| experiment_columns(p, &p.x_row(i), theta, rho))
        .collect::<Result<Vec<_>>>()?;
    Ok(Some(DMatrix::from_fn(n_e * n_o, tols.len(), |r, c| {
        rows[r / n_o][(r % n_o, c)]
    })))
}

/// `J_p` at one experiment for every tolerance (`N_o x P`).
fn experiment_columns<U, O>(
    p: &Problem<'_, U, O>,
    x: &[f64],
    theta: &[f64],
    rho: f64,
) -> Result<DMatrix<f64>>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    Ok(columns_at(p.model, x, theta, rho)?.observed)
}

/// The declared tolerances' columns at one input: what one standard deviation of each
/// deviation adds to the outputs and to the distributed response.
#[derive(Debug, Clone)]
pub(crate) struct ToleranceColumns {
    /// `J_p = [ρ (A_p⁺ g_p⁺ − A_p⁻ g_p⁻) + b_p⁺ − b_p⁻] / 2` (`N_o x P`, output units).
    pub(crate) observed: DMatrix<f64>,
    /// `ρ (g_p⁺ − g_p⁻) / 2` (`C N_u x P`, response units; zero for a tolerance that leaves
    /// the unobservable model alone).
    pub(crate) response: DMatrix<f64>,
}

/// [`ToleranceColumns`] of `model`'s declared tolerances at `x`, `θ` and `ρ`.
pub(crate) fn columns_at<U, O>(
    model: &MultiLevelModel<U, O>,
    x: &[f64],
    theta: &[f64],
    rho: f64,
) -> Result<ToleranceColumns>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let n_u = model.unobservable.response_len();
    let n_o = model.observable.matrix().nrows();
    let response = |u: &U| -> Result<DVector<f64>> {
        let mut g = vec![0.0; n_u];
        u.evaluate(x, theta, &mut g)?;
        Ok(DVector::from_vec(g))
    };
    let nominal = match model.tolerances.iter().any(|t| t.responses.is_none()) {
        true => response(&model.unobservable)?,
        // unused: every tolerance brings its own responses
        false => DVector::zeros(n_u),
    };
    let observed = |o: &O, g: &DVector<f64>| -> Result<DVector<f64>> {
        let mut b = vec![0.0; n_o];
        o.offset(x, theta, &mut b)?;
        Ok(o.matrix() * g * rho + DVector::from_vec(b))
    };
    let p = model.tolerances.len();
    let mut out = ToleranceColumns {
        observed: DMatrix::zeros(n_o, p),
        response: DMatrix::zeros(n_u, p),
    };
    for (c, t) in model.tolerances.iter().enumerate() {
        let (g_lo, g_hi) = match &t.responses {
            Some((lo, hi)) => (response(lo)?, response(hi)?),
            None => (nominal.clone(), nominal.clone()),
        };
        let col = (observed(&t.high, &g_hi)? - observed(&t.low, &g_lo)?) * 0.5;
        out.observed.set_column(c, &col);
        out.response.set_column(c, &((&g_hi - &g_lo) * (0.5 * rho)));
    }
    Ok(out)
}
