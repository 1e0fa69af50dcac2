//! The parameter's change, once the track's alarm stands, applied as a correction.
//!
//! The track ([`crate::ThetaTrack`]) dates and sizes a change of `θ` (the gate's gap); its
//! alarm tells the operator the gap changed. Left at that, the residual still holds the
//! model's response to the change: every gauge the gap moves shows a change of level, the
//! whole-record scan raises one gauge alarm per gauge and per piece of the change (dozens on
//! a gap step of a few inches), and the error window is as far off as before. So the change
//! is put in the model: every row is predicted at `θ(t)` from the track over the whole record
//! (its smoothed levels, on the misfit's scale), and between two consecutive windows the rows
//! get either the windows' interpolation or a one-row step from one window's level to the
//! next, the step when it fits them better by more than choosing its row costs (least
//! squares: the step's row is the data's choice, and a change need not be the one the alarm
//! dated; the CUSUM names only the first). The scan is re-run on the residual at `θ(t)` (the
//! report's gauge alarms are then the gauges' own news; those a sensor finding explains are
//! kept), and the error window's RMSE with the change applied is reported. The track reads
//! every row, so that figure is in-sample; `fitted_on_error_rows` says when the change itself
//! starts in the error window, where no figure fitted on earlier rows can hold it.

use super::{PostPass, track_residual, zero_masked};
use crate::effects::trend::TrackTerm;
use crate::error::Result;
use crate::search::Loop;
use crate::stats::nan_as_null;
use crate::{MeasuredRecord, events, sensor};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// The parameter's change applied as a correction (the report's `parameter_correction`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ParameterCorrection {
    /// Day of the largest one-row step the correction holds (days since the first row);
    /// `None` when the windows' interpolation fits better everywhere (a change spread over
    /// days).
    pub step_day: Option<f64>,
    /// The parameter before and after that step (parameter units, the calibration's scale).
    pub step_levels: Option<(f64, f64)>,
    /// Whether the change the alarm dates may start no earlier than one track window before
    /// the error window (the low end of its 95 % onset interval), so that no fit on earlier
    /// rows can hold it. (Not the largest step's day: a growth's largest step can be anywhere,
    /// and a change that began earlier is not the error window's own.)
    pub fitted_on_error_rows: bool,
    /// RMSE per gauge on the error window with the change applied (output units); `NaN`
    /// (JSON `null`) for a gauge set aside on every row of the window. Always in-sample: the
    /// track reads every row, the error window's included.
    #[serde(deserialize_with = "nan_as_null::vec")]
    pub error_rmse: Vec<f64>,
    /// Gauge alarms of the whole-record scan without the change (on the residual before the
    /// sensor pass's corrections after selection, as the scan first ran); the report's
    /// `events` are the scan with the change and those corrections, plus the first scan's
    /// alarms a sensor finding explains.
    pub gauge_alarms_without: usize,
}

/// A one-row step: its hour, the level before and after (misfit scale).
type Step = (f64, f64, f64);

/// Applies the standing alarm's change: re-runs the scan on the residual at `θ(t)` into
/// `post.events` and returns what it did (`None` without a standing alarm).
pub(super) fn apply(
    lp: &Loop<'_>,
    rec: &MeasuredRecord,
    post: &mut PostPass,
) -> Result<Option<ParameterCorrection>> {
    let Some(track) = post.track.as_ref().filter(|t| t.alarm.is_some()) else {
        return Ok(None);
    };
    // the earliest onset the alarm allows: a change that may have begun before the error
    // window is not the error window's own
    let onset = track
        .alarm
        .as_ref()
        .map_or(f64::NAN, |a| a.onset_day_interval.0);
    let model = post.st.model.as_ref();
    let term = TrackTerm::from_track(track, model.theta_bounds());
    let offset = track.anchor.as_ref().map_or(0.0, |a| a.offset);
    let noise_var = track.noise_sd.powi(2);
    // the data less the additive effects, less the model at the calibrated θ
    let r_t = track_residual(lp, post)?;
    let (theta, step) = theta_rows(lp, rec, post, &r_t, &term, noise_var)?;
    let mut r = r_t - (model.predict_at_theta(lp.x, &theta)? - &post.st.mean);
    zero_masked(&mut r, &post.mask);
    let gauge_alarms_without = post.events.as_ref().map_or(0, |e| e.alarms.len());
    if lp.cfg.event_scan.enabled {
        let mut scan = events::scan(rec, &r, &post.mask, lp.sel.len(), &lp.cfg.event_scan)?;
        keep_sensor_alarms(&mut scan, post);
        post.events = Some(scan);
    }
    let rows = lp.error_rows();
    let error_start = rows
        .first()
        .map_or(f64::INFINITY, |&i| rec.time_h[i] / 24.0);
    Ok(Some(ParameterCorrection {
        step_day: step.map(|(t_h, _, _)| t_h / 24.0),
        step_levels: step.map(|(_, b, a)| (b - offset, a - offset)),
        fitted_on_error_rows: onset > error_start - lp.cfg.track.window_hours / 24.0,
        error_rmse: sensor::rmse_unmasked(&r, rows, &post.mask),
        gauge_alarms_without,
    }))
}

/// The earlier scan's alarms that a sensor finding of the pass explains (same gauge, onset
/// within a day of the finding's start) are kept in `scan`: the residual it reads is corrected
/// for the finding, but a corrected fault is still news to the operator.
fn keep_sensor_alarms(scan: &mut events::EventScan, post: &PostPass) {
    let Some(before) = &post.events else {
        return;
    };
    let explained = |a: &events::Alarm| {
        post.findings
            .iter()
            .any(|f| f.gauges.contains(&a.gauge) && (f.from_day - a.onset_day).abs() <= 1.0)
    };
    let present = |s: &events::EventScan, a: &events::Alarm| {
        s.alarms
            .iter()
            .any(|b| b.gauge == a.gauge && (b.onset_day - a.onset_day).abs() <= 1.0)
    };
    let kept: Vec<events::Alarm> = before
        .alarms
        .iter()
        .filter(|a| explained(a) && !present(scan, a))
        .cloned()
        .collect();
    scan.alarms.extend(kept);
    scan.alarms
        .sort_by(|a, b| a.onset_day.total_cmp(&b.onset_day));
}

/// `θ` at every row, and the largest one-row step it holds. Between two consecutive windows
/// the rows get the windows' interpolation or a one-row step from the first window's level to
/// the second's (levels clamped to the prior's support), the step when it lowers the sum of
/// squares by more than `2 ln(m)` noise variances (`noise_var`) for `m` possible split rows
/// (a step at a window's edge is the data's choice too); before the first window and after the last, the
/// track's term (its first level; the last filtered level along its slope). Three predictions
/// of every row: at the interpolation, at the level before and at the level after.
fn theta_rows(
    lp: &Loop<'_>,
    rec: &MeasuredRecord,
    post: &PostPass,
    r_t: &DMatrix<f64>,
    term: &TrackTerm,
    noise_var: f64,
) -> Result<(Vec<f64>, Option<Step>)> {
    let bounds = post.st.model.theta_bounds();
    let knots: Vec<(f64, f64)> = term
        .knots()
        .iter()
        .map(|&(h, v)| (h, v.clamp(bounds.0, bounds.1)))
        .collect();
    let t = &rec.time_h;
    let mut theta: Vec<f64> = t.iter().map(|&h| term.theta_at(h)).collect();
    // the interval of each row: k when knots[k].0 <= t < knots[k + 1].0
    let interval: Vec<Option<usize>> = t
        .iter()
        .map(|&h| {
            let k = knots.partition_point(|kn| kn.0 <= h);
            (k >= 1 && k < knots.len()).then(|| k - 1)
        })
        .collect();
    let lo: Vec<f64> = (0..t.len())
        .map(|i| interval[i].map_or(theta[i], |k| knots[k].1))
        .collect();
    let hi: Vec<f64> = (0..t.len())
        .map(|i| interval[i].map_or(theta[i], |k| knots[k + 1].1))
        .collect();
    let model = post.st.model.as_ref();
    let target = r_t + &post.st.mean;
    let sse = |theta: &[f64]| -> Result<Vec<f64>> {
        let pred = model.predict_at_theta(lp.x, theta)?;
        Ok((0..t.len())
            .map(|i| {
                (0..pred.ncols())
                    .filter(|&g| !post.mask[(i, g)])
                    .map(|g| (target[(i, g)] - pred[(i, g)]).powi(2))
                    .sum()
            })
            .collect())
    };
    let (e_int, e_lo, e_hi) = (sse(&theta)?, sse(&lo)?, sse(&hi)?);
    let mut largest: Option<Step> = None;
    for k in 0..knots.len().saturating_sub(1) {
        let rows: Vec<usize> = (0..t.len()).filter(|&i| interval[i] == Some(k)).collect();
        if rows.is_empty() {
            continue;
        }
        let interp: f64 = rows.iter().map(|&i| e_int[i]).sum();
        // split s: rows[..s] at the level before, rows[s..] at the level after
        let total_hi: f64 = rows.iter().map(|&i| e_hi[i]).sum();
        let (mut best, mut acc_lo, mut acc_hi) = ((f64::INFINITY, 0), 0.0, 0.0);
        for s in 0..=rows.len() {
            let v = acc_lo + total_hi - acc_hi;
            if v < best.0 {
                best = (v, s);
            }
            if s < rows.len() {
                acc_lo += e_lo[rows[s]];
                acc_hi += e_hi[rows[s]];
            }
        }
        // the split is the best of `rows.len() + 1`: it must gain what choosing among them
        // costs, 2 ln(m) noise variances (the sensor pass's penalty for choosing among `m`)
        let penalty = 2.0 * ((rows.len() + 1) as f64).ln() * noise_var;
        if best.0 + penalty >= interp {
            continue;
        }
        let (before, after) = (knots[k].1, knots[k + 1].1);
        for (j, &i) in rows.iter().enumerate() {
            theta[i] = if j < best.1 { before } else { after };
        }
        let at = rows.get(best.1).map_or(knots[k + 1].0, |&i| t[i]);
        if largest.is_none_or(|(_, b, a)| (after - before).abs() > (a - b).abs()) {
            largest = Some((at, before, after));
        }
    }
    Ok((theta, largest))
}
