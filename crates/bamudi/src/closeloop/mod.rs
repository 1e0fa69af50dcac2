//! Closing the loop with measured data: find what the calibrated model misses.
//!
//! A calibrated model is trusted once its residuals on measured data are explained. Given a
//! measured record (see [`read_csv`]) and a [`Calibrator`] (the BA-MUDI pipeline, or
//! [`reference::GridCalibrator`] for tests), [`close_loop`]:
//!
//! 1. splits the record in time into a calibration window (first
//!    [`CloseLoopConfig::calibration_fraction`]) and a held-out window;
//! 2. calibrates on the calibration window and computes residuals and standardised residuals
//!    (residual / predictive sd) on both windows, with adequacy checks: bias per gauge, variance
//!    against the predictive variance, lag-1 autocorrelation and Ljung-Box, and correlation with
//!    every covariate (time, levels, head, their rates of change, and every other CSV column);
//! 3. ranks candidate explanations by the HELD-OUT mean square error they remove: the library
//!    of physically named effects ([`EffectSpec`]: gauge offset, gauge drift, offset jump,
//!    thermal strain with a fitted lag for every temperature column, filling/emptying load-path
//!    hysteresis, a time-varying gap) and a generic sparse linear term in the covariates, each
//!    fitted on the calibration window only; where the calibrated model would re-absorb
//!    load-shaped terms ([`CalibratedModel::absorbs_load_functions`], BA-MUDI's discrepancy),
//!    jointly with a smooth function of the load, so that what the first calibration absorbed
//!    of an effect does not hide it;
//! 4. adds each of the most promising candidates ([`CloseLoopConfig::confirm_candidates`]) to
//!    the model, re-calibrates and back-fits, and accepts the best only if it then lowers the
//!    held-out mean square error by more than
//!    [`CloseLoopConfig::min_relative_improvement`] (the generic term must beat the best library
//!    effect by that margin too); repeats until the residuals pass the checks or nothing
//!    improves;
//! 5. reports every step ([`report::write_report`]: `report.md`, `results.json`, SVG plots).
//!
//! The loop is never told which effect is present; with no effect it reports
//! "no missing effect found".
//!
//! Units: levels in inches, strains in microstrain, time in hours (days where named).
//!
//! ```
//! use bamudi::closeloop::{close_loop, reference::{GridCalibrator, ToyGate}, CloseLoopConfig, MeasuredRecord};
//! use mitergate::field::{simulate, FieldConfig};
//! let gate = ToyGate::default();
//! let truth = |hu: f64, hd: f64, gap: f64| gate.strain(hu, hd, gap);
//! let rec = simulate(&FieldConfig::default().duration(12.0, 60.0).seed(1), &truth).unwrap();
//! let data = bamudi::closeloop::parse_csv(&rec.to_csv_string(), "sim.csv",
//!     &bamudi::closeloop::IngestConfig::new(rec.gauge_names.clone())).unwrap();
//! let out = close_loop(&data, &GridCalibrator::new(gate, (40.0, 200.0)), &CloseLoopConfig::default()).unwrap();
//! assert!(out.report.effects.is_empty()); // pure noise: nothing to explain
//! ```

pub mod bamudi_calibrator;
mod data;
mod effects;
mod nuisance;
pub mod reference;
pub mod report;
mod stats;

pub use bamudi_calibrator::{BamudiCalibrator, BamudiModel};
pub use data::{IngestConfig, MeasuredRecord, MissingPolicy, parse_csv, read_csv};
pub use effects::{EffectParameter, EffectReport, EffectSpec};
pub use stats::{Adequacy, CovariateCorrelation, GaugeCheck};

use crate::BamudiError;
use effects::{FitContext, Fitted};
use nalgebra::DMatrix;
use nuisance::LoadNuisance;
use serde::{Deserialize, Serialize};
use stats::{
    CheckThresholds, adequacy, mse_rows, noise_sd_from_differences, rmse_per_column, select_rows,
};
use std::sync::Arc;

/// Posterior summary of the gap θ (in).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ThetaSummary {
    /// Posterior mean (in).
    pub mean: f64,
    /// Posterior standard deviation (in).
    pub sd: f64,
    /// 95 % credible interval (in).
    pub ci95: (f64, f64),
}

/// A model calibrated on measured data (BA-MUDI Modules 1-4 or a stand-in).
pub trait CalibratedModel: Send + Sync {
    /// Predictive mean and variance (microstrain, microstrain²) at rows `x = [h_up, h_down]`,
    /// θ marginalised over its posterior; each `n x N_o`.
    fn predict(&self, x: &DMatrix<f64>) -> Result<(DMatrix<f64>, DMatrix<f64>), BamudiError>;
    /// Mean strain conditional on a gap `theta[i]` (in) for row `i` (Eq. 50 at fixed θ).
    fn predict_at_theta(
        &self,
        x: &DMatrix<f64>,
        theta: &[f64],
    ) -> Result<DMatrix<f64>, BamudiError>;
    /// Posterior summary of θ.
    fn theta_summary(&self) -> ThetaSummary;
    /// Support of the prior of θ (in).
    fn theta_bounds(&self) -> (f64, f64);
    /// Whether a re-calibration can absorb any smooth function of the load inputs at rows
    /// with the gate closed (BA-MUDI's discrepancy `δ(x)` can). The loop then fits each
    /// candidate effect together with such a function, so that the part of an effect that the
    /// current calibration has absorbed does not hide it. Default: `false`.
    ///
    /// ```
    /// use bamudi::closeloop::{CalibratedModel, Calibrator, reference::{GridCalibrator, ToyGate}};
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
}

/// Calibrates a model on rows `x = [h_up, h_down]` (in) and gauge strains `y` (microstrain)
/// from which the loop has already subtracted the current effect terms.
pub trait Calibrator: Sync {
    /// Runs the calibration.
    fn calibrate(
        &self,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
    ) -> Result<Box<dyn CalibratedModel>, BamudiError>;
}

/// Settings of the loop. Defaults in brackets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CloseLoopConfig {
    /// Fraction of the record (in time order) used for calibration [0.6].
    pub calibration_fraction: f64,
    /// Maximum number of effects added [4].
    pub max_steps: usize,
    /// Minimum relative reduction of the held-out mean square error to accept an effect [0.05].
    pub min_relative_improvement: f64,
    /// Temperature columns for the thermal effect; `None` = every column whose name contains
    /// `temp` [None].
    pub temperature_columns: Option<Vec<String>>,
    /// Segments of the calibration window for the time-varying gap [6].
    pub gap_segments: usize,
    /// Maximum number of covariates in the generic term [3].
    pub max_generic_features: usize,
    /// Lags of the Ljung-Box test [10].
    pub ljung_box_lags: usize,
    /// Family-wise significance level of the adequacy checks per window [0.01].
    pub significance: f64,
    /// Candidates re-calibrated at each step to decide between them [3]; at least 2 are
    /// (the best library effect and the best generic term) when both pass the screening.
    pub confirm_candidates: usize,
}

impl Default for CloseLoopConfig {
    fn default() -> Self {
        Self {
            calibration_fraction: 0.6,
            max_steps: 4,
            min_relative_improvement: 0.05,
            temperature_columns: None,
            gap_segments: 6,
            max_generic_features: 3,
            ljung_box_lags: 10,
            significance: 0.01,
            confirm_candidates: 3,
        }
    }
}

impl CloseLoopConfig {
    /// Sets the calibration fraction.
    ///
    /// ```
    /// let c = bamudi::closeloop::CloseLoopConfig::default().calibration_fraction(0.5);
    /// assert_eq!(c.calibration_fraction, 0.5);
    /// ```
    pub fn calibration_fraction(mut self, f: f64) -> Self {
        self.calibration_fraction = f;
        self
    }
    /// Sets the maximum number of effects.
    ///
    /// ```
    /// let c = bamudi::closeloop::CloseLoopConfig::default().max_steps(2);
    /// assert_eq!(c.max_steps, 2);
    /// ```
    pub fn max_steps(mut self, n: usize) -> Self {
        self.max_steps = n;
        self
    }
    /// Sets the minimum relative held-out improvement.
    ///
    /// ```
    /// let c = bamudi::closeloop::CloseLoopConfig::default().min_relative_improvement(0.1);
    /// assert_eq!(c.min_relative_improvement, 0.1);
    /// ```
    pub fn min_relative_improvement(mut self, f: f64) -> Self {
        self.min_relative_improvement = f;
        self
    }

    /// Sets how many screened candidates are re-calibrated per step.
    ///
    /// ```
    /// let c = bamudi::closeloop::CloseLoopConfig::default().confirm_candidates(4);
    /// assert_eq!(c.confirm_candidates, 4);
    /// ```
    pub fn confirm_candidates(mut self, k: usize) -> Self {
        self.confirm_candidates = k;
        self
    }

    fn validate(&self) -> Result<(), BamudiError> {
        let bad = |name, reason: String| Err(BamudiError::InvalidConfig { name, reason });
        if !(self.calibration_fraction > 0.0 && self.calibration_fraction < 1.0) {
            return bad(
                "calibration_fraction",
                format!("must be in (0, 1), got {}", self.calibration_fraction),
            );
        }
        if self.min_relative_improvement.is_nan() || self.min_relative_improvement < 0.0 {
            return bad(
                "min_relative_improvement",
                format!("must be >= 0, got {}", self.min_relative_improvement),
            );
        }
        if !(self.significance > 0.0 && self.significance < 1.0) {
            return bad(
                "significance",
                format!("must be in (0, 1), got {}", self.significance),
            );
        }
        if self.confirm_candidates == 0 {
            return bad("confirm_candidates", "must be >= 1".into());
        }
        if self.ljung_box_lags == 0 {
            return bad("ljung_box_lags", "must be >= 1".into());
        }
        Ok(())
    }
}

/// Candidate features derived from a record: `time_days`, `h_up`, `h_down`, `head`, the
/// CSV covariates, and the rate of change per hour `d_<name>_per_h` of all but time.
#[derive(Debug, Clone)]
pub(crate) struct Features {
    pub names: Vec<String>,
    pub cols: Vec<Vec<f64>>,
    pub time_h: Vec<f64>,
    pub head: Vec<f64>,
    pub head_rate: Vec<f64>,
}

fn backward_rate(t: &[f64], v: &[f64]) -> Vec<f64> {
    (0..v.len())
        .map(|i| {
            let (a, b) = if i == 0 {
                (0, 1.min(v.len() - 1))
            } else {
                (i - 1, i)
            };
            if a == b {
                0.0
            } else {
                (v[b] - v[a]) / (t[b] - t[a])
            }
        })
        .collect()
}

impl Features {
    fn new(rec: &MeasuredRecord) -> Self {
        let t = rec.time_h.clone();
        let hu: Vec<f64> = rec.x.column(0).iter().copied().collect();
        let hd: Vec<f64> = rec.x.column(1).iter().copied().collect();
        let head: Vec<f64> = hu.iter().zip(&hd).map(|(a, b)| a - b).collect();
        let mut names = vec![
            "time_days".to_string(),
            "h_up".into(),
            "h_down".into(),
            "head".into(),
        ];
        let mut cols = vec![t.iter().map(|h| h / 24.0).collect(), hu, hd, head.clone()];
        for (k, nm) in rec.covariate_names.iter().enumerate() {
            names.push(nm.clone());
            cols.push(rec.covariates.column(k).iter().copied().collect());
        }
        let n_base = names.len();
        for k in 1..n_base {
            names.push(format!("d_{}_per_h", names[k]));
            cols.push(backward_rate(&t, &cols[k]));
        }
        let head_rate = backward_rate(&t, &head);
        Self {
            names,
            cols,
            time_h: t,
            head,
            head_rate,
        }
    }
}

/// A calibrated model with its predictive mean and variance at every row.
type Calibrated = (Arc<dyn CalibratedModel>, DMatrix<f64>, DMatrix<f64>);

/// Score of one candidate at one step.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CandidateScore {
    /// Effect name.
    pub name: String,
    /// Covariates used.
    pub covariates: Vec<String>,
    /// Screening: held-out mean square residual with the candidate fitted on the calibration
    /// window (jointly with the load nuisance where the model absorbs one; microstrain²).
    pub heldout_mse: f64,
    /// Screening: reduction of the held-out mean square residual against the nuisance-only
    /// fit (or the residual itself), relative to the MSE before the step.
    pub relative_improvement: f64,
    /// Held-out mean square residual after adding the candidate, re-calibrating and
    /// back-fitting (microstrain²); `None` when it was not among the confirmed candidates.
    #[serde(default)]
    pub recalibrated_heldout_mse: Option<f64>,
    /// Relative reduction of the held-out MSE after re-calibration (what the decision uses).
    #[serde(default)]
    pub recalibrated_relative_improvement: Option<f64>,
}

/// One iteration of the loop.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StepReport {
    /// Step number (1-based).
    pub step: usize,
    /// Held-out mean square residual before this step (microstrain²).
    pub heldout_mse_before: f64,
    /// Candidates, best first.
    pub candidates: Vec<CandidateScore>,
    /// Accepted effect, if any.
    pub accepted: Option<String>,
    /// Why the step ended as it did.
    pub decision: String,
    /// Held-out RMSE per gauge after the step (microstrain).
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
    /// Rows used, rows in the calibration and held-out windows.
    pub n_rows: usize,
    /// Rows in the calibration window.
    pub n_calibration: usize,
    /// Rows in the held-out window.
    pub n_heldout: usize,
    /// Rows dropped for missing gauge values.
    pub dropped_missing: usize,
    /// Gauge cells imputed.
    pub imputed: usize,
    /// Day at which the held-out window starts (days since the first row).
    pub split_day: f64,
    /// White-noise sd estimated from first differences of the initial residuals (microstrain).
    pub noise_sd_estimate: f64,
    /// Accepted effects in order, with final parameters.
    pub effects: Vec<EffectReport>,
    /// Held-out RMSE per gauge before the loop (microstrain).
    pub heldout_rmse_before: Vec<f64>,
    /// Held-out RMSE per gauge after the loop (microstrain).
    pub heldout_rmse_after: Vec<f64>,
    /// Held-out RMSE over all gauges before (microstrain).
    pub heldout_rmse_total_before: f64,
    /// Held-out RMSE over all gauges after (microstrain).
    pub heldout_rmse_total_after: f64,
    /// θ (in) of the first calibration.
    pub theta_before: ThetaSummary,
    /// θ (in) after the loop; at the end of the record when a time-varying gap was accepted.
    pub theta_after: ThetaSummary,
    /// What `theta_after` refers to.
    pub theta_after_basis: String,
    /// Adequacy of the initial residuals (calibration, held-out).
    pub checks_before: Vec<Adequacy>,
    /// Adequacy of the final residuals (calibration, held-out).
    pub checks_after: Vec<Adequacy>,
    /// Every step.
    pub steps: Vec<StepReport>,
    /// One-sentence conclusion.
    pub conclusion: String,
}

/// Result of [`close_loop`]: the report plus the residual series used for the plots.
#[derive(Debug, Clone)]
pub struct CloseLoopOutcome {
    /// The serialisable report.
    pub report: CloseLoopReport,
    /// Residuals before the loop (`n x N_o`, microstrain).
    pub residual_before: DMatrix<f64>,
    /// Residuals after the loop.
    pub residual_after: DMatrix<f64>,
    /// Held-out row indices.
    pub heldout_rows: Vec<usize>,
    /// Feature names and values, for plotting residuals against covariates.
    pub features: Vec<(String, Vec<f64>)>,
    /// The covariate that best shows each accepted effect.
    pub effect_plot_covariates: Vec<String>,
}

/// The calibrated model, its predictive moments at every row and the accepted effects.
#[derive(Clone)]
struct State {
    model: Arc<dyn CalibratedModel>,
    mean: DMatrix<f64>,
    var: DMatrix<f64>,
    effects: Vec<Fitted>,
}

impl State {
    fn has_gap_trend(&self) -> bool {
        self.effects.iter().any(|e| e.spec == EffectSpec::GapTrend)
    }
}

/// A candidate after screening, with its fit (kept for confirmation).
struct Screened {
    score: CandidateScore,
    fitted: Fitted,
    /// Held-out MSE gain over the reference (residual, or residual minus nuisance-only fit).
    gain: f64,
}

/// Everything fixed during one run of the loop.
struct Loop<'a> {
    calibrator: &'a dyn Calibrator,
    x: &'a DMatrix<f64>,
    y: &'a DMatrix<f64>,
    feats: &'a Features,
    cal: &'a [usize],
    ho: &'a [usize],
    gauges: &'a [String],
    cfg: &'a CloseLoopConfig,
    nuisance: Option<LoadNuisance>,
}

/// Runs the loop on a measured record. See the module docs.
///
/// ```
/// // see the module-level example
/// let c = bamudi::closeloop::CloseLoopConfig::default();
/// assert_eq!(c.max_steps, 4);
/// ```
pub fn close_loop(
    rec: &MeasuredRecord,
    calibrator: &dyn Calibrator,
    cfg: &CloseLoopConfig,
) -> Result<CloseLoopOutcome, BamudiError> {
    cfg.validate()?;
    let n = rec.len();
    let n_cal = (cfg.calibration_fraction * n as f64).round() as usize;
    if n_cal < 30 || n - n_cal < 30 {
        return Err(BamudiError::TooFewRows {
            what: "calibration and held-out windows (30 each)".into(),
            got: n,
        });
    }
    let cal: Vec<usize> = (0..n_cal).collect();
    let ho: Vec<usize> = (n_cal..n).collect();
    let feats = Features::new(rec);
    let gauges = &rec.gauge_names;
    let th = CheckThresholds {
        ljung_box_lags: cfg.ljung_box_lags,
        significance: cfg.significance,
    };
    let library = effect_library(rec, cfg);
    let lp = Loop {
        calibrator,
        x: &rec.x,
        y: &rec.y,
        feats: &feats,
        cal: &cal,
        ho: &ho,
        gauges,
        cfg,
        nuisance: LoadNuisance::new(&rec.x, &cal),
    };

    let (model, mean, var) = lp.calibrate(lp.y)?;
    let theta_before = model.theta_summary();
    let r0 = lp.y - &mean;
    let checks_before = vec![
        adequacy("calibration", &r0, &var, &cal, gauges, &feats, &th),
        adequacy("heldout", &r0, &var, &ho, gauges, &feats, &th),
    ];
    let mut noise: Vec<f64> = (0..r0.ncols())
        .map(|j| noise_sd_from_differences(&cal.iter().map(|&i| r0[(i, j)]).collect::<Vec<_>>()))
        .collect();
    noise.sort_by(|a, b| a.total_cmp(b));
    let noise_sd = noise[noise.len() / 2];
    let rmse_before = rmse_per_column(&r0, &ho);
    let mut st = State {
        model,
        mean,
        var,
        effects: vec![],
    };
    let mut steps = vec![];
    let mut conclusion = String::new();
    for step in 1..=cfg.max_steps {
        let r = lp.residual(&st)?;
        let checks = [
            adequacy("calibration", &r, &st.var, &cal, gauges, &feats, &th),
            adequacy("heldout", &r, &st.var, &ho, gauges, &feats, &th),
        ];
        if checks.iter().all(Adequacy::passed) {
            conclusion = if st.effects.is_empty() {
                "no missing effect found: residuals pass every adequacy check".into()
            } else {
                "residuals pass every adequacy check after the accepted effects".into()
            };
            break;
        }
        let mse_before = mse_rows(&r, &ho);
        let (candidates, outcome) = lp.search(&st, &library, &r, mse_before)?;
        let Some((next, name, decision)) = outcome.accepted else {
            conclusion = if st.effects.is_empty() {
                format!(
                    "no missing effect found: {}; remaining check failures: {}",
                    outcome.decision,
                    checks.iter().map(|c| c.failures.len()).sum::<usize>()
                )
            } else {
                format!(
                    "stopped after {} effect(s): {}",
                    st.effects.len(),
                    outcome.decision
                )
            };
            steps.push(StepReport {
                step,
                heldout_mse_before: mse_before,
                candidates,
                accepted: None,
                decision: outcome.decision,
                heldout_rmse_after: rmse_per_column(&r, &ho),
                theta_after: theta_now(&st).0,
            });
            break;
        };
        st = next;
        let r_new = lp.residual(&st)?;
        steps.push(StepReport {
            step,
            heldout_mse_before: mse_before,
            candidates,
            accepted: Some(name),
            decision,
            heldout_rmse_after: rmse_per_column(&r_new, &ho),
            theta_after: theta_now(&st).0,
        });
        if step == cfg.max_steps {
            conclusion = format!("stopped at the maximum of {} effects", cfg.max_steps);
        }
    }
    let r_final = lp.residual(&st)?;
    let checks_after = vec![
        adequacy("calibration", &r_final, &st.var, &cal, gauges, &feats, &th),
        adequacy("heldout", &r_final, &st.var, &ho, gauges, &feats, &th),
    ];
    let (theta_after, basis) = theta_now(&st);
    let rmse_after = rmse_per_column(&r_final, &ho);
    let total = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let report = CloseLoopReport {
        file: rec.file.clone(),
        gauge_names: gauges.clone(),
        n_rows: n,
        n_calibration: cal.len(),
        n_heldout: ho.len(),
        dropped_missing: rec.dropped_missing,
        imputed: rec.imputed,
        split_day: rec.time_h[n_cal] / 24.0,
        noise_sd_estimate: noise_sd,
        effects: st.effects.iter().map(|e| e.report.clone()).collect(),
        heldout_rmse_total_before: total(&rmse_before),
        heldout_rmse_total_after: total(&rmse_after),
        heldout_rmse_before: rmse_before,
        heldout_rmse_after: rmse_after,
        theta_before,
        theta_after,
        theta_after_basis: basis,
        checks_before,
        checks_after,
        steps,
        conclusion,
    };
    Ok(CloseLoopOutcome {
        report,
        residual_before: r0,
        residual_after: r_final,
        heldout_rows: ho,
        features: feats
            .names
            .iter()
            .cloned()
            .zip(feats.cols.iter().cloned())
            .collect(),
        effect_plot_covariates: st
            .effects
            .iter()
            .map(|e| e.plot_covariate.clone())
            .collect(),
    })
}

/// The physically named effects searched at every step (the generic term comes on top).
fn effect_library(rec: &MeasuredRecord, cfg: &CloseLoopConfig) -> Vec<EffectSpec> {
    let temp_cols: Vec<String> = match &cfg.temperature_columns {
        Some(c) => c.clone(),
        None => rec
            .covariate_names
            .iter()
            .filter(|c| c.to_lowercase().contains("temp"))
            .cloned()
            .collect(),
    };
    let mut library = vec![
        EffectSpec::GaugeOffset,
        EffectSpec::GaugeDrift,
        EffectSpec::OffsetJump,
    ];
    library.extend(
        temp_cols
            .iter()
            .map(|c| EffectSpec::Thermal { column: c.clone() }),
    );
    library.extend([EffectSpec::LoadPath, EffectSpec::GapTrend]);
    library
}

/// What one step's search decided: the new state with the accepted effect, or nothing.
struct SearchOutcome {
    accepted: Option<(State, String, String)>,
    decision: String,
}

impl Loop<'_> {
    fn calibrate(&self, y_adj: &DMatrix<f64>) -> Result<Calibrated, BamudiError> {
        let model = self.calibrator.calibrate(
            &select_rows(self.x, self.cal),
            &select_rows(y_adj, self.cal),
        )?;
        let (mean, var) = model.predict(self.x)?;
        Ok((Arc::from(model), mean, var))
    }

    fn context<'s>(&'s self, st: &'s State) -> FitContext<'s> {
        FitContext {
            feats: self.feats,
            x: self.x,
            cal: self.cal,
            model: st.model.as_ref(),
            base_mean: &st.mean,
            gauges: self.gauges,
            gap_segments: self.cfg.gap_segments,
            max_generic_features: self.cfg.max_generic_features,
        }
    }

    /// The load nuisance, where a re-calibration of `st`'s model would absorb load
    /// functions: its model says so, and no gap trend keeps the model fixed.
    fn nuisance_for(&self, st: &State, adds_gap_trend: bool) -> Option<&LoadNuisance> {
        let recalibrates = !(st.has_gap_trend() || adds_gap_trend);
        self.nuisance
            .as_ref()
            .filter(|_| recalibrates && st.model.absorbs_load_functions())
    }

    /// Data minus model mean minus every accepted effect.
    fn residual(&self, st: &State) -> Result<DMatrix<f64>, BamudiError> {
        Ok(self.y - &st.mean - self.effect_sum(st)?)
    }

    /// One step: screen every candidate, confirm the most promising by re-calibrating with
    /// each, and accept the best confirmed one if it clears the margin.
    fn search(
        &self,
        st: &State,
        library: &[EffectSpec],
        r: &DMatrix<f64>,
        mse_before: f64,
    ) -> Result<(Vec<CandidateScore>, SearchOutcome), BamudiError> {
        let margin = self.cfg.min_relative_improvement * mse_before;
        let mut screened = self.screen(st, library, r, mse_before)?;
        // screening only approximates a re-calibration (the seed-5 jump screened at 1.84 and
        // re-calibrated at 1.07 microstrain²), so a candidate is confirmed unless screening
        // credits it with less than half the margin
        let picks = confirmation_picks(&screened, 0.5 * margin, self.cfg.confirm_candidates);
        let mut trials: Vec<(usize, (State, bool), f64)> = vec![];
        for &k in &picks {
            let trial = self.with_effect(st, screened[k].fitted.clone())?;
            let mse = mse_rows(&self.residual(&trial.0)?, self.ho);
            screened[k].score.recalibrated_heldout_mse = Some(mse);
            screened[k].score.recalibrated_relative_improvement = Some(1.0 - mse / mse_before);
            trials.push((k, trial, mse));
        }
        let is_generic = |k: usize| screened[k].fitted.spec == EffectSpec::Generic;
        let best = |generic: bool| {
            trials
                .iter()
                .filter(|t| is_generic(t.0) == generic)
                .min_by(|a, b| a.2.total_cmp(&b.2))
        };
        // a library effect is preferred unless the generic term beats it by the margin
        let choice = match (best(false), best(true)) {
            (Some(l), Some(g)) if g.2 < l.2 - margin => Some(g),
            (Some(l), _) => Some(l),
            (None, g) => g,
        };
        let pct = |v: f64| 100.0 * v;
        let min_pct = pct(self.cfg.min_relative_improvement);
        let choice = choice.map(|c| (c.0, c.2));
        let outcome = match choice {
            Some((k, mse)) if mse_before - mse > margin => {
                let name = screened[k].score.name.clone();
                let at = trials.iter().position(|t| t.0 == k).unwrap_or(0);
                let (_, (mut trial, settled), _) = trials.swap_remove(at);
                if !settled {
                    self.recalibrate_and_backfit(&mut trial, MAX_BACKFIT_ROUNDS - CONFIRM_ROUNDS)?;
                }
                let decision = format!(
                    "accepted {name}: held-out MSE {mse_before:.3} -> {mse:.3} microstrain^2 after re-calibration ({:.1} % better, threshold {min_pct:.1} %)",
                    pct(1.0 - mse / mse_before)
                );
                SearchOutcome {
                    accepted: Some((trial, name, decision.clone())),
                    decision,
                }
            }
            Some((k, mse)) => SearchOutcome {
                accepted: None,
                decision: format!(
                    "no candidate lowers the held-out MSE by {min_pct:.1} % after re-calibration (best: {}, {:.1} %)",
                    screened[k].score.name,
                    pct(1.0 - mse / mse_before)
                ),
            },
            None => SearchOutcome {
                accepted: None,
                decision: match screened.first() {
                    Some(s) => format!(
                        "no candidate lowers the held-out MSE by {min_pct:.1} % (best screened: {}, {:.1} %)",
                        s.score.name,
                        pct(s.gain / mse_before)
                    ),
                    None => "no candidate applies".into(),
                },
            },
        };
        // confirmed candidates first, by their re-calibrated error; then the screened order
        screened.sort_by(|a, b| {
            let key = |s: &Screened| {
                (
                    s.score.recalibrated_heldout_mse.is_none(),
                    s.score.recalibrated_heldout_mse.unwrap_or(-s.gain),
                )
            };
            let (ka, kb) = (key(a), key(b));
            ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1))
        });
        Ok((screened.into_iter().map(|s| s.score).collect(), outcome))
    }

    /// Every candidate fitted on the calibration window (jointly with the load nuisance where
    /// a re-calibration would absorb one) and scored on the held-out window; best gain first.
    fn screen(
        &self,
        st: &State,
        library: &[EffectSpec],
        r: &DMatrix<f64>,
        mse_before: f64,
    ) -> Result<Vec<Screened>, BamudiError> {
        let ctx = self.context(st);
        let accepted: Vec<String> = st.effects.iter().map(|e| e.spec.name()).collect();
        // what the nuisance alone would leave, so that a candidate is credited only with what
        // the re-calibration could not have done by itself (the same for every candidate)
        let nuisance_only = self
            .nuisance_for(st, false)
            .map(|n| mse_rows(&(r - n.fit(r, self.cal)), self.ho));
        let mut out = vec![];
        for spec in library.iter().chain(std::iter::once(&EffectSpec::Generic)) {
            if accepted.contains(&spec.name()) && *spec != EffectSpec::Generic {
                continue;
            }
            let nu = self.nuisance_for(st, *spec == EffectSpec::GapTrend);
            let Some(j) = nuisance::fit_jointly(spec, &ctx, r, nu)? else {
                continue;
            };
            let reference = match (nu, nuisance_only) {
                (Some(_), Some(mse)) => mse,
                _ => mse_before,
            };
            let mse = mse_rows(&(r - &j.effect - &j.nuisance), self.ho);
            out.push(Screened {
                score: CandidateScore {
                    name: j.fitted.report.name.clone(),
                    covariates: j.fitted.report.covariates.clone(),
                    heldout_mse: mse,
                    relative_improvement: (reference - mse) / mse_before,
                    recalibrated_heldout_mse: None,
                    recalibrated_relative_improvement: None,
                },
                gain: reference - mse,
                fitted: j.fitted,
            });
        }
        out.sort_by(|a, b| b.gain.total_cmp(&a.gain));
        Ok(out)
    }

    /// `st` with one more effect, re-calibrated and back-fitted for at most
    /// [`CONFIRM_ROUNDS`] calibrations; `true` when the back-fit settled.
    fn with_effect(&self, st: &State, fitted: Fitted) -> Result<(State, bool), BamudiError> {
        let mut trial = st.clone();
        trial.effects.push(fitted);
        let settled = self.recalibrate_and_backfit(&mut trial, CONFIRM_ROUNDS)?;
        Ok((trial, settled))
    }

    /// Re-calibrates on the data minus the additive effects (the gap trend is model-relative
    /// and is re-fitted instead), then re-fits every effect with the others held fixed, until
    /// the re-fitted effects agree with those the calibration was given.
    /// Returns whether it settled within `max_rounds` calibrations.
    fn recalibrate_and_backfit(
        &self,
        st: &mut State,
        max_rounds: usize,
    ) -> Result<bool, BamudiError> {
        let has_gap = st.has_gap_trend();
        for _round in 0..max_rounds {
            let given = self.effect_sum(st)?;
            if !has_gap {
                let (m, mean, var) = self.calibrate(&(self.y - &given))?;
                st.model = m;
                st.mean = mean;
                st.var = var;
            }
            let nu = self.nuisance_for(st, false);
            // each term evaluated once per round (a gap trend costs a contact solve per row)
            // and replaced when its effect is re-fitted
            let mut terms = self.contributions(st)?;
            for k in 0..st.effects.len() {
                let ctx = self.context(st);
                let mut r = self.y - &st.mean;
                for (j, c) in terms.iter().enumerate() {
                    if j != k {
                        r -= c;
                    }
                }
                let spec = st.effects[k].spec.clone();
                if let Some(j) = nuisance::fit_jointly(&spec, &ctx, &r, nu)? {
                    terms[k] = j.effect;
                    st.effects[k] = j.fitted;
                }
            }
            let sum = sum_terms(&terms, self.y.shape());
            let moved = mse_rows(&(&sum - &given), self.cal).sqrt();
            let resid = mse_rows(&(self.y - &st.mean - &sum), self.cal).sqrt();
            if has_gap || moved <= BACKFIT_TOL * resid {
                return Ok(true);
            }
        }
        Ok(false)
    }

    /// Each accepted effect's contribution at every row (microstrain).
    fn contributions(&self, st: &State) -> Result<Vec<DMatrix<f64>>, BamudiError> {
        let ctx = self.context(st);
        st.effects
            .iter()
            .map(|e| effects::contribution(e, &ctx))
            .collect()
    }

    /// The sum of the accepted effects' contributions at every row (microstrain).
    fn effect_sum(&self, st: &State) -> Result<DMatrix<f64>, BamudiError> {
        Ok(sum_terms(&self.contributions(st)?, self.y.shape()))
    }
}

/// `terms` added in order to a zero matrix of `shape`.
fn sum_terms(terms: &[DMatrix<f64>], shape: (usize, usize)) -> DMatrix<f64> {
    let mut sum = DMatrix::zeros(shape.0, shape.1);
    for t in terms {
        sum += t;
    }
    sum
}

/// Most calibrations in one back-fit.
const MAX_BACKFIT_ROUNDS: usize = 10;
/// Calibrations a candidate gets before it is scored. The right effect, fitted jointly with
/// the load nuisance, settles in 2 (measured on the FE gate: the first re-calibration moves it
/// by a quarter of the noise, the second by 0.2 %); a wrong one keeps trading signal with the
/// discrepancy for 5-7 rounds while its error barely changes (2.14 -> 1.95 microstrain for a
/// generic term on an offset-jump record), so the ranking is settled after 3. The accepted
/// candidate then finishes its back-fit.
const CONFIRM_ROUNDS: usize = 3;
/// The back-fit stops when the re-fitted effects differ from those the calibration was given by
/// less than this fraction of the residual RMS (calibration window): the calibration then saw
/// data consistent with its effects to 2 % of the noise, which changes the residual's mean
/// square by about 0.04 %, far below the 5 % margin the loop decides on.
const BACKFIT_TOL: f64 = 0.02;

/// Which screened candidates (indices into `screened`, best gain first) are re-calibrated:
/// those gaining more than `min_gain`, at most `k` of them, always including the best library
/// effect and the best generic term among them so that the preference rule can be applied.
fn confirmation_picks(screened: &[Screened], min_gain: f64, k: usize) -> Vec<usize> {
    let eligible: Vec<usize> = (0..screened.len())
        .filter(|&i| screened[i].gain > min_gain)
        .collect();
    let generic = |i: &usize| screened[*i].fitted.spec == EffectSpec::Generic;
    let mut picks: Vec<usize> = vec![];
    picks.extend(eligible.iter().find(|i| !generic(i)));
    picks.extend(eligible.iter().find(|i| generic(i)));
    for i in eligible {
        if picks.len() >= k {
            break;
        }
        if !picks.contains(&i) {
            picks.push(i);
        }
    }
    picks
}

/// θ now: the gap at the end of the record when a gap trend is accepted, else the model's.
fn theta_now(st: &State) -> (ThetaSummary, String) {
    match st.effects.iter().find_map(|e| e.gap_end) {
        Some((end, sd, half)) => (
            ThetaSummary { mean: end, sd, ci95: (end - half, end + half) },
            "gap at the end of the record from the fitted gap trend (95 % interval from the segment regression)".into(),
        ),
        None => (st.model.theta_summary(), "posterior of the last calibration".into()),
    }
}
