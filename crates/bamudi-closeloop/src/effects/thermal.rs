//! Thermal (or apparent) strain proportional to a first-order-lagged temperature.

use super::linear::{Basis, LinearTerm};
use crate::effect::{Effect, FitContext, Fitted, param};
use crate::error::Result;
use nalgebra::DMatrix;
use std::sync::Arc;

/// Output proportional to the temperature in `column` passed through a first-order lag whose
/// time constant is fitted (0-128 h).
#[derive(Debug, Clone)]
pub struct Thermal {
    /// The temperature feature.
    pub column: String,
}

impl Effect for Thermal {
    fn name(&self) -> String {
        format!("thermal({})", self.column)
    }
    fn meaning(&self) -> String {
        "apparent/thermal strain proportional to a first-order-lagged temperature".into()
    }
    fn fit(self: Arc<Self>, ctx: &FitContext<'_>, r: &DMatrix<f64>) -> Result<Option<Fitted>> {
        let Some(col) = ctx.feats.position(&self.column) else {
            return Ok(None);
        };
        let term = fit_thermal(ctx, r, col);
        let coef = &term.coef;
        // temperature at which the thermal term vanishes (the gauges' zeroing temperature when
        // nothing else offsets them)
        let zero_temp = (0..coef.ncols()).map(|g| -coef[(0, g)] / coef[(1, g)]);
        let tau_h = match term.basis {
            Basis::Thermal { tau_h, .. } => tau_h,
            _ => f64::NAN,
        };
        let c = &self.column;
        let p = vec![
            term.parameter(1, "coefficient", &format!("{} per unit of {c}", ctx.unit)),
            term.parameter(0, "intercept", ctx.unit),
            param(
                "zero_strain_temperature",
                &format!("unit of {c}"),
                zero_temp.collect(),
            ),
            param("lag_time_constant (all gauges)", "hours", vec![tau_h]),
        ];
        let plot = self.column.clone();
        Ok(Some(Fitted::new(
            self,
            Arc::new(term),
            vec![plot.clone()],
            p,
            &plot,
        )))
    }
}

/// The lag time constants searched: 0 (no lag) and a doubling grid 0.5-128 h.
const LAG_GRID_H: [f64; 10] = [0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0];

/// The grid time constant of [`LAG_GRID_H`] whose lagged column `col` fits `r` best (least
/// squares on a constant and the lagged column, calibration rows), with its position and the
/// fit's sum of squares at every grid point.
pub(super) fn best_lag_on_grid(
    ctx: &FitContext<'_>,
    r: &DMatrix<f64>,
    col: usize,
) -> (usize, Vec<f64>) {
    let sse = |tau: f64| LinearTerm::fit(Basis::Thermal { col, tau_h: tau }, ctx, r).sse;
    let vals: Vec<f64> = LAG_GRID_H.iter().map(|&t| sse(t)).collect();
    let k = (0..LAG_GRID_H.len())
        .min_by(|&a, &b| vals[a].total_cmp(&vals[b]))
        .unwrap_or(0);
    (k, vals)
}

/// The time constant at grid position `k` of [`LAG_GRID_H`].
pub(super) fn lag_grid_h(k: usize) -> f64 {
    LAG_GRID_H[k]
}

/// Thermal term: lag time constant by a grid over 0-128 h refined by golden section on ln τ.
fn fit_thermal(ctx: &FitContext<'_>, r: &DMatrix<f64>, col: usize) -> LinearTerm {
    let sse = |tau: f64| LinearTerm::fit(Basis::Thermal { col, tau_h: tau }, ctx, r).sse;
    let grid = LAG_GRID_H;
    let (k, vals) = best_lag_on_grid(ctx, r, col);
    let mut tau = grid[k];
    if k > 0 && k + 1 < grid.len() {
        // golden section on ln τ between the grid neighbours
        let (mut lo, mut hi) = (grid[k - 1].max(0.25).ln(), grid[k + 1].ln());
        let gr = 0.618_033_988_75;
        for _ in 0..25 {
            let (a, b) = (hi - gr * (hi - lo), lo + gr * (hi - lo));
            if sse(a.exp()) < sse(b.exp()) {
                hi = b
            } else {
                lo = a
            }
        }
        let t = (0.5 * (lo + hi)).exp();
        if sse(t) < vals[k] {
            tau = t;
        }
    }
    LinearTerm::fit(Basis::Thermal { col, tau_h: tau }, ctx, r)
}
