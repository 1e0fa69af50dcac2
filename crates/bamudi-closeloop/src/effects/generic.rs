//! The data-driven term: a sparse linear model in the record's covariates, for effects outside
//! the library, named by the covariates it uses.

use super::linear::{Basis, LinearTerm, lagged};
use super::stepwise;
use super::thermal::{best_lag_on_grid, lag_grid_h};
use crate::config::Selection;
use crate::effect::{Effect, EffectKind, FitContext, Fitted, param};
use crate::error::Result;
use crate::stats::correlation;
use nalgebra::DMatrix;
use std::sync::Arc;

/// A sparse linear term in at most `max_features` standardised candidates (one shared set,
/// per-gauge coefficients): the record's features beside the model (see
/// [`Features`](crate::Features): covariates, rates, same-unit differences,
/// harmonics) and first-order lags of its level columns with a fitted time constant. The
/// model's own inputs and the load (and any covariate that duplicates one of them) are left
/// out: the calibrated model's discrepancy is already a function of them.
#[derive(Debug, Clone)]
pub struct Generic {
    /// Most covariates in the term.
    pub max_features: usize,
    /// How the covariates are selected.
    pub selection: Selection,
    /// Columns whose first-order lag is a library effect's own form (the thermal effect's
    /// temperature columns): their lags are not candidates, so the data-driven term cannot
    /// re-fit a library effect with more freedom and take it over.
    pub lag_covered: Vec<String>,
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
        let cands = candidates(ctx, r, &self.lag_covered);
        let chosen = match self.selection {
            Selection::StepwiseBic => stepwise::select_bic(ctx, r, &cands, self.max_features),
            Selection::StepwiseCv => stepwise::select_cv(ctx, r, &cands, self.max_features),
            Selection::GroupLassoCv => super::lasso::select(ctx, r, &cands, self.max_features),
        };
        let Some(chosen) = chosen else {
            return Ok(None);
        };
        let chosen: Vec<&Candidate> = chosen.iter().map(|&k| &cands[k]).collect();
        let names: Vec<String> = chosen.iter().map(|c| c.name.clone()).collect();
        let sd: Vec<f64> = chosen.iter().map(|c| c.sd).collect();
        let basis = Basis::Generic {
            cols: chosen.iter().map(|c| c.col).collect(),
            lags_h: chosen.iter().map(|c| c.tau_h).collect(),
            mean: chosen.iter().map(|c| c.mean).collect(),
            sd: sd.clone(),
        };
        let term = LinearTerm::fit(basis, ctx, r);
        let mut p = vec![term.parameter(0, "intercept", ctx.unit)];
        for (k, nm) in names.iter().enumerate() {
            let name = format!("per_sd_of_{nm} (sd = {:.4})", sd[k]);
            p.push(param(
                &name,
                ctx.unit,
                term.coef.row(k + 1).iter().copied().collect(),
            ));
        }
        // plotted against the feature itself (a lagged candidate's source column)
        let plot = ctx.feats.names[chosen[0].col].clone();
        Ok(Some(Fitted::new(self, Arc::new(term), names, p, &plot)))
    }
}

/// A candidate covariate of the data-driven term: feature `col`, through a first-order lag of
/// `tau_h` hours when positive, with its values at every row and their mean and population sd
/// on the calibration rows.
pub(super) struct Candidate {
    /// Feature column.
    pub col: usize,
    /// Lag time constant (hours; 0 = none).
    pub tau_h: f64,
    /// Name in reports: the feature's, or `lag<τ>h(<feature>)`.
    pub name: String,
    /// Values at every row.
    pub values: Vec<f64>,
    /// Mean on the calibration rows.
    pub mean: f64,
    /// Population sd on the calibration rows.
    pub sd: f64,
}

impl Candidate {
    fn new(ctx: &FitContext<'_>, col: usize, tau_h: f64) -> Self {
        let feature = &ctx.feats.names[col];
        let name = if tau_h > 0.0 {
            format!("lag{tau_h}h({feature})")
        } else {
            feature.clone()
        };
        let values = lagged(ctx.feats, col, tau_h);
        Self {
            tau_h,
            ..Self::from_values(ctx, col, name, values)
        }
    }

    /// A candidate from given `values` at every row (`col`: the feature it is built from,
    /// for plots; no lag).
    pub(super) fn from_values(
        ctx: &FitContext<'_>,
        col: usize,
        name: String,
        values: Vec<f64>,
    ) -> Self {
        let n = ctx.cal.len() as f64;
        let mean = ctx.cal.iter().map(|&i| values[i]).sum::<f64>() / n;
        let var = ctx
            .cal
            .iter()
            .map(|&i| (values[i] - mean).powi(2))
            .sum::<f64>()
            / n;
        Self {
            col,
            tau_h: 0.0,
            name,
            values,
            mean,
            sd: var.sqrt(),
        }
    }

    /// The standardised value at row `i`.
    pub fn z(&self, i: usize) -> f64 {
        (self.values[i] - self.mean) / self.sd
    }
}

/// The candidates: every feature beside the model that varies on the calibration rows; and,
/// for every lag source ([`Features::lag_sources`](crate::Features::lag_sources))
/// beside the model and not in `covered`, its first-order lag at the time constant of the grid
/// 0.5-128 h whose lag fits `r` best, unless no lag (the column itself) fits better.
pub(super) fn candidates(
    ctx: &FitContext<'_>,
    r: &DMatrix<f64>,
    covered: &[String],
) -> Vec<Candidate> {
    let f = ctx.feats;
    let beside: Vec<bool> = (0..f.cols.len()).map(|c| beside_model(ctx, c)).collect();
    let lag_ok = |c: usize| beside[c] && !covered.contains(&f.names[c]);
    let mut out: Vec<Candidate> = (0..f.cols.len())
        .filter(|&c| beside[c])
        .map(|c| Candidate::new(ctx, c, 0.0))
        .filter(|c| c.sd > 1e-12)
        .collect();
    for &c in f.lag_sources.iter().filter(|&&c| lag_ok(c)) {
        let (k, _) = best_lag_on_grid(ctx, r, c);
        if k > 0 {
            let cand = Candidate::new(ctx, c, lag_grid_h(k));
            if cand.sd > 1e-12 {
                out.push(cand);
            }
        }
    }
    out
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
