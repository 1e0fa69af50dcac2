//! The data-driven term: a sparse linear model in the record's covariates, for effects outside
//! the library, named by the covariates it uses.

use super::linear::{Basis, LinearTerm};
use crate::closeloop::effect::{Effect, EffectKind, FitContext, Fitted, param};
use crate::closeloop::stats::{correlation, ols, select_rows};
use crate::error::Result;
use nalgebra::DMatrix;
use std::sync::Arc;

/// A sparse linear term in at most `max_features` standardised covariates (one shared set,
/// per-gauge coefficients). The model's own inputs and the load (and any covariate that
/// duplicates one of them) are left out: the calibrated model's discrepancy is already a
/// function of them.
#[derive(Debug, Clone, Copy)]
pub struct Generic {
    /// Most covariates in the term.
    pub max_features: usize,
    /// How the covariates are selected.
    pub selection: Selection,
}

/// How the data-driven term selects its covariates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Selection {
    /// Forward stepwise least squares, stopped by BIC.
    #[default]
    StepwiseBic,
    /// The multi-task lasso path (`linfa-elasticnet`, a group penalty across gauges) with the
    /// penalty chosen by blocked cross-validation in time of the refitted least squares.
    GroupLassoCv,
}

impl Effect for Generic {
    fn name(&self) -> String {
        "generic_covariate_term".into()
    }
    fn meaning(&self) -> String {
        "effect outside the library: linear in the named covariates".into()
    }
    fn kind(&self) -> EffectKind {
        EffectKind::DataDriven
    }
    fn fit(self: Arc<Self>, ctx: &FitContext<'_>, r: &DMatrix<f64>) -> Result<Option<Fitted>> {
        let cols = match self.selection {
            Selection::StepwiseBic => select_stepwise(ctx, r, self.max_features),
            Selection::GroupLassoCv => super::lasso::select(ctx, r, self.max_features),
        };
        let Some(cols) = cols else {
            return Ok(None);
        };
        let stats = column_stats(ctx);
        let mean = cols.iter().map(|&c| stats[c].0).collect();
        let sd: Vec<f64> = cols.iter().map(|&c| stats[c].1).collect();
        let names: Vec<String> = cols.iter().map(|&c| ctx.feats.names[c].clone()).collect();
        let term = LinearTerm::fit(
            Basis::Generic {
                cols,
                mean,
                sd: sd.clone(),
            },
            ctx,
            r,
        );
        let mut p = vec![term.parameter(0, "intercept", ctx.unit)];
        for (k, nm) in names.iter().enumerate() {
            let name = format!("per_sd_of_{nm} (sd = {:.4})", sd[k]);
            p.push(param(
                &name,
                ctx.unit,
                term.coef.row(k + 1).iter().copied().collect(),
            ));
        }
        let plot = names[0].clone();
        Ok(Some(Fitted::new(self, Arc::new(term), names, p, &plot)))
    }
}

/// Mean and population sd of every feature over the calibration rows.
pub(super) fn column_stats(ctx: &FitContext<'_>) -> Vec<(f64, f64)> {
    let (cal, n) = (ctx.cal, ctx.cal.len() as f64);
    ctx.feats
        .cols
        .iter()
        .map(|c| {
            let m = cal.iter().map(|&i| c[i]).sum::<f64>() / n;
            let sd = (cal.iter().map(|&i| (c[i] - m).powi(2)).sum::<f64>() / n).sqrt();
            (m, sd)
        })
        .collect()
}

/// The columns forward stepwise BIC selects (`None`: none improves on the intercept).
fn select_stepwise(ctx: &FitContext<'_>, r: &DMatrix<f64>, max: usize) -> Option<Vec<usize>> {
    let (f, cal) = (ctx.feats, ctx.cal);
    let stats = column_stats(ctx);
    let rc = select_rows(r, cal);
    let bic = |cols: &[usize]| bic_of(ctx, &stats, &rc, cols);
    let beside_model = |c: usize| beside_model(ctx, c);
    let mut chosen: Vec<usize> = vec![];
    let mut best = bic(&chosen);
    while chosen.len() < max {
        let mut step: Option<(f64, usize)> = None;
        for c in 0..f.cols.len() {
            if chosen.contains(&c) || stats[c].1 <= 1e-12 || !beside_model(c) {
                continue;
            }
            let mut trial = chosen.clone();
            trial.push(c);
            let v = bic(&trial);
            if step.is_none_or(|s| v < s.0) {
                step = Some((v, c));
            }
        }
        match step {
            Some((v, c)) if v < best => {
                best = v;
                chosen.push(c);
            }
            _ => break,
        }
    }
    (!chosen.is_empty()).then_some(chosen)
}

/// Whether feature `c` is beside the model: not one of its inputs (or the load), and not a
/// duplicate of one (|correlation| > 0.999 on the calibration rows, e.g. a `chamber` column
/// that equals `h_up`).
pub(super) fn beside_model(ctx: &FitContext<'_>, c: usize) -> bool {
    let (f, cal) = (ctx.feats, ctx.cal);
    let values = |c: usize| -> Vec<f64> { cal.iter().map(|&i| f.cols[c][i]).collect() };
    let model = 1..=f.model_columns;
    !model.contains(&c)
        && model
            .clone()
            .all(|m| correlation(&values(c), &values(m)).abs() <= 0.999)
}

/// BIC of the least-squares fit of `rc` (calibration rows) on a constant and `cols`.
fn bic_of(ctx: &FitContext<'_>, stats: &[(f64, f64)], rc: &DMatrix<f64>, cols: &[usize]) -> f64 {
    let (f, cal) = (ctx.feats, ctx.cal);
    let (n, g) = (cal.len() as f64, rc.ncols() as f64);
    let x = DMatrix::from_fn(cal.len(), cols.len() + 1, |i, j| {
        if j == 0 {
            1.0
        } else {
            let c = cols[j - 1];
            (f.cols[c][cal[i]] - stats[c].0) / stats[c].1
        }
    });
    let res = rc - &x * ols(&x, rc);
    let fit: f64 = (0..res.ncols())
        .map(|j| n * (res.column(j).norm_squared() / n).max(1e-300).ln())
        .sum();
    fit + (cols.len() + 1) as f64 * g * n.ln()
}
