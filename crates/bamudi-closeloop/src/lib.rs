//! `bamudi-closeloop`: closing the loop with measured data: find what a calibrated model
//! misses, add it as a correction, and re-report.
//!
//! A calibrated model is trusted once its residuals on measured data are explained. Given a
//! measured record ([`parse_csv`]) and a [`Calibrator`] (BA-MUDI on the application's model, or
//! [`testing::GridCalibrator`] in tests), [`close_loop`]:
//!
//! 1. splits the record in time into a calibration window (first
//!    [`CloseLoopConfig::calibration_fraction`]), a validation window cut into rolling-origin
//!    folds ([`CloseLoopConfig::selection_origins`]) and a final test window (last
//!    [`CloseLoopConfig::test_fraction`]) that selection never sees;
//! 2. calibrates on the calibration window and computes residuals and standardised residuals
//!    (residual / predictive sd) on each window, with adequacy checks: bias per output,
//!    variance against the predictive variance, lag-1 autocorrelation and Ljung-Box, and
//!    correlation with every covariate (time, the inputs, the declared load, their rates of
//!    change, and every other CSV column);
//! 3. ranks candidate explanations by the CROSS-VALIDATED mean square error they remove on
//!    the validation window: an open library of [`Effect`]s ([`effects::default_library`]:
//!    gauge offset, drift, offset jump, thermal strain with a fitted lag, load-path
//!    hysteresis, a parameter changing in time, and a data-driven term), each fitted at every
//!    origin on all rows before it and scored up to the next origin; where the
//!    calibrated model would re-absorb functions of the load
//!    ([`CalibratedModel::absorbs_load_functions`], BA-MUDI's discrepancy), jointly with a
//!    smooth function of the load, so that what the first calibration absorbed of an effect
//!    does not hide it;
//! 4. adds each of the most promising candidates ([`CloseLoopConfig::confirm_candidates`]) to
//!    the model, re-calibrates and back-fits on the calibration window (one origin: each
//!    origin would cost a calibration per candidate), re-fits the effects at the later
//!    origins, and accepts the best only if it then lowers the cross-validated mean square
//!    error by more than [`CloseLoopConfig::min_relative_improvement`], or by less but
//!    significantly ([`CloseLoopConfig::improvement_significance`]: a Student t over the
//!    days of the validation window, for an effect below the margin only; a data-driven
//!    term is preferred to the best physical effect only when it beats it by the margin);
//!    repeats until the calibration
//!    and validation residuals pass the checks or nothing improves;
//! 5. re-fits the accepted effects on every row selection used and reports the error before
//!    and after on the test window (`error_window` in the report);
//! 6. scans every gauge's final residual over the whole record, the newest data included, for
//!    changes of level ([`EventScan`]: alarms dated and sized with intervals), and tracks `θ`
//!    through the record ([`ThetaTrack`]: window estimates, a local linear trend with 95 %
//!    bands, `θ` now, a change alarm with its delay).
//!
//! The loop is never told which effect is present; with no effect it reports "no missing
//! effect found". The application renders the [`CloseLoopOutcome`] (the gate's `report.md`,
//! `results.json` and plots live in `bamudi-gate`).
//!
//! ```
//! use bamudi_closeloop::{close_loop, testing::{record_with, GridCalibrator, ToyGate}, CloseLoopConfig};
//! let gate = ToyGate::default();
//! let rec = record_with(&gate, 720, 1, |_, _| 0.0).unwrap(); // 30 days hourly, noise only
//! let out = close_loop(&rec, &GridCalibrator::new(gate, (40.0, 200.0)), &CloseLoopConfig::default()).unwrap();
//! assert!(out.report.effects.is_empty()); // pure noise: nothing to explain
//! ```

/// The crate README's example, compiled and run as a doc test.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctest;

mod config;
mod correct;
mod effect;
pub mod effects;
mod error;
mod events;
mod features;
mod nuisance;
mod record;
mod regime;
mod search;
mod sensor;
pub(crate) mod stats;
#[cfg(any(test, feature = "testing"))]
pub mod testing;
pub(crate) mod track;

pub use bamudi::posterior::ThetaSummary;
pub use config::{CloseLoopConfig, EventScanConfig, LoadSpec, SensorConfig, TrackConfig};
pub use correct::ParameterCorrection;
pub use correct::{OnsetReport, OnsetTest};
pub use effect::{
    Effect, EffectKind, EffectParameter, EffectReport, FitContext, Fitted, ParameterEnd, Term,
    param,
};
pub use effects::LinearTerm;
pub use error::{CloseLoopError, Result};
pub use events::{Alarm, AlarmWindow, EventScan, GaugeScale};
pub use features::{Features, TEMPERATURE_RANGE_C, is_temperature_unit, temperature_range};
pub use record::{IngestConfig, MeasuredRecord, MissingPolicy, from_table, parse_csv, read_csv};
pub use regime::{CalibratedAfterStep, CalibratedBeforeChange};
pub use sensor::{
    AttributionTest, CalibrationRows, SensorAction, SensorFinding, SensorKind, SensorReport,
    WithheldAlarm,
};
pub use stats::{Adequacy, CovariateCorrelation, GaugeCheck};
pub use track::{ThetaTrack, TrackAlarm, TrackAnchor, TrackPoint, TrackState};

use nalgebra::DMatrix;
use nuisance::LoadNuisance;
use search::{Loop, State};
use serde::{Deserialize, Serialize};
use stats::{CheckThresholds, adequacy, mse_rows, rmse_per_column};
use std::sync::Arc;

/// A model calibrated on measured data (BA-MUDI Modules 2-4, or a stand-in), with a scalar
/// parameter `θ`. `Any` lets an application get its own type back from the loop's final
/// model ([`CloseLoopOutcome::model`]; `(m.as_ref() as &dyn Any).downcast_ref::<T>()`), e.g.
/// to push the final calibration through a prediction model.
pub trait CalibratedModel: Send + Sync + std::fmt::Debug + std::any::Any {
    /// Predictive mean and variance of a new measurement (output units and their square) at
    /// the input rows `x`, `θ` marginalised over its posterior; each `n x N_o`.
    fn predict(&self, x: &DMatrix<f64>) -> Result<(DMatrix<f64>, DMatrix<f64>)>;
    /// Mean output conditional on `θ = theta[i]` for row `i` (Eq. 50 at fixed `θ`).
    fn predict_at_theta(&self, x: &DMatrix<f64>, theta: &[f64]) -> Result<DMatrix<f64>>;
    /// Mean outputs at every row of `x` for each of `thetas`, all rows at the same `θ` (one
    /// matrix per `θ`). The default calls [`Self::predict_at_theta`] once per `θ`; a model whose
    /// `θ`-independent part is costly at `x` (BA-MUDI's discrepancy) computes it once.
    ///
    /// ```
    /// use bamudi_closeloop::{CalibratedModel, Calibrator, testing::{GridCalibrator, ToyGate}};
    /// let gate = ToyGate::default();
    /// let rows = [[540.0, 180.0], [500.0, 180.0], [400.0, 180.0]];
    /// let x = nalgebra::DMatrix::from_fn(3, 2, |i, j| rows[i][j]);
    /// let y = nalgebra::DMatrix::from_fn(3, 7, |i, g| gate.strain(rows[i][0], rows[i][1], 90.0)[g]);
    /// let m = GridCalibrator::new(gate, (40.0, 200.0)).calibrate(&x, &y).unwrap();
    /// let at = m.predict_at_thetas(&x, &[80.0, 100.0]).unwrap();
    /// assert_eq!(at[1], m.predict_at_theta(&x, &[100.0; 3]).unwrap());
    /// assert!(at[0] != at[1]); // the gap moves the strains
    /// ```
    fn predict_at_thetas(&self, x: &DMatrix<f64>, thetas: &[f64]) -> Result<Vec<DMatrix<f64>>> {
        thetas
            .iter()
            .map(|&t| self.predict_at_theta(x, &vec![t; x.nrows()]))
            .collect()
    }
    /// Posterior summary of θ.
    fn theta_summary(&self) -> ThetaSummary;
    /// Support of the prior of `θ`.
    fn theta_bounds(&self) -> (f64, f64);
    /// Whether a re-calibration can absorb any smooth function of the inputs at loaded rows
    /// (BA-MUDI's discrepancy `δ(x)` can). The loop then fits each
    /// candidate effect together with such a function, so that the part of an effect that the
    /// current calibration has absorbed does not hide it. Default: `false`.
    ///
    /// ```
    /// use bamudi_closeloop::{CalibratedModel, Calibrator, testing::{GridCalibrator, ToyGate}};
    /// let gate = ToyGate::default();
    /// let rows = [[540.0, 180.0], [500.0, 180.0], [400.0, 180.0]];
    /// let x = nalgebra::DMatrix::from_fn(3, 2, |i, j| rows[i][j]);
    /// let y = nalgebra::DMatrix::from_fn(3, 7, |i, g| gate.strain(rows[i][0], rows[i][1], 90.0)[g]);
    /// let m = GridCalibrator::new(gate, (40.0, 200.0)).calibrate(&x, &y).unwrap();
    /// assert!(!m.absorbs_load_functions()); // θ is its only parameter
    /// ```
    fn absorbs_load_functions(&self) -> bool {
        false
    }
    /// The calibration's own adequacy verdict ([`bamudi::adequacy`]), when it has one: a
    /// discrepancy that absorbed a sensor fault leaves clean residuals but fails it.
    fn adequacy(&self) -> Option<&bamudi::adequacy::AdequacyReport> {
        None
    }
    /// The log evidence of the calibration data, `ln ∫ p(y | θ) p(θ) dθ` (hyper-parameters at
    /// their estimates), when the model has it. The loop compares two relabellings of the same
    /// readings by it (an exchange of channels: which side of its day was wired right); without
    /// it, by the residual's Gaussian profile likelihood on the calibration rows. Default:
    /// `None`.
    fn log_evidence(&self) -> Option<f64> {
        None
    }
}

/// Calibrates a model on input rows `x` and outputs `y` from which the loop has already
/// subtracted the current effect terms.
pub trait Calibrator: Sync {
    /// Runs the calibration.
    fn calibrate(&self, x: &DMatrix<f64>, y: &DMatrix<f64>) -> Result<Box<dyn CalibratedModel>>;
    /// The posterior summary of `θ` alone, for the loop's re-calibrations that read nothing
    /// else (the bootstrap draws of `θ`'s uncertainty, `θ` without the sensor corrections).
    /// It must equal `calibrate(x, y)?.theta_summary()`; an implementation may skip what
    /// does not change `θ` (checks, reports). Default: exactly that.
    ///
    /// ```
    /// use bamudi_closeloop::{Calibrator, testing::{GridCalibrator, ToyGate}};
    /// let gate = ToyGate::default();
    /// let rows = [[540.0, 180.0], [500.0, 180.0], [400.0, 180.0]];
    /// let x = nalgebra::DMatrix::from_fn(3, 2, |i, j| rows[i][j]);
    /// let y = nalgebra::DMatrix::from_fn(3, 7, |i, g| gate.strain(rows[i][0], rows[i][1], 90.0)[g]);
    /// let cal = GridCalibrator::new(gate, (40.0, 200.0));
    /// let theta = cal.calibrate_theta(&x, &y).unwrap();
    /// assert_eq!(theta.mean, cal.calibrate(&x, &y).unwrap().theta_summary().mean);
    /// ```
    fn calibrate_theta(&self, x: &DMatrix<f64>, y: &DMatrix<f64>) -> Result<ThetaSummary> {
        Ok(self.calibrate(x, y)?.theta_summary())
    }
}

/// Score of one candidate at one step.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CandidateScore {
    /// Effect name.
    pub name: String,
    /// Covariates used.
    pub covariates: Vec<String>,
    /// Screening: cross-validated mean square residual on the validation window, the
    /// candidate fitted at each rolling origin on all rows before it (jointly with the load
    /// nuisance where the model absorbs one; microstrain²).
    pub heldout_mse: f64,
    /// Screening: reduction of that mean square residual against the nuisance-only fit (or
    /// the residual itself), relative to the MSE before the step.
    pub relative_improvement: f64,
    /// Cross-validated mean square residual on the validation window after adding the
    /// candidate, re-calibrating and back-fitting on the calibration window, every effect
    /// re-fitted at each later origin (microstrain²); `None` when it was not among the
    /// confirmed candidates.
    #[serde(default)]
    pub recalibrated_heldout_mse: Option<f64>,
    /// Relative reduction of that MSE after re-calibration (what the decision uses).
    #[serde(default)]
    pub recalibrated_relative_improvement: Option<f64>,
    /// Student t of that reduction over the days of the validation window, with the number of
    /// days (`improvement_significance`'s test; `None` when not confirmed, or when the t is
    /// infinite because the reduction is the same every day).
    #[serde(default)]
    pub recalibrated_improvement_t: Option<(f64, usize)>,
}

/// One iteration of the loop.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StepReport {
    /// Step number (1-based).
    pub step: usize,
    /// Cross-validated mean square residual on the validation window before this step
    /// (microstrain²).
    pub heldout_mse_before: f64,
    /// Candidates, best first.
    pub candidates: Vec<CandidateScore>,
    /// Accepted effect, if any.
    pub accepted: Option<String>,
    /// Why the step ended as it did.
    pub decision: String,
    /// Cross-validated RMSE per gauge on the validation window after the step (output units).
    pub heldout_rmse_after: Vec<f64>,
    /// θ after re-calibration.
    pub theta_after: ThetaSummary,
}

/// Everything `results.json` holds (keys documented in `docs/closeloop.md`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CloseLoopReport {
    /// Source file.
    pub file: String,
    /// Gauge names.
    pub gauge_names: Vec<String>,
    /// Rows used.
    pub n_rows: usize,
    /// Rows in the calibration window.
    pub n_calibration: usize,
    /// Rows after the calibration window (validation and test windows).
    pub n_heldout: usize,
    /// Rows in the validation window (rolling-origin selection).
    #[serde(default)]
    pub n_validation: usize,
    /// Rows in the final test window (never used by selection; 0 when `test_fraction` is 0).
    #[serde(default)]
    pub n_test: usize,
    /// Rows dropped for missing gauge values.
    pub dropped_missing: usize,
    /// Gauge cells imputed.
    pub imputed: usize,
    /// Day at which the validation window starts (days since the first row).
    pub split_day: f64,
    /// Day at which the test window starts (`None` without one).
    #[serde(default)]
    pub test_start_day: Option<f64>,
    /// Days of the rolling-origin evaluation origins (the first is `split_day`).
    #[serde(default)]
    pub selection_origin_days: Vec<f64>,
    /// Which rows `heldout_rmse_*` are computed on: `test` (the final test window, never used
    /// by selection) or `validation` (when `test_fraction` is 0; selection saw those rows).
    #[serde(default)]
    pub error_window: String,
    /// White-noise sd estimated from first differences of the initial residuals (microstrain).
    pub noise_sd_estimate: f64,
    /// Accepted effects in order, with final parameters.
    pub effects: Vec<EffectReport>,
    /// RMSE per gauge before the loop on the error window ([`Self::error_window`]: the
    /// test window; microstrain).
    pub heldout_rmse_before: Vec<f64>,
    /// RMSE per gauge after the loop on the error window, with every accepted effect fitted
    /// on all rows before it (microstrain); `NaN` (JSON `null`) for a gauge set aside on every
    /// row of the window.
    #[serde(deserialize_with = "stats::nan_as_null::vec")]
    pub heldout_rmse_after: Vec<f64>,
    /// RMSE over all gauges before, on the error window (microstrain).
    pub heldout_rmse_total_before: f64,
    /// RMSE over all gauges after, on the error window (microstrain).
    pub heldout_rmse_total_after: f64,
    /// θ (in) of the first calibration.
    pub theta_before: ThetaSummary,
    /// θ (in) after the loop; the track's value at the end of the record when a time-varying
    /// gap was accepted or the track's change alarm stands (`theta_after_basis` says which).
    pub theta_after: ThetaSummary,
    /// What `theta_after` refers to.
    pub theta_after_basis: String,
    /// Adequacy of the initial residuals (calibration, validation, test windows).
    pub checks_before: Vec<Adequacy>,
    /// Adequacy of the final residuals: calibration and validation windows as selection saw
    /// them (validation: cross-validated residual), the test window with the effects fitted
    /// on all rows before it.
    pub checks_after: Vec<Adequacy>,
    /// Every step.
    pub steps: Vec<StepReport>,
    /// One-sentence conclusion.
    pub conclusion: String,
    /// The first calibration's adequacy verdict (when the calibrated model has one).
    #[serde(default)]
    pub model_adequacy_before: Option<bamudi::adequacy::AdequacyReport>,
    /// The final calibration's adequacy verdict.
    #[serde(default)]
    pub model_adequacy_after: Option<bamudi::adequacy::AdequacyReport>,
    /// Changes of level in the final residual over the whole record, with the gap's change
    /// applied when the track's alarm stands ([`Self::parameter_correction`]; `None` when
    /// disabled).
    #[serde(default)]
    pub events: Option<EventScan>,
    /// The parameter tracked through the record (`None` when disabled).
    #[serde(default)]
    pub theta_track: Option<ThetaTrack>,
    /// Every alarm in one list for the operator, in order of onset: the gauges' changes of
    /// level (from [`Self::events`]) and the gap's change (from [`Self::theta_track`]).
    #[serde(default)]
    pub alarms: Vec<AlarmSummary>,
    /// The gap's change applied as a correction when the track's change alarm stands: the
    /// step it holds, the error window's RMSE with it, and the gauge alarms without it (the
    /// `events` and `alarms` above are the scan's with it). `None` without a standing alarm.
    #[serde(default)]
    pub parameter_correction: Option<ParameterCorrection>,
    /// Wall time of the whole loop on this record (s).
    #[serde(default)]
    pub wall_time_s: f64,
    /// The sensor pass: every sensor finding with its correction or set-aside span, the
    /// structure-or-sensor tests, and `θ` with and without the corrections (`None` when
    /// disabled).
    #[serde(default)]
    pub sensor: Option<SensorReport>,
    /// The sd the accepted effects' and corrections' parameters add to `theta_after` (in
    /// `θ`'s unit; already in `theta_after`'s sd and interval); `None` when nothing was
    /// propagated.
    #[serde(default)]
    pub theta_after_effect_sd: Option<f64>,
    /// The gap's change dated inside the calibration window, and the loop run again on the
    /// window's rows after it (everything above is that run's, but for the first
    /// calibration's figures: `*_before`, `checks_before`, `noise_sd_estimate`,
    /// `n_calibration`); `None` when the loop ran once.
    #[serde(default)]
    pub after_step: Option<CalibratedAfterStep>,
    /// The gap's change dated inside the calibration window by the first run's track, and the
    /// loop run again with the model calibrated on the window's rows before it (everything
    /// above is that run's, but for the first calibration's figures, as with `after_step`);
    /// `None` when the loop did not.
    #[serde(default)]
    pub before_change: Option<CalibratedBeforeChange>,
    /// The changes seen on several gauges together after the calibration window, each tested
    /// for a library effect from its day on beside the gap and one sensor, and the effects
    /// added (`None` when no such change was seen, or `sensor.onset_effects` is off).
    #[serde(default)]
    pub onset: Option<OnsetReport>,
}

/// Result of [`close_loop`]: the report plus the residual series used for the plots.
#[derive(Debug, Clone)]
pub struct CloseLoopOutcome {
    /// The serialisable report.
    pub report: CloseLoopReport,
    /// The loop's final calibration (on the data with the accepted effects removed).
    pub model: Arc<dyn CalibratedModel>,
    /// Residuals before the loop (`n x N_o`, microstrain).
    pub residual_before: DMatrix<f64>,
    /// Residuals after the loop.
    pub residual_after: DMatrix<f64>,
    /// Rows of the error window (the test window, or the validation window without one).
    pub heldout_rows: Vec<usize>,
    /// Feature names and values, for plotting residuals against covariates.
    pub features: Vec<(String, Vec<f64>)>,
    /// The covariate that best shows each accepted effect.
    pub effect_plot_covariates: Vec<String>,
}

/// Runs the loop on a measured record with the [default library](effects::default_library).
/// See the module docs.
pub fn close_loop(
    rec: &MeasuredRecord,
    calibrator: &dyn Calibrator,
    cfg: &CloseLoopConfig,
) -> Result<CloseLoopOutcome> {
    close_loop_with(rec, calibrator, cfg, &effects::default_library(rec, cfg))
}

/// Runs the loop with the given effect library (e.g. the default one plus effects of your
/// own).
pub fn close_loop_with(
    rec: &MeasuredRecord,
    calibrator: &dyn Calibrator,
    cfg: &CloseLoopConfig,
    library: &[Arc<dyn Effect>],
) -> Result<CloseLoopOutcome> {
    cfg.validate()?;
    if rec.gauge_names.is_empty() {
        return Err(CloseLoopError::config(
            "gauge_columns",
            format!(
                "{}: the record has no gauge columns to close the loop on",
                rec.file
            ),
        ));
    }
    cfg.check_columns(&rec.file, &rec.covariate_names)?;
    features::check_covariate_values(rec, &cfg.column_units)?;
    let started = std::time::Instant::now();
    let w = Windows::of(rec, cfg)?;
    let first = run_on(rec, calibrator, cfg, library, &w)?;
    // a step inside the window: calibrated after it when the rows after it hold one gap
    let after_step = match regime::step_in_window(&first.report, rec, &w.cal) {
        Some(s) => {
            let again = Windows {
                cal: s.rows.clone(),
                step: Some(s.size),
                ..w.clone()
            };
            let out = run_on(rec, calibrator, cfg, library, &again)?;
            (s.first_holds_one_gap(&first.report) || s.second_holds_one_gap(&out.report))
                .then_some((out, s.day))
        }
        None => None,
    };
    // otherwise a change the track dates inside the window (a growth, or a step whose rows
    // after it do not hold one gap): calibrated before it
    let mut out = match after_step {
        Some((out, day)) => regime::merged(first, out, day),
        None => match regime::change_in_window(&first.report, rec, &w.cal) {
            Some(c) => {
                let again = Windows {
                    calibrate_on: Some(c.rows.clone()),
                    ..w
                };
                let out = run_on(rec, calibrator, cfg, library, &again)?;
                // the run is there for the change the first run's alarm dated: one whose track
                // raises no alarm (a growth from the record's first rows leaves it no rows at
                // the old gap to compare with) would drop the alarm, so the first run stands
                match out
                    .report
                    .theta_track
                    .as_ref()
                    .is_some_and(|t| t.alarm.is_some())
                {
                    true => regime::merged_before(first, out, &c),
                    false => first,
                }
            }
            None => first,
        },
    };
    out.report.wall_time_s = started.elapsed().as_secs_f64();
    Ok(out)
}

/// The loop on the windows `w`: the first calibration on `w.cal`, the sensor pass, selection
/// and the post-selection pass.
fn run_on(
    rec: &MeasuredRecord,
    calibrator: &dyn Calibrator,
    cfg: &CloseLoopConfig,
    library: &[Arc<dyn Effect>],
    w: &Windows,
) -> Result<CloseLoopOutcome> {
    let feats = Features::new(rec, cfg.load.as_ref(), &cfg.column_units);
    let lp = Loop {
        calibrator,
        x: &rec.x,
        y: &rec.y,
        feats: &feats,
        cal: &w.cal,
        calib: w.calib(),
        fit_rows: w.calib(),
        val: &w.validation,
        sel: &w.selection,
        test: &w.test,
        folds: &w.folds,
        gauges: &rec.gauge_names,
        cfg,
        nuisance: cfg
            .load
            .as_ref()
            .and_then(|l| LoadNuisance::new(&rec.x, l, &w.cal)),
        step: w.step,
    };
    let (model, mean, var) = lp.calibrate(lp.y)?;
    let mut before = Before::of(&lp, model.theta_summary(), &mean, &var);
    before.adequacy = model.adequacy().cloned();
    let mut st = State::calibrated((model, mean, var));
    // the sensor pass first: the loop then looks for effects in corrected readings
    let mut pre = match cfg.sensor.enabled {
        true => correct::pre_pass(&lp, rec, &st)?,
        false => correct::PrePass {
            findings: vec![],
            tests: vec![],
            coincident: vec![],
            relabelled: None,
        },
    };
    let base = pre.relabelled.take();
    let first = base.as_ref().map_or(&st, |b| &b.state).clone();
    let applied = correct::apply_and_recalibrate(&lp, rec, &mut pre, &first, base)?;
    let lp_y = lp.with_y(&applied.y);
    let lp = lp_y.with_fit_rows(applied.rows.rows(w.calib()));
    if let Some(s) = applied.state {
        st = s;
    }
    let (steps, conclusion) = run_steps(&lp, &mut st, library)?;
    let run = Run {
        before,
        st,
        steps,
        conclusion,
        pre,
    };
    outcome(&lp, rec, run, library)
}

/// The record's rows in time order: the calibration window, the validation window (cut into
/// rolling-origin folds) and the final test window that selection never sees. The loop run
/// again after a change of the gap inside the calibration window calibrates on the window's
/// rows after it ([`regime`]): `cal` then starts later, and effects are fitted from its first
/// row.
#[derive(Clone)]
struct Windows {
    cal: Vec<usize>,
    /// The window's rows the calibrator reads when not all of `cal`: those before the gap
    /// began to move inside the window ([`regime::ChangeInWindow`]).
    calibrate_on: Option<Vec<usize>>,
    /// The gap's step when the loop runs again after it ([`Loop::step`]).
    step: Option<f64>,
    validation: Vec<usize>,
    selection: Vec<usize>,
    test: Vec<usize>,
    /// `(origin, end)` of each fold: fitted on rows `0..origin`, scored on `origin..end`.
    folds: Vec<(usize, usize)>,
}

impl Windows {
    fn of(rec: &MeasuredRecord, cfg: &CloseLoopConfig) -> Result<Self> {
        let n = rec.len();
        let n_cal = (cfg.calibration_fraction * n as f64).round() as usize;
        let n_test = (cfg.test_fraction * n as f64).round() as usize;
        let n_sel = n.saturating_sub(n_test);
        if n_cal < 30 || n_sel < n_cal + 30 || (cfg.test_fraction > 0.0 && n_test < 30) {
            return Err(CloseLoopError::TooFewRows {
                what: format!(
                    "calibration, validation and test windows (30 rows each; calibration_fraction {}, test_fraction {})",
                    cfg.calibration_fraction, cfg.test_fraction
                ),
                got: n,
            });
        }
        // folds of at least MIN_FOLD_ROWS rows, so that each scores a stretch of the record
        let k = cfg
            .selection_origins
            .min((n_sel - n_cal) / MIN_FOLD_ROWS)
            .max(1);
        let origin = |j: usize| n_cal + (j * (n_sel - n_cal)) / k;
        Ok(Self {
            cal: (0..n_cal).collect(),
            calibrate_on: None,
            step: None,
            validation: (n_cal..n_sel).collect(),
            selection: (0..n_sel).collect(),
            test: (n_sel..n).collect(),
            folds: (0..k).map(|j| (origin(j), origin(j + 1))).collect(),
        })
    }
}

impl Windows {
    /// The window's rows the calibrator reads.
    fn calib(&self) -> &[usize] {
        self.calibrate_on.as_deref().unwrap_or(&self.cal)
    }
}

/// Fewest validation rows a rolling-origin fold scores (a day of hourly data).
const MIN_FOLD_ROWS: usize = 24;

/// A finished run of the loop.
struct Run {
    before: Before,
    st: State,
    steps: Vec<StepReport>,
    conclusion: String,
    /// The sensor pass before selection.
    pre: correct::PrePass,
}

/// The checks, error and `θ` of the first calibration.
struct Before {
    residual: DMatrix<f64>,
    checks: Vec<Adequacy>,
    rmse: Vec<f64>,
    noise_sd: f64,
    theta: ThetaSummary,
    adequacy: Option<bamudi::adequacy::AdequacyReport>,
}

impl Before {
    fn of(lp: &Loop<'_>, theta: ThetaSummary, mean: &DMatrix<f64>, var: &DMatrix<f64>) -> Self {
        let r0 = lp.y - mean;
        let mut noise: Vec<f64> = (0..r0.ncols())
            .map(|j| {
                let col: Vec<f64> = lp.cal.iter().map(|&i| r0[(i, j)]).collect();
                numerics::robust::noise_sd_from_differences(&col)
            })
            .collect();
        noise.sort_by(|a, b| a.total_cmp(b));
        let mut checks = windows(lp, &r0, &r0, var);
        checks.extend(test_window(lp, &r0, var));
        Self {
            checks,
            rmse: rmse_per_column(&r0, lp.error_rows()),
            noise_sd: noise[noise.len() / 2],
            theta,
            adequacy: None,
            residual: r0,
        }
    }
}

/// The thresholds of the adequacy checks.
fn thresholds(lp: &Loop<'_>) -> CheckThresholds {
    CheckThresholds {
        ljung_box_lags: lp.cfg.ljung_box_lags,
        significance: lp.cfg.significance,
    }
}

/// The adequacy checks selection may look at: the calibration window on the residual `r`
/// (effects fitted there) and the validation window on the cross-validated residual `r_cv`.
fn windows(
    lp: &Loop<'_>,
    r: &DMatrix<f64>,
    r_cv: &DMatrix<f64>,
    var: &DMatrix<f64>,
) -> Vec<Adequacy> {
    let th = thresholds(lp);
    vec![
        adequacy("calibration", r, var, lp.cal, lp.gauges, lp.feats, &th),
        adequacy("validation", r_cv, var, lp.val, lp.gauges, lp.feats, &th),
    ]
}

/// The adequacy checks of the final test window (reported only; `None` without one).
fn test_window(lp: &Loop<'_>, r: &DMatrix<f64>, var: &DMatrix<f64>) -> Option<Adequacy> {
    let th = thresholds(lp);
    (!lp.test.is_empty()).then(|| adequacy("test", r, var, lp.test, lp.gauges, lp.feats, &th))
}

/// The loop's steps until the checks pass, nothing improves or the step budget is spent;
/// returns the step reports and the conclusion. Decisions use the calibration and validation
/// windows only.
fn run_steps(
    lp: &Loop<'_>,
    st: &mut State,
    library: &[Arc<dyn Effect>],
) -> Result<(Vec<StepReport>, String)> {
    let mut steps = vec![];
    for step in 1..=lp.cfg.max_steps {
        let fold_r = lp.fold_residuals(st)?;
        let r_cv = lp.cv_of(&fold_r);
        let checks = windows(lp, &fold_r[0], &r_cv, &st.var);
        if checks.iter().all(Adequacy::passed) && !model_inadequate(st) {
            let c = if st.effects.is_empty() {
                "no missing effect found: residuals pass every adequacy check"
            } else {
                "residuals pass every adequacy check after the accepted effects"
            };
            return Ok((steps, c.into()));
        }
        let mse_before = mse_rows(&r_cv, lp.val);
        let (candidates, outcome) = lp.search(st, library, &fold_r, mse_before)?;
        let mut report = StepReport {
            step,
            heldout_mse_before: mse_before,
            candidates,
            accepted: None,
            decision: outcome.decision.clone(),
            heldout_rmse_after: rmse_per_column(&r_cv, lp.val),
            theta_after: search::theta_now(st).0,
        };
        let Some((next, name, decision)) = outcome.accepted else {
            steps.push(report);
            return Ok((steps, stop_conclusion(st, &outcome.decision, &checks)));
        };
        *st = next;
        report.accepted = Some(name);
        report.decision = decision;
        report.heldout_rmse_after = rmse_per_column(&lp.cv_residual(st)?, lp.val);
        report.theta_after = search::theta_now(st).0;
        steps.push(report);
    }
    Ok((
        steps,
        format!("stopped at the maximum of {} effects", lp.cfg.max_steps),
    ))
}

/// Whether the current calibration's own verdict says its model does not explain the data.
fn model_inadequate(st: &State) -> bool {
    st.model
        .adequacy()
        .is_some_and(|a| a.verdict == bamudi::adequacy::Verdict::Inadequate)
}

/// Why the loop stopped when a step accepted nothing. "No missing effect found" is never
/// said while a check fails: the conclusion then names what is unexplained.
fn stop_conclusion(st: &State, decision: &str, checks: &[Adequacy]) -> String {
    let mut unexplained: Vec<String> = checks
        .iter()
        .flat_map(|c| {
            c.failures
                .iter()
                .map(move |f| format!("{} window: {f}", c.window))
        })
        .take(3)
        .collect();
    let failures: usize = checks.iter().map(|c| c.failures.len()).sum();
    if failures > unexplained.len() {
        unexplained.push(format!(
            "{} more residual check(s)",
            failures - unexplained.len()
        ));
    }
    if let Some(a) = st.model.adequacy().filter(|_| model_inadequate(st)) {
        unexplained.push(format!("the calibration's verdict: {}", a.summary()));
    }
    let head = match st.effects.len() {
        0 => "no effect in the library explains the data".to_string(),
        n => format!("stopped after {n} effect(s)"),
    };
    format!(
        "{head}; unexplained: {}; {decision}",
        unexplained.join("; ")
    )
}

/// The conclusion with the alarms: "no missing effect found" is never said while the
/// whole-record scan finds a change of level in a residual or the parameter's track raises
/// its change alarm.
fn with_alarms(
    conclusion: String,
    scan: Option<&EventScan>,
    track: Option<&ThetaTrack>,
    unit: &str,
) -> String {
    let mut found = vec![];
    if let Some(scan) = scan.filter(|s| !s.alarms.is_empty()) {
        let n = scan.alarms.len();
        found.push(format!(
            "the whole-record scan finds {n} change(s) of level in the residual: {}{}",
            scan.headline(3, unit).join("; "),
            if n > 3 { "; ..." } else { "" }
        ));
    }
    if let Some(a) = track.and_then(|t| t.alarm.as_ref()) {
        found.push(format!(
            "the parameter's track raises a change alarm: {} detected on day {:.2}, onset day {:.2} (95 %: {:.2} – {:.2}), size {:+.3} ± {:.3}",
            a.direction,
            a.day,
            a.onset_day,
            a.onset_day_interval.0,
            a.onset_day_interval.1,
            a.size,
            a.size_sd
        ));
    }
    if found.is_empty() {
        return conclusion;
    }
    let found = found.join("; ");
    match conclusion.strip_prefix("no missing effect found: ") {
        Some(rest) => format!("{rest}, but {found}"),
        None => format!("{conclusion}; {found}"),
    }
}

/// The candidate features by name, with their columns (for the plots).
fn feature_columns(lp: &Loop<'_>) -> Vec<(String, Vec<f64>)> {
    let f = lp.feats;
    f.names
        .iter()
        .cloned()
        .zip(f.cols.iter().cloned())
        .collect()
}

/// The RMSE over every gauge from per-gauge RMSEs (the report's `heldout_rmse_total_*` from
/// `heldout_rmse_*`, and the same total of `ParameterCorrection::error_rmse` or a sensor
/// report's per-gauge figures); a gauge set aside over the whole error window has no error
/// (`NaN`) and is left out; `0` when no gauge has one.
///
/// ```
/// let per_gauge = [3.0, f64::NAN, 4.0]; // microstrain; the second gauge set aside
/// let total = bamudi_closeloop::rmse_over_gauges(&per_gauge);
/// assert!((total - 12.5f64.sqrt()).abs() < 1e-12);
/// ```
pub fn rmse_over_gauges(v: &[f64]) -> f64 {
    let ok: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    (ok.iter().map(|x| x * x).sum::<f64>() / ok.len().max(1) as f64).sqrt()
}

/// The conclusion with the sensor findings first: what was corrected or set aside is said
/// before anything else, and "no missing effect found" is not said when something was.
/// The selection's final state, the post-selection pass on it, and the test window's error and
/// checks after both.
fn after_selection(
    lp: &Loop<'_>,
    rec: &MeasuredRecord,
    st: State,
    pre: correct::PrePass,
    library: &[Arc<dyn Effect>],
) -> Result<(correct::PostPass, Vec<f64>, Vec<Adequacy>)> {
    let Final {
        st,
        residual,
        rmse,
        checks: mut checks_after,
    } = final_state(lp, st)?;
    let post = correct::post_pass(lp, rec, st, residual, pre, library)?;
    let rmse_after = correct::test_error(lp, rec, &post, rmse, &mut checks_after)?;
    Ok((post, rmse_after, checks_after))
}

/// The onset step's report, with the error window's RMSE once an effect was added (in-sample).
fn onset_report(lp: &Loop<'_>, post: &correct::PostPass) -> Option<OnsetReport> {
    post.onset.clone().map(|mut o| {
        if !o.added.is_empty() {
            o.error_rmse_with = Some(sensor::rmse_unmasked(
                &post.residual,
                lp.error_rows(),
                &post.mask,
            ));
        }
        o
    })
}

/// The conclusion with the effects added from an onset after selection ([`onset`]).
fn with_onset(conclusion: String, onset: Option<&OnsetReport>) -> String {
    let Some(o) = onset else {
        return conclusion;
    };
    let added: Vec<String> = o
        .tests
        .iter()
        .filter(|t| t.verdict == "effect")
        .map(|t| {
            format!(
                "{} added from day {:.2}, where {} changed together (score {:.0} against {:.0} for a change of the parameter and {:.0} for one sensor; fitted on the rows from that day, the test window's included)",
                t.effect_name.as_deref().unwrap_or("an effect"),
                t.from_day,
                t.gauges.join(", "),
                t.effect.unwrap_or(f64::NAN),
                t.structure,
                t.sensor
            )
        })
        .collect();
    if added.is_empty() {
        return conclusion;
    }
    let rest = conclusion
        .strip_prefix("no missing effect found: ")
        .unwrap_or(&conclusion);
    format!("{rest}; after selection, {}", added.join("; "))
}

fn with_sensor(conclusion: String, sensor: Option<&SensorReport>) -> String {
    let Some(s) = sensor.filter(|s| !s.findings.is_empty()) else {
        return conclusion;
    };
    let what: Vec<String> = s.findings.iter().map(SensorFinding::describe).collect();
    let rest = conclusion
        .strip_prefix("no missing effect found: ")
        .unwrap_or(&conclusion);
    let withheld = s.withheld_gap_alarm.as_ref().map_or(String::new(), |w| {
        format!(
            "; the parameter's change alarm ({} of {:.2} from day {:.2}) is withheld: {}",
            w.alarm.direction, w.alarm.size, w.alarm.onset_day, w.reason
        )
    });
    format!(
        "sensor findings: {}; then {rest}{withheld}",
        what.join("; ")
    )
}

/// The whole-record analyses of the final state: the event scan and the parameter's track
/// (each `None` when disabled).
fn whole_record(
    lp: &Loop<'_>,
    rec: &MeasuredRecord,
    st: &State,
    r_final: &DMatrix<f64>,
    set_aside: &DMatrix<bool>,
) -> Result<(Option<EventScan>, Option<ThetaTrack>)> {
    let events = match lp.cfg.event_scan.enabled {
        true => Some(events::scan(
            rec,
            r_final,
            set_aside,
            lp.sel.len(),
            &lp.cfg.event_scan,
        )?),
        false => None,
    };
    let track = match lp.cfg.track.enabled {
        true => Some(track_theta(lp, rec, st, r_final)?),
        false => None,
    };
    Ok((events, track))
}

/// The parameter tracked over the record with the final model, on the data minus the
/// accepted additive effects (a parameter trend is what the track replaces, so it is left in).
fn track_theta(
    lp: &Loop<'_>,
    rec: &MeasuredRecord,
    st: &State,
    r_final: &DMatrix<f64>,
) -> Result<ThetaTrack> {
    let mut target = lp.y.clone();
    for (e, c) in st.effects.iter().zip(lp.contributions(st)?) {
        if !e.effect.keeps_model_fixed() {
            target -= c;
        }
    }
    let mut calibrated = vec![false; rec.time_h.len()];
    for &i in lp.calib {
        calibrated[i] = true;
    }
    let input = track::TrackInput {
        model: st.model.as_ref(),
        x: lp.x,
        target: &target,
        time_h: &rec.time_h,
        noise_sd: stats::median_noise_sd(r_final),
        calibrated: Some(&calibrated),
    };
    track::track(&input, &lp.cfg.track)
}

/// `θ` after the loop, what it refers to, and whether it is the track's (then the effects'
/// parameter uncertainty is not propagated onto it: the track's sd is its own).
///
/// The track's `θ` now is taken when a parameter trend was accepted, or when the track's change
/// alarm stands (after the sensor pass's guard): the user is told the gap changed, so the gap
/// reported must be the one after the change, not the calibration's from before it.
///
/// When the alarm dates the step the loop calibrated after ([`regime`]), the calibration's
/// value is the gap after the change and is kept.
fn theta_after(
    st: &State,
    track: Option<&ThetaTrack>,
    calibrated_after: bool,
) -> (ThetaSummary, String, bool) {
    match track {
        Some(t) if st.model_fixed() => (
            t.now,
            "the parameter at the end of the record from its track over the whole record (Kalman filter at the last window)".to_string(),
            true,
        ),
        Some(t) if t.alarm.is_some() && !calibrated_after && t.now.mean.is_finite() => (
            t.now,
            "the parameter at the end of the record from its track: the track's change alarm stands, so the calibration's value (from before the change) is no longer the gap now".to_string(),
            true,
        ),
        _ => {
            let (t, basis) = search::theta_now(st);
            (t, basis, false)
        }
    }
}

/// The gap after the loop and the sensor pass's report.
struct TheGap {
    theta_after: ThetaSummary,
    basis: String,
    effect_sd: Option<f64>,
    sensor_report: Option<SensorReport>,
}

/// `θ` after the loop ([`theta_after`]), widened for the effects' parameters when it is a
/// calibration's, and the sensor report, whose gaps with and without the corrections are both
/// a calibration's (the track's gap after a change would make the change look like the
/// corrections' doing).
fn the_gap(lp: &Loop<'_>, rec: &MeasuredRecord, post: &correct::PostPass) -> Result<TheGap> {
    let after = post
        .track
        .as_ref()
        .and_then(|t| t.alarm.as_ref())
        .is_some_and(|a| regime::calibrated_after(lp.cal, rec, a));
    let (theta, basis, from_track) = theta_after(&post.st, post.track.as_ref(), after);
    let (theta_after, effect_sd) = match from_track {
        true => (theta, None),
        false => correct::propagate(&lp.with_y(&post.y), rec, post, theta)?,
    };
    let calibrated = match from_track {
        true => search::theta_now(&post.st).0,
        false => theta_after,
    };
    Ok(TheGap {
        theta_after,
        basis,
        effect_sd,
        sensor_report: correct::report(lp, rec, post, calibrated)?,
    })
}

/// The state selection chose, made final.
struct Final {
    /// Its effects re-fitted on every row selection used.
    st: State,
    /// Its residual at every row.
    residual: DMatrix<f64>,
    /// RMSE per gauge on the error window: the test window, or without one the validation
    /// window's cross-validated residual (the re-fitted effects have seen those rows).
    rmse: Vec<f64>,
    /// The calibration and validation windows as selection saw them, then the test window.
    checks: Vec<Adequacy>,
}

fn final_state(lp: &Loop<'_>, mut st: State) -> Result<Final> {
    let fold_r = lp.fold_residuals(&st)?;
    let r_cv = lp.cv_of(&fold_r);
    let mut checks = windows(lp, &fold_r[0], &r_cv, &st.var);
    let (residual, refitted) = match st.effects.is_empty() {
        true => (fold_r[0].clone(), vec![]),
        false => lp.refit(&st, lp.sel, true)?,
    };
    st.effects = refitted;
    checks.extend(test_window(lp, &residual, &st.var));
    let rmse = match lp.test.is_empty() {
        true => rmse_per_column(&r_cv, lp.val),
        false => rmse_per_column(&residual, lp.test),
    };
    Ok(Final {
        st,
        residual,
        rmse,
        checks,
    })
}

/// The report's description of the loop's windows.
fn window_fields(lp: &Loop<'_>, rec: &MeasuredRecord) -> WindowFields {
    let day = |i: usize| rec.time_h[i] / 24.0;
    WindowFields {
        n_validation: lp.val.len(),
        n_test: lp.test.len(),
        split_day: day(lp.cal.last().map_or(0, |&i| i + 1)),
        test_start_day: lp.test.first().map(|&i| day(i)),
        selection_origin_days: lp.folds.iter().map(|&(o, _)| day(o)).collect(),
        error_window: match lp.test.is_empty() {
            true => "validation".into(),
            false => "test".into(),
        },
    }
}

/// The loop's windows as the report states them (see [`CloseLoopReport`]'s fields).
struct WindowFields {
    n_validation: usize,
    n_test: usize,
    split_day: f64,
    test_start_day: Option<f64>,
    selection_origin_days: Vec<f64>,
    error_window: String,
}

/// Assembles the outcome of a finished run: the selection's checks on the state it chose,
/// then every accepted effect re-fitted on all the rows selection used and the error on the
/// test window that selection never saw.
fn outcome(
    lp: &Loop<'_>,
    rec: &MeasuredRecord,
    run: Run,
    library: &[Arc<dyn Effect>],
) -> Result<CloseLoopOutcome> {
    let Run {
        before,
        st,
        steps,
        conclusion,
        pre,
    } = run;
    let (post, rmse_after, checks_after) = after_selection(lp, rec, st, pre, library)?;
    let onset = onset_report(lp, &post);
    let (events, theta_track) = (post.events.clone(), post.track.clone());
    let TheGap {
        theta_after,
        basis,
        effect_sd,
        sensor_report,
    } = the_gap(lp, rec, &post)?;
    let conclusion = with_onset(conclusion, onset.as_ref());
    let conclusion = with_sensor(conclusion, sensor_report.as_ref());
    let unit = &lp.cfg.output_unit;
    let conclusion = with_alarms(conclusion, events.as_ref(), theta_track.as_ref(), unit);
    let (st, r_final, w) = (post.st, post.residual, window_fields(lp, rec));
    let report = CloseLoopReport {
        file: rec.file.clone(),
        gauge_names: rec.gauge_names.clone(),
        n_rows: rec.len(),
        n_calibration: lp.cal.len(),
        n_heldout: w.n_validation + w.n_test,
        n_validation: w.n_validation,
        n_test: w.n_test,
        dropped_missing: rec.dropped_missing,
        imputed: rec.imputed,
        split_day: w.split_day,
        test_start_day: w.test_start_day,
        selection_origin_days: w.selection_origin_days,
        error_window: w.error_window,
        noise_sd_estimate: before.noise_sd,
        effects: st.effects.iter().map(|e| e.report.clone()).collect(),
        heldout_rmse_total_before: rmse_over_gauges(&before.rmse),
        heldout_rmse_total_after: rmse_over_gauges(&rmse_after),
        heldout_rmse_before: before.rmse,
        heldout_rmse_after: rmse_after,
        theta_before: before.theta,
        theta_after,
        theta_after_basis: basis,
        checks_before: before.checks,
        checks_after,
        steps,
        conclusion,
        model_adequacy_before: before.adequacy,
        model_adequacy_after: st.model.adequacy().cloned(),
        alarms: alarm_summaries(events.as_ref(), theta_track.as_ref(), unit),
        events,
        theta_track,
        parameter_correction: post.parameter.clone(),
        wall_time_s: 0.0,
        sensor: sensor_report,
        theta_after_effect_sd: effect_sd,
        onset,
        after_step: None,
        before_change: None,
    };
    Ok(CloseLoopOutcome {
        report,
        model: Arc::clone(&st.model),
        residual_before: before.residual,
        residual_after: r_final,
        heldout_rows: lp.error_rows().to_vec(),
        features: feature_columns(lp),
        effect_plot_covariates: st
            .effects
            .iter()
            .map(|e| e.plot_covariate.clone())
            .collect(),
    })
}

/// One alarm as the operator reads it: what changed, when, by how much.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AlarmSummary {
    /// What changed: a gauge's name, or `parameter` (the calibrated parameter θ; the gap of
    /// the gate application).
    pub subject: String,
    /// `level change` (a gauge's residual), `increase` or `decrease` (the parameter).
    pub change: String,
    /// Estimated onset (days since the first row).
    pub onset_day: f64,
    /// 95 % interval of the onset (days).
    pub onset_day_interval: (f64, f64),
    /// Size of the change and its sd, in `unit`.
    pub size: f64,
    /// Sd of `size`.
    pub size_sd: f64,
    /// Unit of `size`: the gauges' output unit, or `parameter` (θ's own unit).
    pub unit: String,
    /// Day the parameter's CUSUM crossed its threshold; `None` for a gauge (the scan runs on the
    /// whole record once).
    pub raised_day: Option<f64>,
}

/// The gauges' and the gap's alarms in one list, by onset.
fn alarm_summaries(
    events: Option<&EventScan>,
    track: Option<&ThetaTrack>,
    unit: &str,
) -> Vec<AlarmSummary> {
    let gauges = events
        .into_iter()
        .flat_map(|e| &e.alarms)
        .map(|a| AlarmSummary {
            subject: a.gauge.clone(),
            change: "level change".into(),
            onset_day: a.onset_day,
            onset_day_interval: a.onset_day_interval,
            size: a.size,
            size_sd: a.size_sd,
            unit: unit.into(),
            raised_day: None,
        });
    let gap = track.and_then(|t| t.alarm.as_ref()).map(|a| AlarmSummary {
        subject: "parameter".into(),
        change: a.direction.clone(),
        onset_day: a.onset_day,
        onset_day_interval: a.onset_day_interval,
        size: a.size,
        size_sd: a.size_sd,
        unit: "parameter".into(),
        raised_day: Some(a.day),
    });
    let mut all: Vec<AlarmSummary> = gauges.chain(gap).collect();
    all.sort_by(|a, b| a.onset_day.total_cmp(&b.onset_day));
    all
}
