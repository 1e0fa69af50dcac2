//! The model parameter `θ` changing linearly in time (e.g. a gate's bottom gap opening).

use crate::closeloop::effect::{Effect, FitContext, Fitted, ParameterEnd, Term, param};
use crate::closeloop::stats::select_rows;
use crate::error::Result;
use nalgebra::DMatrix;
use statrs::distribution::{ContinuousCDF, StudentsT};
use std::sync::Arc;

/// `θ(t) = a + b t`: the calibration window cut into `segments`, `θ` of each found by a grid
/// search of the model conditional on `θ`, then a straight line through the segment values.
/// The term is relative to the calibrated model (`g(x, θ(t)) − g(x, θ̂)`), so the loop keeps
/// the model fixed once it is accepted.
#[derive(Debug, Clone)]
pub struct ParameterTrend {
    /// Name of the parameter (e.g. `gap`); the effect is `time_varying_<parameter>`.
    pub parameter: String,
    /// Segments of the calibration window (at least 3, each of at least 10 rows).
    pub segments: usize,
}

/// `ctx.model` at `θ = a + b t` (clamped to `bounds`) minus the model's own mean.
#[derive(Debug, Clone)]
struct TrendTerm {
    a: f64,
    b_per_h: f64,
    bounds: (f64, f64),
}

impl Term for TrendTerm {
    fn contribution(&self, ctx: &FitContext<'_>) -> Result<DMatrix<f64>> {
        let theta: Vec<f64> = ctx
            .feats
            .time_h
            .iter()
            .map(|t| (self.a + self.b_per_h * t).clamp(self.bounds.0, self.bounds.1))
            .collect();
        Ok(ctx.model.predict_at_theta(ctx.x, &theta)? - ctx.base_mean)
    }
}

impl Effect for ParameterTrend {
    fn name(&self) -> String {
        format!("time_varying_{}", self.parameter)
    }
    fn meaning(&self) -> String {
        format!(
            "{} changing during the record (linear in time)",
            self.parameter
        )
    }
    fn keeps_model_fixed(&self) -> bool {
        true
    }
    fn fit(self: Arc<Self>, ctx: &FitContext<'_>, r: &DMatrix<f64>) -> Result<Option<Fitted>> {
        let k = self.segments;
        if k < 3 || ctx.cal.len() < 10 * k {
            return Ok(None);
        }
        let (tk, thk) = segment_values(ctx, r, k)?;
        let bounds = ctx.model.theta_bounds();
        let t_end = *ctx.feats.time_h.last().unwrap_or(&0.0);
        let (term, end) = straight_line(&tk, &thk, bounds, t_end);
        let pn = &self.parameter;
        let p = vec![
            param(&format!("{pn}_at_start"), "parameter units", vec![term.a]),
            param(
                &format!("{pn}_rate"),
                "parameter units/day",
                vec![term.b_per_h * 24.0],
            ),
            param(&format!("{pn}_at_end"), "parameter units", vec![end.0]),
        ];
        let cov = vec!["time_days".into()];
        let mut f = Fitted::new(self, Arc::new(term), cov, p, "time_days");
        f.parameter_end = Some(end);
        Ok(Some(f))
    }
}

/// Mean time (hours) and the best `θ` of each of `k` consecutive segments of the calibration
/// rows: a 41-point grid over the prior support refined by the vertex of a parabola.
fn segment_values(
    ctx: &FitContext<'_>,
    r: &DMatrix<f64>,
    k: usize,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let n = ctx.cal.len();
    let bounds = ctx.model.theta_bounds();
    let grid: Vec<f64> = (0..=40)
        .map(|i| bounds.0 + (bounds.1 - bounds.0) * i as f64 / 40.0)
        .collect();
    let (mut tk, mut thk) = (vec![], vec![]);
    for s in 0..k {
        let rows: Vec<usize> = ctx.cal[s * n / k..(s + 1) * n / k].to_vec();
        let xs = select_rows(ctx.x, &rows);
        // target = data minus the other effects = residual + current model mean
        let target = select_rows(r, &rows) + select_rows(ctx.base_mean, &rows);
        let mut sse = Vec::with_capacity(grid.len());
        for &th in &grid {
            let p = ctx.model.predict_at_theta(&xs, &vec![th; rows.len()])?;
            sse.push((&target - p).norm_squared());
        }
        tk.push(rows.iter().map(|&i| ctx.feats.time_h[i]).sum::<f64>() / rows.len() as f64);
        thk.push(parabola_minimum(&grid, &sse));
    }
    Ok((tk, thk))
}

/// The grid minimum refined by the vertex of the parabola through it and its neighbours.
fn parabola_minimum(grid: &[f64], sse: &[f64]) -> f64 {
    let b = (0..grid.len())
        .min_by(|&a, &c| sse[a].total_cmp(&sse[c]))
        .unwrap_or(0);
    let mut th = grid[b];
    if b > 0 && b + 1 < grid.len() {
        let (y0, y1, y2) = (sse[b - 1], sse[b], sse[b + 1]);
        let den = y0 - 2.0 * y1 + y2;
        if den > 0.0 {
            th += 0.5 * (y0 - y2) / den * (grid[1] - grid[0]);
        }
    }
    th
}

/// Least-squares line through `(tk, thk)`, and its value at `t_end` with the standard error of
/// the fitted mean and the half-width of its 95 % interval (Student t, `k − 2` dof).
fn straight_line(
    tk: &[f64],
    thk: &[f64],
    bounds: (f64, f64),
    t_end: f64,
) -> (TrendTerm, ParameterEnd) {
    let kf = tk.len() as f64;
    let (tm, ym) = (tk.iter().sum::<f64>() / kf, thk.iter().sum::<f64>() / kf);
    let sxx: f64 = tk.iter().map(|t| (t - tm).powi(2)).sum();
    let b = tk
        .iter()
        .zip(thk)
        .map(|(t, y)| (t - tm) * (y - ym))
        .sum::<f64>()
        / sxx;
    let a = ym - b * tm;
    let s2 = tk
        .iter()
        .zip(thk)
        .map(|(t, y)| (y - a - b * t).powi(2))
        .sum::<f64>()
        / (kf - 2.0);
    let end = (a + b * t_end).clamp(bounds.0, bounds.1);
    let sd = (s2 * (1.0 / kf + (t_end - tm).powi(2) / sxx)).sqrt();
    let term = TrendTerm {
        a,
        b_per_h: b,
        bounds,
    };
    (term, (end, sd, student_t975(tk.len() - 2) * sd))
}

/// 97.5 % quantile of Student's t with `dof` degrees of freedom (∞ for none).
fn student_t975(dof: usize) -> f64 {
    match StudentsT::new(0.0, 1.0, dof as f64) {
        Ok(t) if dof > 0 => t.inverse_cdf(0.975),
        _ => f64::INFINITY,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn student_quantiles_match_tables() {
        // 12.706 (1 dof), 2.776 (4 dof), 2.042 (30 dof): the tables' three decimals
        for (dof, q) in [(1, 12.706), (4, 2.776), (30, 2.042)] {
            assert!((student_t975(dof) - q).abs() < 5e-4, "{dof}");
        }
        assert!(student_t975(0).is_infinite());
    }
}
