//! What a re-calibration would take back: a load nuisance fitted jointly with each candidate.
//!
//! BA-MUDI's discrepancy `δ(x)` is a free smooth function of the model inputs at loaded rows. When the data carry an effect the model lacks, the first
//! calibration absorbs the part of the effect that looks like a function of the load (on the
//! thermal record ρ* fell to 0.26), and the residual shows the effect *minus* that part. A
//! candidate fitted to this residual alone is scored against a distorted target, and a generic
//! term that can mimic the load (e.g. with `lockage_phase`) beats the true effect. Fitting the
//! candidate together with a per-gauge smooth function of the load, zero where the gate is open
//! (as the discrepancy is), estimates the effect as if the calibration had not absorbed any of
//! it: the Frisch-Waugh-Lovell view of "add the effect, then re-calibrate".
//!
//! The basis is a polynomial in the standardised load `s` (a gate's head) and its companion
//! input `d` (the lower level) over the loaded calibration rows:
//! `1, s, d, s², s d, d², s³, s⁴` (the load gets the higher powers because the response along a
//! filling or emptying is a curved function of it; the full-lift states only spread over a
//! small patch of `(s, d)`).

use super::config::LoadSpec;
use super::effect::{Effect, FitContext, Fitted};
use super::stats::{ols, select_rows};
use crate::error::Result;
use nalgebra::DMatrix;
use std::sync::Arc;

/// Alternations between the effect and the nuisance. Backfitting converges to the joint least
/// squares fit for linear terms, at a rate set by how collinear the two are; the cap bounds
/// the cost of the gap trend (a grid search per fit). A fit that has not settled by then is
/// used as it is: it only ranks candidates, and the loop decides after a real re-calibration.
const MAX_ALTERNATIONS: usize = 8;
/// Relative change of the fitted total (effect + nuisance) on the calibration rows at which
/// the alternation stops: far below the 5 % held-out improvements the loop decides on.
const ALTERNATION_TOL: f64 = 1e-4;

/// The load basis at every row (`n x 8`, zero where the model is unloaded).
#[derive(Debug, Clone)]
pub(crate) struct LoadNuisance {
    basis: DMatrix<f64>,
}

impl LoadNuisance {
    /// Builds the basis from the model inputs `x` and the declared `load`, standardised over
    /// the loaded rows among `cal`. `None` when fewer loaded calibration rows than twice the
    /// basis size exist.
    pub(crate) fn new(x: &DMatrix<f64>, load: &LoadSpec, cal: &[usize]) -> Option<Self> {
        const P: usize = 8;
        let row = |i: usize| -> Vec<f64> { x.row(i).iter().copied().collect() };
        let loaded = |i: usize| !load.unloaded(&row(i));
        let rows: Vec<usize> = cal.iter().copied().filter(|&i| loaded(i)).collect();
        if rows.len() < 2 * P {
            return None;
        }
        let level = |i: usize| load.value(&row(i));
        let c = load.companion;
        let (sm, ss) = mean_sd(rows.iter().map(|&i| level(i)));
        let (dm, ds) = mean_sd(rows.iter().map(|&i| x[(i, c)]));
        let basis = DMatrix::from_fn(x.nrows(), P, |i, k| {
            if !loaded(i) {
                return 0.0;
            }
            let s = (level(i) - sm) / ss;
            let d = (x[(i, c)] - dm) / ds;
            [1.0, s, d, s * s, s * d, d * d, s * s * s, s * s * s * s][k]
        });
        Some(Self { basis })
    }

    /// Least-squares fit of the basis to `r` on the rows `cal`, evaluated at every row.
    pub(crate) fn fit(&self, r: &DMatrix<f64>, cal: &[usize]) -> DMatrix<f64> {
        let coef = ols(&select_rows(&self.basis, cal), &select_rows(r, cal));
        &self.basis * coef
    }
}

fn mean_sd(v: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = v.clone().count().max(1) as f64;
    let m = v.clone().sum::<f64>() / n;
    let sd = (v.map(|a| (a - m).powi(2)).sum::<f64>() / n).sqrt();
    // a constant column (all loaded rows at one head) is left unscaled
    (m, if sd > 1e-9 { sd } else { 1.0 })
}

/// A candidate fitted to a residual, with what it and the nuisance explain together.
pub(crate) struct JointFit {
    /// The effect alone (what the loop adds to the model).
    pub fitted: Fitted,
    /// The effect's contribution at every row (microstrain).
    pub effect: DMatrix<f64>,
    /// The nuisance's contribution at every row (zero without a nuisance).
    pub nuisance: DMatrix<f64>,
}

/// Fits `effect` to `r` jointly with the nuisance by alternating the two fits on the
/// calibration rows; without a nuisance it is the plain fit. `None` when the effect does not
/// apply.
pub(crate) fn fit_jointly(
    effect: &Arc<dyn Effect>,
    ctx: &FitContext<'_>,
    r: &DMatrix<f64>,
    nuisance: Option<&LoadNuisance>,
) -> Result<Option<JointFit>> {
    let zero = DMatrix::zeros(r.nrows(), r.ncols());
    let spec = effect;
    let Some(nu) = nuisance else {
        let Some(fitted) = effect.clone().fit(ctx, r)? else {
            return Ok(None);
        };
        let effect = fitted.term.contribution(ctx)?;
        return Ok(Some(JointFit {
            fitted,
            effect,
            nuisance: zero,
        }));
    };
    let scale = select_rows(r, ctx.cal).norm().max(1e-300);
    let mut n_c = zero;
    let mut last: Option<JointFit> = None;
    for _ in 0..MAX_ALTERNATIONS {
        let Some(fitted) = spec.clone().fit(ctx, &(r - &n_c))? else {
            // the effect stopped applying on the partial residual (e.g. no step left):
            // keep the last fit that did
            break;
        };
        let effect = fitted.term.contribution(ctx)?;
        let n_new = nu.fit(&(r - &effect), ctx.cal);
        let moved = match &last {
            Some(l) => select_rows(&(&effect + &n_new - &l.effect - &l.nuisance), ctx.cal).norm(),
            None => f64::INFINITY,
        };
        let joint = JointFit {
            fitted,
            effect,
            nuisance: n_new,
        };
        n_c.copy_from(&joint.nuisance);
        last = Some(joint);
        if moved <= ALTERNATION_TOL * scale {
            break;
        }
    }
    Ok(last)
}
