//! The whole-record event scan: changes of level in every gauge's final residual, found over
//! the whole record (the newest days included), dated with an interval and sized.
//!
//! The loop fits and selects effects on time windows and needs two rolling-origin folds to
//! accept one, so an event that starts in its last fold or in the test window (a gauge
//! re-zeroed, a debond, a shifted support) is not fitted.
//! The scan does not fit anything: it segments each gauge's residual (data − calibrated model −
//! accepted effects) by [`numerics::changepoint`] (PELT, modified BIC, a robust AR(1)
//! long-run noise scale per gauge) and reports every change it finds as an [`Alarm`]. An alarm
//! is a statement about the data, not an effect: the loop's conclusion names it and never says
//! "no missing effect found" while one stands.

use super::record::MeasuredRecord;
use crate::config::EventScanConfig;
use crate::error::{CloseLoopError, Result};
use nalgebra::DMatrix;
use numerics::changepoint::{MeanChange, detect_mean_changes};
use serde::{Deserialize, Serialize};

/// The noise scale one gauge's residual was judged against.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GaugeScale {
    /// Gauge name.
    pub gauge: String,
    /// Marginal sd of the residual (output units).
    pub marginal_sd: f64,
    /// Lag-1 autocorrelation of its AR(1) reading.
    pub phi: f64,
    /// Long-run sd (output units): the scale of a level difference.
    pub long_run_sd: f64,
}

/// Where an alarm's onset interval lies relative to the loop's windows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlarmWindow {
    /// Inside the rows the loop fits and selects its effects on (the calibration and
    /// validation windows).
    Selection,
    /// Across the boundary between those rows and the test window.
    Split,
    /// In the final test window, which the loop never fits or selects on.
    Test,
}

/// One change of level in one gauge's residual.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Alarm {
    /// Gauge name.
    pub gauge: String,
    /// Time of the first row at the new level (days since the first row).
    pub onset_day: f64,
    /// Interval of the onset at the scan's level (days): after the first and by the second.
    pub onset_day_interval: (f64, f64),
    /// The onset as an ISO 8601 UTC time, when the record's time column was a date.
    pub onset_time: Option<String>,
    /// CSV line of the first row at the new level.
    pub onset_csv_line: u64,
    /// Level after minus level before (output units).
    pub size: f64,
    /// Standard deviation of `size` (output units).
    pub size_sd: f64,
    /// Interval of `size` at the scan's level.
    pub size_interval: (f64, f64),
    /// Where the onset lies.
    pub window: AlarmWindow,
    /// Other gauges with a change whose onset interval overlaps this one.
    pub coincident_gauges: Vec<String>,
    /// One sentence on what it may mean.
    pub reading: String,
}

/// What the scan found.
///
/// ```
/// use bamudi_closeloop::{AlarmWindow, CloseLoopConfig, close_loop};
/// use bamudi_closeloop::testing::{GridCalibrator, ToyGate, record_with};
/// let gate = ToyGate::default();
/// // 30 days hourly; gauge g2 re-zeroed by +6 microstrain at hour 650, in the test window
/// let rec = record_with(&gate, 720, 3, |t, g| if g == 1 && t >= 650.0 { 6.0 } else { 0.0 }).unwrap();
/// let calibrator = GridCalibrator::new(gate, (40.0, 200.0));
/// let out = close_loop(&rec, &calibrator, &CloseLoopConfig::default()).unwrap();
/// let scan = out.report.events.expect("the scan runs by default");
/// assert_eq!(scan.alarms.len(), 1);
/// let a = &scan.alarms[0];
/// assert_eq!((a.gauge.as_str(), a.window), ("g2", AlarmWindow::Test));
/// let (lo, hi) = a.onset_day_interval;
/// assert!(lo <= 650.0 / 24.0 && 650.0 / 24.0 <= hi);
/// assert!(a.size_interval.0 <= 6.0 && 6.0 <= a.size_interval.1);
/// ```
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EventScan {
    /// Method, in one line.
    pub method: String,
    /// The settings used.
    pub config: EventScanConfig,
    /// Per gauge scanned: the noise scale its changes were judged against (a gauge set aside on
    /// more than half its rows is not scanned).
    pub scales: Vec<GaugeScale>,
    /// Every change, in time order.
    pub alarms: Vec<Alarm>,
}

impl EventScan {
    /// Up to `k` alarms, largest `|size| / size_sd` first, in one line each.
    pub fn headline(&self, k: usize, unit: &str) -> Vec<String> {
        let mut order: Vec<&Alarm> = self.alarms.iter().collect();
        order.sort_by(|a, b| {
            (b.size / b.size_sd)
                .abs()
                .total_cmp(&(a.size / a.size_sd).abs())
        });
        order
            .into_iter()
            .take(k)
            .map(|a| {
                format!(
                    "{} {:+.2} ± {:.2} {unit} at day {:.2} [{:.2}, {:.2}] ({})",
                    a.gauge,
                    a.size,
                    0.5 * (a.size_interval.1 - a.size_interval.0),
                    a.onset_day,
                    a.onset_day_interval.0,
                    a.onset_day_interval.1,
                    match a.window {
                        AlarmWindow::Selection => "in the rows selection used",
                        AlarmWindow::Split => "at the start of the test window",
                        AlarmWindow::Test => "in the test window, not fitted",
                    }
                )
            })
            .collect()
    }
}

/// Scans every gauge's residual `r` (`n x N_o`) of `rec`; the first `n_sel` rows are those
/// the loop fitted its effects on. Only the rows the sensor pass did not set aside
/// (`set_aside`) are scanned, and the gauge's noise scale is read from them: on set-aside rows
/// the residual is the model's own prediction or a dead gauge's constant, with no noise to
/// judge a change against (a gauge dead from day 30 used to raise an alarm for every swing of
/// the load after it, against a noise scale of nearly zero). A gauge with fewer than four
/// segments' worth of rows left is not scanned; it is already reported as set aside.
pub(super) fn scan(
    rec: &MeasuredRecord,
    r: &DMatrix<f64>,
    set_aside: &DMatrix<bool>,
    n_sel: usize,
    cfg: &EventScanConfig,
) -> Result<EventScan> {
    let params = cfg.params();
    let (mut scales, mut alarms) = (vec![], vec![]);
    for (g, name) in rec.gauge_names.iter().enumerate() {
        let kept: Vec<usize> = (0..r.nrows()).filter(|&i| !set_aside[(i, g)]).collect();
        if kept.len() < 4 * params.min_segment.max(1) {
            continue;
        }
        let col: Vec<f64> = kept.iter().map(|&i| r[(i, g)]).collect();
        let found = detect_mean_changes(&col, &params).map_err(|e| CloseLoopError::Numerical {
            context: format!("event scan of gauge {name}"),
            reason: e.to_string(),
        })?;
        scales.push(GaugeScale {
            gauge: name.clone(),
            marginal_sd: found.scale.marginal_sd,
            phi: found.scale.phi,
            long_run_sd: found.scale.long_run_sd,
        });
        alarms.extend(
            found
                .changes
                .iter()
                .map(|c| alarm(rec, name, &on_rows(c, &kept), n_sel)),
        );
    }
    mark_coincident(&mut alarms);
    alarms.sort_by(|a, b| a.onset_day.total_cmp(&b.onset_day));
    Ok(EventScan {
        method: "PELT over the whole record per gauge residual, modified BIC penalty, robust AR(1) long-run noise scale; onset intervals from the least-squares location law (Bai 1997)".into(),
        config: cfg.clone(),
        scales,
        alarms,
    })
}

/// Change `c` of the series of `kept` rows, with its rows those of the record: the first row
/// at the new level, and an interval whose row before its start is the kept row before it.
fn on_rows(c: &MeanChange, kept: &[usize]) -> MeanChange {
    let at = |k: usize| kept[k.min(kept.len() - 1)];
    let (lo, hi) = c.interval;
    MeanChange {
        first_row_after: at(c.first_row_after),
        interval: (at(lo.saturating_sub(1)) + usize::from(lo > 0), at(hi)),
        ..*c
    }
}

/// The alarm of change `c` on gauge `name`.
fn alarm(rec: &MeasuredRecord, name: &str, c: &MeanChange, n_sel: usize) -> Alarm {
    let day = |row: usize| rec.time_h[row] / 24.0;
    let (lo, hi) = c.interval;
    let window = if lo > n_sel {
        AlarmWindow::Test
    } else if hi < n_sel {
        AlarmWindow::Selection
    } else {
        AlarmWindow::Split
    };
    let onset_time = (rec.start_unix_s != 0.0)
        .then(|| {
            let s = rec.start_unix_s + rec.time_h[c.first_row_after] * 3600.0;
            jiff::Timestamp::from_second(s.round() as i64).ok()
        })
        .flatten()
        .map(|t| t.to_string());
    Alarm {
        gauge: name.to_string(),
        onset_day: day(c.first_row_after),
        onset_day_interval: (day(lo - 1), day(hi)),
        onset_time,
        onset_csv_line: rec.source_lines[c.first_row_after],
        size: c.size,
        size_sd: c.size_sd,
        size_interval: (c.size - c.size_half_width, c.size + c.size_half_width),
        window,
        coincident_gauges: vec![],
        reading: String::new(),
    }
}

/// Fills `coincident_gauges` (overlapping onset intervals on other gauges) and `reading`.
fn mark_coincident(alarms: &mut [Alarm]) {
    let overlaps = |a: &Alarm, b: &Alarm| {
        a.gauge != b.gauge
            && a.onset_day_interval.0 <= b.onset_day_interval.1
            && b.onset_day_interval.0 <= a.onset_day_interval.1
    };
    let coincident: Vec<Vec<String>> = alarms
        .iter()
        .map(|a| {
            let mut g: Vec<String> = alarms
                .iter()
                .filter(|b| overlaps(a, b))
                .map(|b| b.gauge.clone())
                .collect();
            g.dedup();
            g
        })
        .collect();
    for (a, g) in alarms.iter_mut().zip(coincident) {
        a.reading = reading(a.window, g.len());
        a.coincident_gauges = g;
    }
}

/// What an alarm in `window`, shared with `others` gauges, may mean.
fn reading(window: AlarmWindow, others: usize) -> String {
    let cause = if others >= 2 {
        format!(
            "{} gauges change together: a change of the structure, its supports or the loads is more likely than one sensor",
            others + 1
        )
    } else {
        "a change on this gauge alone: a re-zeroed, slipped or debonding sensor is the first suspect".into()
    };
    let when = match window {
        AlarmWindow::Selection => {
            "inside the rows selection used and not explained by the accepted effects (an event in the last rolling-origin fold is not fitted)"
        }
        AlarmWindow::Split => {
            "at the start of the test window: the model and effects fitted before it may not predict the later data at this level, or an event happened then"
        }
        AlarmWindow::Test => "in the test window, which the loop never fits",
    };
    format!("{when}; {cause}")
}
