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
//!    fitted on the calibration window only;
//! 4. accepts the best candidate only if it lowers the held-out mean square error by more than
//!    [`CloseLoopConfig::min_relative_improvement`] (the generic term must beat the best library
//!    effect by that margin too), subtracts it, re-calibrates, re-fits the accepted effects
//!    (back-fitting) and repeats until the residuals pass the checks or nothing improves;
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
use serde::{Deserialize, Serialize};
use stats::{
    CheckThresholds, adequacy, mse_rows, noise_sd_from_differences, rmse_per_column, select_rows,
};

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

/// Score of one candidate at one step.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CandidateScore {
    /// Effect name.
    pub name: String,
    /// Covariates used.
    pub covariates: Vec<String>,
    /// Held-out mean square residual with the candidate (microstrain²).
    pub heldout_mse: f64,
    /// Relative reduction of the held-out mean square residual.
    pub relative_improvement: f64,
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

struct State {
    model: Box<dyn CalibratedModel>,
    mean: DMatrix<f64>,
    var: DMatrix<f64>,
    effects: Vec<Fitted>,
}

/// A calibrated model with its predictive mean and variance at every row.
type Calibrated = (Box<dyn CalibratedModel>, DMatrix<f64>, DMatrix<f64>);

fn calibrate(
    calibrator: &dyn Calibrator,
    x: &DMatrix<f64>,
    y_adj: &DMatrix<f64>,
    cal: &[usize],
) -> Result<Calibrated, BamudiError> {
    let model = calibrator.calibrate(&select_rows(x, cal), &select_rows(y_adj, cal))?;
    let (mean, var) = model.predict(x)?;
    Ok((model, mean, var))
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
    let x = &rec.x;
    let y = &rec.y;
    let gauges = &rec.gauge_names;
    let th = CheckThresholds {
        ljung_box_lags: cfg.ljung_box_lags,
        significance: cfg.significance,
    };
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

    let (model, mean, var) = calibrate(calibrator, x, y, &cal)?;
    let theta_before = model.theta_summary();
    let r0 = y - &mean;
    let checks_before = vec![
        adequacy("calibration", &r0, &var, &cal, gauges, &feats, &th),
        adequacy("heldout", &r0, &var, &ho, gauges, &feats, &th),
    ];
    let mut noise: Vec<f64> = (0..y.ncols())
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
        let r = residual(&st, y, &feats, x, &cal, gauges, cfg)?;
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
        let ctx = context(&st, &feats, x, &cal, gauges, cfg);
        let mut scored: Vec<(CandidateScore, Fitted)> = vec![];
        let accepted_names: Vec<String> = st.effects.iter().map(|e| e.spec.name()).collect();
        for spec in library.iter().chain(std::iter::once(&EffectSpec::Generic)) {
            if accepted_names.contains(&spec.name()) && *spec != EffectSpec::Generic {
                continue;
            }
            let Some(f) = effects::fit(spec, &ctx, &r)? else {
                continue;
            };
            let c = effects::contribution(&f, &ctx)?;
            let mse = mse_rows(&(&r - &c), &ho);
            scored.push((
                CandidateScore {
                    name: f.report.name.clone(),
                    covariates: f.report.covariates.clone(),
                    heldout_mse: mse,
                    relative_improvement: 1.0 - mse / mse_before,
                },
                f,
            ));
        }
        scored.sort_by(|a, b| a.0.heldout_mse.total_cmp(&b.0.heldout_mse));
        let candidates: Vec<CandidateScore> = scored.iter().map(|s| s.0.clone()).collect();
        let best_lib = scored.iter().find(|s| s.1.spec != EffectSpec::Generic);
        let best_gen = scored.iter().find(|s| s.1.spec == EffectSpec::Generic);
        let margin = cfg.min_relative_improvement * mse_before;
        // a library effect is preferred unless the generic term beats it by the margin
        let choice = match (best_lib, best_gen) {
            (Some(l), Some(g)) if g.0.heldout_mse < l.0.heldout_mse - margin => Some(g),
            (Some(l), _) => Some(l),
            (None, g) => g,
        };
        let (accepted, decision) = match choice {
            Some(c) if mse_before - c.0.heldout_mse > margin => (
                Some(c.1.clone()),
                format!(
                    "accepted {}: held-out MSE {:.3} -> {:.3} microstrain^2 ({:.1} % better, threshold {:.1} %)",
                    c.0.name,
                    mse_before,
                    c.0.heldout_mse,
                    100.0 * c.0.relative_improvement,
                    100.0 * cfg.min_relative_improvement
                ),
            ),
            Some(c) => (
                None,
                format!(
                    "no candidate lowers the held-out MSE by {:.1} % (best: {}, {:.1} %)",
                    100.0 * cfg.min_relative_improvement,
                    c.0.name,
                    100.0 * c.0.relative_improvement
                ),
            ),
            None => (None, "no candidate applies".into()),
        };
        let Some(fitted) = accepted else {
            conclusion = if st.effects.is_empty() {
                format!(
                    "no missing effect found: {decision}; remaining check failures: {}",
                    checks.iter().map(|c| c.failures.len()).sum::<usize>()
                )
            } else {
                format!("stopped after {} effect(s): {decision}", st.effects.len())
            };
            steps.push(StepReport {
                step,
                heldout_mse_before: mse_before,
                candidates,
                accepted: None,
                decision,
                heldout_rmse_after: rmse_per_column(&r, &ho),
                theta_after: theta_now(&st).0,
            });
            break;
        };
        let name = fitted.report.name.clone();
        st.effects.push(fitted);
        recalibrate_and_backfit(&mut st, calibrator, y, &feats, x, &cal, gauges, cfg)?;
        let r_new = residual(&st, y, &feats, x, &cal, gauges, cfg)?;
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
    let r_final = residual(&st, y, &feats, x, &cal, gauges, cfg)?;
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

fn context<'a>(
    st: &'a State,
    feats: &'a Features,
    x: &'a DMatrix<f64>,
    cal: &'a [usize],
    gauges: &'a [String],
    cfg: &CloseLoopConfig,
) -> FitContext<'a> {
    FitContext {
        feats,
        x,
        cal,
        model: st.model.as_ref(),
        base_mean: &st.mean,
        gauges,
        gap_segments: cfg.gap_segments,
        max_generic_features: cfg.max_generic_features,
    }
}

/// Data minus model mean minus every accepted effect.
fn residual(
    st: &State,
    y: &DMatrix<f64>,
    feats: &Features,
    x: &DMatrix<f64>,
    cal: &[usize],
    gauges: &[String],
    cfg: &CloseLoopConfig,
) -> Result<DMatrix<f64>, BamudiError> {
    let ctx = context(st, feats, x, cal, gauges, cfg);
    let mut r = y - &st.mean;
    for e in &st.effects {
        r -= effects::contribution(e, &ctx)?;
    }
    Ok(r)
}

/// Re-calibrates on the data minus the additive effects (the gap trend is model-relative and
/// is re-fitted instead), then re-fits every effect with the others held fixed, twice.
#[allow(clippy::too_many_arguments)]
fn recalibrate_and_backfit(
    st: &mut State,
    calibrator: &dyn Calibrator,
    y: &DMatrix<f64>,
    feats: &Features,
    x: &DMatrix<f64>,
    cal: &[usize],
    gauges: &[String],
    cfg: &CloseLoopConfig,
) -> Result<(), BamudiError> {
    let has_gap = st.effects.iter().any(|e| e.spec == EffectSpec::GapTrend);
    let mut last_sse = f64::INFINITY;
    // alternate calibration and effect re-fits until the calibration-window fit settles
    for _round in 0..10 {
        if !has_gap {
            let ctx = context(st, feats, x, cal, gauges, cfg);
            let mut y_adj = y.clone();
            for e in &st.effects {
                y_adj -= effects::contribution(e, &ctx)?;
            }
            let (m, mean, var) = calibrate(calibrator, x, &y_adj, cal)?;
            st.model = m;
            st.mean = mean;
            st.var = var;
        }
        for k in 0..st.effects.len() {
            let ctx = context(st, feats, x, cal, gauges, cfg);
            let mut r = y - &st.mean;
            for (j, e) in st.effects.iter().enumerate() {
                if j != k {
                    r -= effects::contribution(e, &ctx)?;
                }
            }
            let spec = st.effects[k].spec.clone();
            if let Some(f) = effects::fit(&spec, &ctx, &r)? {
                st.effects[k] = f;
            }
        }
        let sse = mse_rows(&residual(st, y, feats, x, cal, gauges, cfg)?, cal);
        // 1e-4 relative: far below the noise-level changes the acceptance rule looks at
        if has_gap || (last_sse - sse).abs() <= 1e-4 * sse {
            break;
        }
        last_sse = sse;
    }
    Ok(())
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
