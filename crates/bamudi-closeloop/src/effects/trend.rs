//! The model parameter `θ` changing in time (e.g. a gate's bottom gap opening), tracked.

use crate::config::TrackConfig;
use crate::effect::{Effect, FitContext, Fitted, Term, param};
use crate::error::Result;
use crate::stats::select_rows;
use crate::track::{self, ThetaTrack, TrackInput};
use nalgebra::DMatrix;
use std::sync::Arc;

/// `θ(t)` tracked through the rows the effect is fitted on (the rows before an evaluation
/// origin; [`crate::ThetaTrack`]: window estimates of `θ`, a local linear trend
/// over them by Kalman filter and smoother) and carried past them along the last filtered
/// level and slope. No straight line or other form is imposed:
/// a gap that grows, accelerates or opens in one go is followed as it is. The term is relative
/// to the calibrated model (`g(x, θ(t)) − g(x, θ̂)`), so the loop keeps the model fixed once it
/// is accepted.
#[derive(Debug, Clone)]
pub struct ParameterTrend {
    /// Name of the parameter (e.g. `gap`); the effect is `time_varying_<parameter>`.
    pub parameter: String,
    /// Windows and state-space settings of the track.
    pub track: TrackConfig,
}

/// `ctx.model` at the tracked `θ(t)` (clamped to `bounds`) minus the model's own mean.
#[derive(Debug, Clone)]
pub(crate) struct TrackTerm {
    /// Window mid-times (hours) and smoothed levels, in time order.
    knots: Vec<(f64, f64)>,
    /// The filtered level and slope (per hour) at the last knot.
    end: (f64, f64, f64),
    bounds: (f64, f64),
}

impl TrackTerm {
    /// The term of `t`'s levels on the misfit's scale (the model's `θ` that fits each
    /// window, not the calibration's reading of it).
    pub(crate) fn from_track(t: &ThetaTrack, bounds: (f64, f64)) -> Self {
        let offset = t.offset();
        let knots = t
            .points
            .iter()
            .map(|p| (24.0 * p.day, p.smoothed.0 + offset))
            .collect();
        let s = &t.state_now;
        Self {
            knots,
            end: (24.0 * s.day, s.level + offset, s.slope / 24.0),
            bounds,
        }
    }

    /// `θ` at `t` hours: linear between knots, flat before the first, along the last filtered
    /// slope after the last.
    pub(crate) fn theta_at(&self, t: f64) -> f64 {
        let (t_end, level, slope) = self.end;
        let th = if t >= t_end {
            level + slope * (t - t_end)
        } else {
            let k = self.knots.partition_point(|&(tk, _)| tk <= t);
            match k {
                0 => self.knots[0].1,
                _ => {
                    let (t0, v0) = self.knots[k - 1];
                    let (t1, v1) = self.knots[k];
                    v0 + (v1 - v0) * (t - t0) / (t1 - t0)
                }
            }
        };
        th.clamp(self.bounds.0, self.bounds.1)
    }
}

impl TrackTerm {
    /// Window mid-times (hours) and levels, in time order.
    pub(crate) fn knots(&self) -> &[(f64, f64)] {
        &self.knots
    }
}

impl Term for TrackTerm {
    fn contribution(&self, ctx: &FitContext<'_>) -> Result<DMatrix<f64>> {
        let theta: Vec<f64> = ctx.feats.time_h.iter().map(|&t| self.theta_at(t)).collect();
        Ok(ctx.model.predict_at_theta(ctx.x, &theta)? - ctx.base_mean)
    }
}

impl Effect for ParameterTrend {
    fn name(&self) -> String {
        format!("time_varying_{}", self.parameter)
    }
    fn meaning(&self) -> String {
        format!(
            "{} changing during the record (tracked: local linear trend over window estimates)",
            self.parameter
        )
    }
    fn keeps_model_fixed(&self) -> bool {
        true
    }
    fn fit(self: Arc<Self>, ctx: &FitContext<'_>, r: &DMatrix<f64>) -> Result<Option<Fitted>> {
        let Some(t) = calibration_track(ctx, r, &self.track)? else {
            return Ok(None);
        };
        let bounds = ctx.model.theta_bounds();
        let term = TrackTerm::from_track(&t, bounds);
        let t_end_h = *ctx.feats.time_h.last().unwrap_or(&0.0);
        let at_end = t.level_at(t_end_h / 24.0);
        // the track over the fit rows is the misfit's own (not anchored: the term works on
        // that scale); the gap at the end also carries the calibration's uncertainty
        let sd = at_end.sd.hypot(ctx.model.theta_summary().sd);
        let end = at_end.mean.clamp(bounds.0, bounds.1);
        let pn = &self.parameter;
        let p = vec![
            param(
                &format!("{pn}_at_start"),
                "parameter units",
                vec![t.points[0].smoothed.0],
            ),
            param(
                &format!("{pn}_rate_at_end_of_fit"),
                "parameter units/day",
                vec![t.state_now.slope],
            ),
            param(&format!("{pn}_at_end"), "parameter units", vec![end]),
        ];
        let cov = vec!["time_days".into()];
        let mut f = Fitted::new(self, Arc::new(term), cov, p, "time_days");
        f.parameter_end = Some((end, sd, 1.96 * sd));
        Ok(Some(f))
    }
}

/// The track of `θ` over the calibration rows, on the data minus the other effects (residual
/// plus the model's mean); `None` when fewer than 3 windows carry an estimate.
fn calibration_track(
    ctx: &FitContext<'_>,
    r: &DMatrix<f64>,
    cfg: &TrackConfig,
) -> Result<Option<ThetaTrack>> {
    let x = select_rows(ctx.x, ctx.cal);
    let resid = select_rows(r, ctx.cal);
    let target = &resid + select_rows(ctx.base_mean, ctx.cal);
    let time_h: Vec<f64> = ctx.cal.iter().map(|&i| ctx.feats.time_h[i]).collect();
    let input = TrackInput {
        model: ctx.model,
        x: &x,
        target: &target,
        time_h: &time_h,
        noise_sd: crate::stats::median_noise_sd(&resid),
        calibrated: None,
    };
    let t = track::track(&input, cfg)?;
    let informed = t.points.iter().filter(|p| p.estimate.is_some()).count();
    Ok((informed >= 3).then_some(t))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_term_interpolates_between_knots_and_extrapolates_along_the_slope() {
        let term = TrackTerm {
            knots: vec![(12.0, 90.0), (36.0, 92.0), (60.0, 96.0)],
            end: (60.0, 96.5, 0.1),
            bounds: (60.0, 150.0),
        };
        assert_eq!(term.theta_at(0.0), 90.0);
        assert!((term.theta_at(24.0) - 91.0).abs() < 1e-12);
        assert!((term.theta_at(48.0) - 94.0).abs() < 1e-12);
        // past the last knot: the filtered level and slope
        assert!((term.theta_at(70.0) - 97.5).abs() < 1e-12);
        assert_eq!(term.theta_at(1e6), 150.0);
    }
}
