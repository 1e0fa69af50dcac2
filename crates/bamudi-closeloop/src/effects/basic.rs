//! Gauge zero errors: a constant offset, a linear drift and a single step per gauge.

use super::linear::{Basis, LinearTerm};
use crate::effect::{Effect, FitContext, Fitted, Term, param};
use crate::error::Result;
use nalgebra::DMatrix;
use std::sync::Arc;

/// A constant zero offset per gauge.
#[derive(Debug, Clone, Copy, Default)]
pub struct GaugeOffset;

impl Effect for GaugeOffset {
    fn name(&self) -> String {
        "gauge_offset".into()
    }
    fn meaning(&self) -> String {
        "constant gauge zero error (output units)".into()
    }
    fn fit(self: Arc<Self>, ctx: &FitContext<'_>, r: &DMatrix<f64>) -> Result<Option<Fitted>> {
        let term = LinearTerm::fit(Basis::Offset, ctx, r);
        let p = vec![term.parameter(0, "offset", ctx.unit)];
        Ok(Some(Fitted::new(
            self,
            Arc::new(term),
            vec![],
            p,
            "time_days",
        )))
    }
}

/// A zero offset plus a linear drift in time per gauge.
#[derive(Debug, Clone, Copy, Default)]
pub struct GaugeDrift;

impl Effect for GaugeDrift {
    fn name(&self) -> String {
        "gauge_drift".into()
    }
    fn meaning(&self) -> String {
        "gauge zero drifting linearly in time (adhesive creep, moisture; output units/day)".into()
    }
    fn fit(self: Arc<Self>, ctx: &FitContext<'_>, r: &DMatrix<f64>) -> Result<Option<Fitted>> {
        let term = LinearTerm::fit(Basis::Drift, ctx, r);
        let p = vec![
            term.parameter(0, "offset_at_start", ctx.unit),
            term.parameter(1, "drift_rate", &format!("{}/day", ctx.unit)),
        ];
        let cov = vec!["time_days".into()];
        Ok(Some(Fitted::new(self, Arc::new(term), cov, p, "time_days")))
    }
}

/// A zero offset plus a step at a gauge-specific time.
#[derive(Debug, Clone, Copy, Default)]
pub struct OffsetJump;

/// Per gauge: its level, and a step at `times[g]` (hours) if any.
#[derive(Debug, Clone)]
struct JumpTerm {
    times: Vec<Option<f64>>,
    level: Vec<f64>,
    step: Vec<f64>,
}

impl Term for JumpTerm {
    fn contribution(&self, ctx: &FitContext<'_>) -> Result<DMatrix<f64>> {
        let f = ctx.feats;
        let (n, g) = (f.time_h.len(), ctx.gauges.len());
        Ok(DMatrix::from_fn(n, g, |i, j| {
            let after = self.times[j].is_some_and(|tj| f.time_h[i] >= tj);
            self.level[j] + if after { self.step[j] } else { 0.0 }
        }))
    }
}

impl Effect for OffsetJump {
    fn name(&self) -> String {
        "gauge_offset_jump".into()
    }
    fn meaning(&self) -> String {
        "step in a gauge zero (logger reset, re-bonded gauge, electrical transient)".into()
    }
    fn fit(self: Arc<Self>, ctx: &FitContext<'_>, r: &DMatrix<f64>) -> Result<Option<Fitted>> {
        let Some(term) = fit_jump(ctx, r) else {
            return Ok(None);
        };
        let days = term.times.iter().map(|t| t.map_or(f64::NAN, |t| t / 24.0));
        let p = vec![
            param("level_before", ctx.unit, term.level.clone()),
            param("jump_day (NaN = none)", "day", days.collect()),
            param("jump_size", ctx.unit, term.step.clone()),
        ];
        let cov = vec!["time_days".into()];
        Ok(Some(Fitted::new(self, Arc::new(term), cov, p, "time_days")))
    }
}

/// Per gauge, the best single step (by cumulative sums over the calibration rows); kept only
/// where BIC favours it (`n ln(SSE0/SSE1) > 3 ln n`: level, size and time are 3 parameters).
fn fit_jump(ctx: &FitContext<'_>, r: &DMatrix<f64>) -> Option<JumpTerm> {
    let cal = ctx.cal;
    let n = cal.len();
    if n < 20 {
        return None;
    }
    let (mut times, mut level, mut step) = (vec![], vec![], vec![]);
    for j in 0..r.ncols() {
        let v: Vec<f64> = cal.iter().map(|&i| r[(i, j)]).collect();
        let (tot, tot2) = (v.iter().sum::<f64>(), v.iter().map(|x| x * x).sum::<f64>());
        let sse0 = tot2 - tot * tot / n as f64;
        let mut best = (sse0, 0usize);
        let (mut s, mut s2) = (0.0, 0.0);
        let min_seg = (n / 20).max(5);
        for k in 0..n - min_seg {
            s += v[k];
            s2 += v[k] * v[k];
            let m = k + 1;
            if m < min_seg {
                continue;
            }
            let sse = (s2 - s * s / m as f64) + ((tot2 - s2) - (tot - s).powi(2) / (n - m) as f64);
            if sse < best.0 {
                best = (sse, m);
            }
        }
        let m = best.1;
        let keep = m > 0 && best.0 > 0.0 && n as f64 * (sse0 / best.0).ln() > 3.0 * (n as f64).ln();
        if keep {
            let before = v[..m].iter().sum::<f64>() / m as f64;
            let after = v[m..].iter().sum::<f64>() / (n - m) as f64;
            times.push(Some(
                0.5 * (ctx.feats.time_h[cal[m - 1]] + ctx.feats.time_h[cal[m]]),
            ));
            level.push(before);
            step.push(after - before);
        } else {
            times.push(None);
            level.push(tot / n as f64);
            step.push(0.0);
        }
    }
    times
        .iter()
        .any(Option::is_some)
        .then_some(JumpTerm { times, level, step })
}
