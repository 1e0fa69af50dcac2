//! A change of the gap inside the calibration window.
//!
//! The first calibration reads every row of the window as one gap. When the gap stepped inside
//! the window, it learns a gap between the two and a discrepancy fitted across both: the
//! track then dates the step and its correction holds the error window in-sample, but every
//! figure fitted on earlier rows (the out-of-sample error, the effects, the calibration's
//! own `θ`) still carries the mixture. Measured on the close-loop panel (24-in mesh, seeds
//! 1000-1004): steps of 8 and 20 in on day 5 or 30 of a 36-day window left the test window's
//! error at 1.6-8.5 times the noise on 16 of 20 records, with the gap's change dated right.
//!
//! So when the gap's correction ([`crate::ParameterCorrection`]) holds a one-row step inside
//! the window with at least `MIN_COMPLETE_ROWS` (30) of the window's rows after it, the loop is
//! run again, calibrating on those rows. The gap after the step is then the calibration's; the
//! rows before it are predicted at that gap less the step (so that the sensor pass and the
//! scans, which read every row, do not take the step for a gauge's fault) and tracked, the
//! step dated and corrected as before, now from the other side. The first calibration's
//! figures stay the report's "before"; the first run's answer is kept beside the new one
//! ([`CalibratedAfterStep`]). The loop runs again once at most.
//!
//! A change spread over days (a growing gap) keeps the whole window: no set of the window's
//! rows holds one gap. The correction may hold a growth as interpolation (no step) or with its
//! largest one-row step inside the window; the track's level then goes on moving after that
//! step, and the rows after it are used only when it does not ([`STEP_SHARE`]): on the first
//! run's track over the window, or, when that one moves, on the track of the run calibrated
//! after the step, over the rest of the record (whose answer is then kept only if its track
//! holds still).
//!
//! A gap that begins to move inside the window and goes on moving (a growth) has no rows after
//! it at one gap, but it has rows before it: when the first run's track raises a change alarm
//! that stands (the structure-or-sensor test did not withhold it) and dates the change's onset
//! inside the window with at least `MIN_COMPLETE_ROWS` of the window's rows before the onset's
//! 95 % interval, the loop is run again with the model calibrated on those rows
//! ([`ChangeInWindow`]). The model's gap is then the gap before the change, its discrepancy is
//! fitted where the gap was one, and the track and the time-varying gap read the change from
//! there. Effects are still fitted on the whole window. That run is kept only when its own
//! track still raises a change alarm (a growth from the record's first rows leaves a run
//! calibrated before it no rows at the old gap, and the alarm would be lost). Measured on the
//! panel's growths from day 5 (seeds 1000 and 1003 of 20 in, design records): the first
//! calibration, on a window over which the gap grew 11 in, put it at 95.8 and 99.7 in with a
//! discrepancy fitted to the growth; its track then forecast the test window at 2.1 and 3.2
//! times the noise, and the residual it left was taken for one gauge's gain change.

use crate::sensor::MIN_COMPLETE_ROWS;
use crate::{CloseLoopOutcome, CloseLoopReport, MeasuredRecord, ThetaSummary};
use serde::{Deserialize, Serialize};

/// The loop run again on the calibration window's rows after a step of the gap inside it (the
/// report's `after_step`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CalibratedAfterStep {
    /// Day of the step the first run's gap correction held (days since the first row).
    pub step_day: f64,
    /// The window's rows from that day on: the rows the second run calibrated on.
    pub calibration_rows: usize,
    /// `θ` the first run reported (calibrated on the whole window).
    pub theta_whole_window: ThetaSummary,
    /// The error window's RMSE over every gauge after the first run (output units).
    pub error_whole_window: f64,
}

/// A step of the gap inside the calibration window that the loop may calibrate after: the
/// first run's gap correction holds it with enough of the window's rows after it.
pub(crate) struct StepInWindow {
    /// Day of the step (days since the first row).
    pub day: f64,
    /// The calibration window's rows from that day on.
    pub rows: Vec<usize>,
    /// The step's size (after minus before, parameter units).
    pub size: f64,
    /// Day of the calibration window's last row.
    end: f64,
}

impl StepInWindow {
    /// Whether the first run's track holds one gap over the window's rows after the step.
    pub fn first_holds_one_gap(&self, report: &CloseLoopReport) -> bool {
        report
            .theta_track
            .as_ref()
            .is_some_and(|t| one_gap_after(t, self.day, self.end, self.size.abs()))
    }

    /// Whether the run calibrated after the step holds one gap after it, when the first run's
    /// track could not tell: its track's level, from the first window wholly after the step to
    /// the record's end, moves by no more than [`STEP_SHARE`] of the step. A first calibration
    /// fitted across a large step late in the window reads the gap after it through a
    /// discrepancy fitted to the mixture, and its track can swing by the step's size from day to
    /// day (seed 1004's 20-in step from day 30: 96-112 in over the window's last six days);
    /// calibrated on the rows after the step, the track is read by a model at that gap. The
    /// second track is read to the record's end, not the window's: a growth's largest one-row
    /// step late in the window leaves two or three days of it, over which a growth of a tenth
    /// of an inch a day stays within a quarter of a one-row step of 0.36 in (seed 1002's
    /// medium growth from day 5, accepted on the window's days and reported 96.34 ± 0.16 in
    /// for 98). A later change of the gap keeps the first run's answer.
    pub fn second_holds_one_gap(&self, report: &CloseLoopReport) -> bool {
        report
            .theta_track
            .as_ref()
            .is_some_and(|t| one_gap_after(t, self.day, f64::INFINITY, self.size.abs()))
    }
}

/// The step the first run's gap correction holds inside the window, when at least
/// `MIN_COMPLETE_ROWS` of the window's rows (and not all of them) come after it.
pub(crate) fn step_in_window(
    report: &CloseLoopReport,
    rec: &MeasuredRecord,
    cal: &[usize],
) -> Option<StepInWindow> {
    let p = report.parameter_correction.as_ref()?;
    let (day, (before, after)) = (p.step_day?, p.step_levels?);
    let rows: Vec<usize> = cal
        .iter()
        .copied()
        .filter(|&i| rec.time_h[i] / 24.0 >= day)
        .collect();
    let end = rec.time_h[*cal.last()?] / 24.0;
    if rows.len() < MIN_COMPLETE_ROWS || rows.len() >= cal.len() {
        return None;
    }
    Some(StepInWindow {
        day,
        rows,
        size: after - before,
        end,
    })
}

/// Share of the step's size by which the track's level may move between the first window
/// wholly after the step and the last one in the calibration window for those rows to hold one
/// gap. A step leaves the level flat to the track's noise (0.1-0.2 in on the panel's design
/// records, steps of 3-20 in); a growth goes on after its largest one-row step, which is about
/// a day's growth, by a day's growth every day. A quarter separates the two by a wide margin
/// either way. Set before any record ran with it, after seed 1001's growths (design records
/// for it) were calibrated after their largest one-row step and took false gain findings.
const STEP_SHARE: f64 = 0.25;

/// Whether the track's smoothed level from the first window wholly after the step (day
/// `day`) to the last window wholly before `end` (the calibration window's last day, or
/// infinity for the record's end) moves by no more than [`STEP_SHARE`] of the step's `size`.
fn one_gap_after(track: &crate::ThetaTrack, day: f64, end: f64, size: f64) -> bool {
    let half = track.config.window_hours / 48.0;
    let levels: Vec<f64> = track
        .points
        .iter()
        .filter(|p| p.day - half >= day && p.day + half <= end + 1e-9)
        .map(|p| p.smoothed.0)
        .collect();
    match (levels.first(), levels.last()) {
        (Some(a), Some(b)) => (b - a).abs() <= STEP_SHARE * size,
        _ => false,
    }
}

/// The second run's outcome with the first calibration's figures as its "before", the first
/// run's answer kept in `after_step`, and the conclusion saying so.
pub(crate) fn merged(
    first: CloseLoopOutcome,
    mut again: CloseLoopOutcome,
    day: f64,
) -> CloseLoopOutcome {
    let f = first.report;
    let r = &mut again.report;
    r.conclusion = format!(
        "the gap stepped inside the calibration window (day {day:.2}): the loop calibrated \
         again on the window's {} rows after it (on the whole window: gap {:.2} ± {:.2}, error \
         {:.2}); {}",
        r.n_calibration,
        f.theta_after.mean,
        f.theta_after.sd,
        f.heldout_rmse_total_after,
        r.conclusion
    );
    r.after_step = Some(CalibratedAfterStep {
        step_day: day,
        calibration_rows: r.n_calibration,
        theta_whole_window: f.theta_after,
        error_whole_window: f.heldout_rmse_total_after,
    });
    first_calibration_as_before(r, f);
    again.residual_before = first.residual_before;
    again
}

/// Whether the track's `alarm` dates the step the loop calibrated after: the calibration's rows
/// start after the record's first row, and the change may begin no later than they do. The
/// first run's gap-alarm guard tested that change and let it stand; the second run's
/// calibration is on its far side, where the guard's test (which reads the rows after the
/// window) cannot see it, and its `θ` is the gap after it.
pub(crate) fn calibrated_after(
    cal: &[usize],
    rec: &MeasuredRecord,
    alarm: &crate::TrackAlarm,
) -> bool {
    cal.first()
        .is_some_and(|&c| c > 0 && alarm.onset_day_interval.0 <= rec.time_h[c] / 24.0)
}

/// The loop run again with the model calibrated on the window's rows before a change of the
/// gap the first run's track dated inside the window (the report's `before_change`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CalibratedBeforeChange {
    /// Day the change's onset interval starts (days since the first row): the calibration
    /// reads the window's rows before it.
    pub change_day: f64,
    /// How many rows that is.
    pub calibration_rows: usize,
    /// `θ` the first run reported (calibrated on the whole window).
    pub theta_whole_window: ThetaSummary,
    /// The error window's RMSE over every gauge after the first run (output units).
    pub error_whole_window: f64,
}

/// A change of the gap inside the calibration window that is not one step: the first run's
/// standing track alarm dates its onset with enough of the window's rows before it.
pub(crate) struct ChangeInWindow {
    /// Start of the onset's 95 % interval (days since the first row).
    pub day: f64,
    /// The calibration window's rows before that day.
    pub rows: Vec<usize>,
}

/// The change the first run's track alarm dates inside the window, when the alarm stands (a
/// withheld alarm is no longer in the track) and at least `MIN_COMPLETE_ROWS` of the window's
/// rows (and not all of them) come before its onset interval.
pub(crate) fn change_in_window(
    report: &CloseLoopReport,
    rec: &MeasuredRecord,
    cal: &[usize],
) -> Option<ChangeInWindow> {
    let alarm = report.theta_track.as_ref()?.alarm.as_ref()?;
    let day = alarm.onset_day_interval.0;
    let rows: Vec<usize> = cal
        .iter()
        .copied()
        .filter(|&i| rec.time_h[i] / 24.0 < day)
        .collect();
    if rows.len() < MIN_COMPLETE_ROWS || rows.len() >= cal.len() {
        return None;
    }
    Some(ChangeInWindow { day, rows })
}

/// The second run's outcome with the first calibration's figures as its "before", the first
/// run's answer kept in `before_change`, and the conclusion saying so.
pub(crate) fn merged_before(
    first: CloseLoopOutcome,
    mut again: CloseLoopOutcome,
    c: &ChangeInWindow,
) -> CloseLoopOutcome {
    let f = first.report;
    let r = &mut again.report;
    r.conclusion = format!(
        "the gap began to change inside the calibration window (from day {:.2}): the loop \
         calibrated again on the window's {} rows before it (on the whole window: gap {:.2} ± \
         {:.2}, error {:.2}); {}",
        c.day,
        c.rows.len(),
        f.theta_after.mean,
        f.theta_after.sd,
        f.heldout_rmse_total_after,
        r.conclusion
    );
    r.before_change = Some(CalibratedBeforeChange {
        change_day: c.day,
        calibration_rows: c.rows.len(),
        theta_whole_window: f.theta_after,
        error_whole_window: f.heldout_rmse_total_after,
    });
    first_calibration_as_before(r, f);
    again.residual_before = first.residual_before;
    again
}

/// The first run's calibration figures as the second run's "before" (the first calibration,
/// on the whole window, is what the loop started from).
fn first_calibration_as_before(r: &mut CloseLoopReport, f: CloseLoopReport) {
    r.n_calibration = f.n_calibration;
    r.noise_sd_estimate = f.noise_sd_estimate;
    r.heldout_rmse_before = f.heldout_rmse_before;
    r.heldout_rmse_total_before = f.heldout_rmse_total_before;
    r.theta_before = f.theta_before;
    r.checks_before = f.checks_before;
    r.model_adequacy_before = f.model_adequacy_before;
}
