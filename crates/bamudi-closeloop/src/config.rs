//! Settings of the loop and the declared load of a model's inputs.

use crate::error::{CloseLoopError, Result};
use numerics::changepoint::MeanChangeParams;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A scalar load of the model inputs, `Σ_j weights_j x_j` (a gate's head `h_up − h_down`),
/// with the input that completes it to a coordinate pair (the gate's lower level) and the
/// level below which the model is unloaded (a gate with less than 1 in of head is open: no
/// thrust, no quoin force, no discrepancy).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadSpec {
    /// Feature name of the load (e.g. `head`).
    pub name: String,
    /// Weight of each model input.
    pub weights: Vec<f64>,
    /// The input paired with the load in the load nuisance's polynomial.
    pub companion: usize,
    /// Rows with a smaller load are unloaded.
    pub active_above: f64,
}

impl LoadSpec {
    /// The load `x[plus] − x[minus]` of `n_inputs` inputs, paired with `x[minus]`, active above
    /// `active_above`.
    pub fn difference(
        name: &str,
        plus: usize,
        minus: usize,
        n_inputs: usize,
        active_above: f64,
    ) -> Self {
        let mut weights = vec![0.0; n_inputs];
        weights[plus] = 1.0;
        weights[minus] = -1.0;
        Self {
            name: name.into(),
            weights,
            companion: minus,
            active_above,
        }
    }

    /// The load at inputs `x`.
    pub fn value(&self, x: &[f64]) -> f64 {
        let mut v = 0.0;
        for (w, xi) in self.weights.iter().zip(x) {
            if *w != 0.0 {
                v += w * xi;
            }
        }
        v
    }

    /// Whether the model is unloaded at `x`.
    pub fn unloaded(&self, x: &[f64]) -> bool {
        self.value(x) < self.active_above
    }

    fn validate(&self) -> Result<()> {
        if self.companion >= self.weights.len() || self.weights.iter().all(|w| *w == 0.0) {
            return Err(CloseLoopError::config(
                "load",
                format!(
                    "needs non-zero weights and a companion input among its {} inputs",
                    self.weights.len()
                ),
            ));
        }
        if !self.active_above.is_finite() {
            return Err(CloseLoopError::config(
                "load.active_above",
                "must be finite",
            ));
        }
        Ok(())
    }
}

/// Settings of the loop. Defaults in brackets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CloseLoopConfig {
    /// Fraction of the record (in time order) used for calibration [0.6].
    pub calibration_fraction: f64,
    /// Fraction of the record at its end kept as the final test window [0.2]: selection never
    /// sees it, and the loop's before/after error is reported on it. The rows between the
    /// calibration window and the test window are the validation window, where candidates
    /// are scored by rolling origins. `0` reports the error on the validation window instead
    /// (then selection has seen it; `results.json` says so in `error_window`).
    pub test_fraction: f64,
    /// Evaluation origins in the validation window [3]: at each origin every candidate (and
    /// every accepted effect) is fitted on all rows before it and scored on the rows up to
    /// the next origin (rolling-origin cross-validation); the first origin is the end of the
    /// calibration window.
    pub selection_origins: usize,
    /// Maximum number of effects added [4].
    pub max_steps: usize,
    /// Minimum relative reduction of the cross-validated mean square error to accept an effect [0.05].
    pub min_relative_improvement: f64,
    /// One-sided level of the test by which an effect that lowers the cross-validated mean
    /// square error by less than `min_relative_improvement` is still accepted [0.001]: the
    /// reduction of the squared residual, summed per day of the validation window, must have
    /// a one-sample Student t above its quantile at this level (days − 1 degrees of freedom,
    /// four days at least); the effect must lower the error in as many folds as the margin
    /// asks (two; one when there is one fold), and by at least `min_significant_improvement`
    /// overall. At most 0.05; `0` turns the test off (only the relative margin decides).
    pub improvement_significance: f64,
    /// Smallest relative reduction of the cross-validated mean square error the test of
    /// `improvement_significance` accepts [0.01].
    pub min_significant_improvement: f64,
    /// Temperature columns for the thermal effect; `None` = every column whose declared unit
    /// (`column_units`) is a temperature unit (see
    /// [`is_temperature_unit`](super::is_temperature_unit)) [None]. A name that is
    /// not a covariate column of the record is an error.
    pub temperature_columns: Option<Vec<String>>,
    /// Declared units of the record's covariate columns, e.g. `air_temp_f = "degF"` [none].
    /// They choose the thermal effect's candidates (a temperature unit) and the data-driven
    /// term's differences of same-unit columns (air minus water temperature); a column's name
    /// is never read for its meaning. A key that is not a covariate column of the record is
    /// an error, so a misspelt column cannot silently drop a candidate.
    pub column_units: BTreeMap<String, String>,
    /// The scalar load of the model inputs, when the model has one (a gate's head): it gives
    /// the load-path hysteresis effect and the load nuisance [None].
    pub load: Option<LoadSpec>,
    /// Name of the scalar parameter `θ` in effect names and reports, e.g. `gap` gives the
    /// effect `time_varying_gap` [`parameter`].
    pub parameter_name: String,
    /// Unit of the outputs, in effect parameter reports [`output units`].
    pub output_unit: String,
    /// Maximum number of covariates in the generic term [3].
    pub max_generic_features: usize,
    /// How the generic term selects its covariates [`stepwise_bic`].
    pub generic_selection: Selection,
    /// Lags of the Ljung-Box test [10].
    pub ljung_box_lags: usize,
    /// Family-wise significance level of the adequacy checks per window [0.01].
    pub significance: f64,
    /// Candidates re-calibrated at each step to decide between them [3]; at least 2 are
    /// (the best library effect and the best generic term) when both pass the screening.
    pub confirm_candidates: usize,
    /// The whole-record event scan of the final residual [enabled, PELT with the modified BIC].
    pub event_scan: EventScanConfig,
    /// The parameter tracked through the record [enabled, daily windows].
    pub track: TrackConfig,
    /// The sensor pass: faults found by the verdict and the scans made corrections, and the
    /// effects' parameters propagated to `θ` [enabled].
    pub sensor: SensorConfig,
}

impl Default for CloseLoopConfig {
    fn default() -> Self {
        Self {
            calibration_fraction: 0.6,
            test_fraction: 0.2,
            selection_origins: 3,
            max_steps: 4,
            min_relative_improvement: 0.05,
            improvement_significance: 0.001,
            min_significant_improvement: 0.01,
            temperature_columns: None,
            column_units: BTreeMap::new(),
            load: None,
            parameter_name: "parameter".into(),
            output_unit: "output units".into(),
            max_generic_features: 3,
            generic_selection: Selection::StepwiseBic,
            ljung_box_lags: 10,
            significance: 0.01,
            confirm_candidates: 3,
            event_scan: EventScanConfig::default(),
            track: TrackConfig::default(),
            sensor: SensorConfig::default(),
        }
    }
}

impl CloseLoopConfig {
    /// Sets the calibration fraction.
    ///
    /// ```
    /// let c = bamudi_closeloop::CloseLoopConfig::default().calibration_fraction(0.5);
    /// assert_eq!(c.calibration_fraction, 0.5);
    /// ```
    pub fn calibration_fraction(mut self, f: f64) -> Self {
        self.calibration_fraction = f;
        self
    }
    /// Sets the fraction of the record kept as the final test window.
    ///
    /// ```
    /// let c = bamudi_closeloop::CloseLoopConfig::default().test_fraction(0.25);
    /// assert_eq!(c.test_fraction, 0.25);
    /// ```
    pub fn test_fraction(mut self, f: f64) -> Self {
        self.test_fraction = f;
        self
    }
    /// Sets the number of rolling-origin evaluation origins in the validation window.
    ///
    /// ```
    /// let c = bamudi_closeloop::CloseLoopConfig::default().selection_origins(4);
    /// assert_eq!(c.selection_origins, 4);
    /// ```
    pub fn selection_origins(mut self, k: usize) -> Self {
        self.selection_origins = k;
        self
    }
    /// Sets the maximum number of effects.
    ///
    /// ```
    /// let c = bamudi_closeloop::CloseLoopConfig::default().max_steps(2);
    /// assert_eq!(c.max_steps, 2);
    /// ```
    pub fn max_steps(mut self, n: usize) -> Self {
        self.max_steps = n;
        self
    }
    /// Sets the minimum relative cross-validated improvement.
    ///
    /// ```
    /// let c = bamudi_closeloop::CloseLoopConfig::default().min_relative_improvement(0.1);
    /// assert_eq!(c.min_relative_improvement, 0.1);
    /// ```
    pub fn min_relative_improvement(mut self, f: f64) -> Self {
        self.min_relative_improvement = f;
        self
    }
    /// Sets the level of the test that accepts an effect below the relative margin (`0`: off).
    ///
    /// ```
    /// let c = bamudi_closeloop::CloseLoopConfig::default().improvement_significance(0.0);
    /// assert_eq!(c.improvement_significance, 0.0);
    /// ```
    pub fn improvement_significance(mut self, p: f64) -> Self {
        self.improvement_significance = p;
        self
    }
    /// Sets the smallest relative reduction the significance test accepts.
    ///
    /// ```
    /// let c = bamudi_closeloop::CloseLoopConfig::default().min_significant_improvement(0.02);
    /// assert_eq!(c.min_significant_improvement, 0.02);
    /// ```
    pub fn min_significant_improvement(mut self, f: f64) -> Self {
        self.min_significant_improvement = f;
        self
    }

    /// Sets how many screened candidates are re-calibrated per step.
    ///
    /// ```
    /// let c = bamudi_closeloop::CloseLoopConfig::default().confirm_candidates(4);
    /// assert_eq!(c.confirm_candidates, 4);
    /// ```
    pub fn confirm_candidates(mut self, k: usize) -> Self {
        self.confirm_candidates = k;
        self
    }

    /// Declares the model inputs' scalar load.
    ///
    /// ```
    /// use bamudi_closeloop::{CloseLoopConfig, LoadSpec};
    /// let c = CloseLoopConfig::default().load(LoadSpec::difference("head", 0, 1, 2, 1.0));
    /// assert_eq!(c.load.unwrap().value(&[500.0, 100.0]), 400.0);
    /// ```
    pub fn load(mut self, load: LoadSpec) -> Self {
        self.load = Some(load);
        self
    }

    /// Declares the unit of a covariate column (a temperature unit makes it a thermal
    /// candidate; columns of one unit give difference features).
    ///
    /// ```
    /// let c = bamudi_closeloop::CloseLoopConfig::default().column_unit("air_temp_f", "degF");
    /// assert_eq!(c.column_units["air_temp_f"], "degF");
    /// ```
    pub fn column_unit(mut self, column: &str, unit: &str) -> Self {
        self.column_units.insert(column.into(), unit.into());
        self
    }

    /// Checks the column names of `temperature_columns` and `column_units` against the
    /// record's covariate columns (`file` and `covariates` name them in the error).
    pub fn check_columns(&self, file: &str, covariates: &[String]) -> Result<()> {
        let missing = |key: &'static str, name: &str| {
            Err(CloseLoopError::config(
                key,
                format!(
                    "'{name}' is not a covariate column of {file} (its covariate columns: {})",
                    if covariates.is_empty() {
                        "none".to_string()
                    } else {
                        covariates.join(", ")
                    }
                ),
            ))
        };
        for name in self.temperature_columns.iter().flatten() {
            if !covariates.contains(name) {
                return missing("temperature_columns", name);
            }
        }
        for (name, unit) in &self.column_units {
            if !covariates.contains(name) {
                return missing("column_units", name);
            }
            if unit.trim().is_empty() {
                return Err(CloseLoopError::config(
                    "column_units",
                    format!("the unit of '{name}' is empty"),
                ));
            }
        }
        Ok(())
    }

    /// Names the outputs' unit (in effect parameter reports).
    pub fn output_unit(mut self, unit: &str) -> Self {
        self.output_unit = unit.to_string();
        self
    }

    /// Names the scalar parameter `θ` (in effect names and reports).
    pub fn parameter_name(mut self, name: &str) -> Self {
        self.parameter_name = name.to_string();
        self
    }

    /// Checks every field (errors name the key and say what is allowed); the loop checks its
    /// configuration itself, this lets a caller check it before any work.
    pub fn validate(&self) -> Result<()> {
        let bad = |name, reason: String| Err(CloseLoopError::InvalidConfig { name, reason });
        if !(self.calibration_fraction > 0.0 && self.calibration_fraction < 1.0) {
            return bad(
                "calibration_fraction",
                format!("must be in (0, 1), got {}", self.calibration_fraction),
            );
        }
        if !(self.test_fraction >= 0.0 && self.calibration_fraction + self.test_fraction < 1.0) {
            return bad(
                "test_fraction",
                format!(
                    "must be >= 0 and leave a validation window after the calibration window (calibration_fraction + test_fraction < 1), got {} with calibration_fraction {}",
                    self.test_fraction, self.calibration_fraction
                ),
            );
        }
        if self.selection_origins == 0 {
            return bad("selection_origins", "must be >= 1".into());
        }
        if self.min_relative_improvement.is_nan() || self.min_relative_improvement < 0.0 {
            return bad(
                "min_relative_improvement",
                format!("must be >= 0, got {}", self.min_relative_improvement),
            );
        }
        if !(self.improvement_significance >= 0.0 && self.improvement_significance <= 0.05) {
            return bad(
                "improvement_significance",
                format!(
                    "must be in [0, 0.05] (0 turns the test off), got {}",
                    self.improvement_significance
                ),
            );
        }
        if self.min_significant_improvement.is_nan() || self.min_significant_improvement < 0.0 {
            return bad(
                "min_significant_improvement",
                format!("must be >= 0, got {}", self.min_significant_improvement),
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
        if let Some(l) = &self.load {
            l.validate()?;
        }
        self.event_scan.validate()?;
        self.sensor.validate()?;
        self.track.validate()
    }
}

/// How the data-driven term selects its covariates (TOML: `"stepwise_bic"`, `"stepwise_cv"`,
/// `"group_lasso_cv"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Selection {
    /// Forward stepwise least squares, stopped by BIC.
    #[default]
    StepwiseBic,
    /// The same forward path, cut at the length with the least held-out error over five
    /// contiguous blocks of the calibration rows (the path rebuilt without each block).
    StepwiseCv,
    /// The multi-task lasso path (`linfa-elasticnet`, a group penalty across gauges) with the
    /// penalty chosen by blocked cross-validation in time of the refitted least squares.
    GroupLassoCv,
}

/// Settings of the event scan. Defaults in brackets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EventScanConfig {
    /// Whether the scan runs [true].
    pub enabled: bool,
    /// Fewest rows at a level: shorter excursions are outliers, not events [8].
    pub min_segment_rows: usize,
    /// Penalty per change in units of `ln n` [3, the modified BIC].
    pub penalty_per_change_ln_n: f64,
    /// Confidence level of the onset and size intervals [0.95].
    pub level: f64,
}

impl Default for EventScanConfig {
    fn default() -> Self {
        let p = MeanChangeParams::default();
        Self {
            enabled: true,
            min_segment_rows: p.min_segment,
            penalty_per_change_ln_n: p.penalty_per_change_ln_n,
            level: p.level,
        }
    }
}

impl EventScanConfig {
    pub(crate) fn params(&self) -> MeanChangeParams {
        MeanChangeParams {
            min_segment: self.min_segment_rows,
            penalty_per_change_ln_n: self.penalty_per_change_ln_n,
            level: self.level,
        }
    }

    pub(super) fn validate(&self) -> Result<()> {
        let bad = |key: &'static str, why: &str| Err(CloseLoopError::config(key, why.to_string()));
        if self.min_segment_rows < 2 {
            return bad("event_scan.min_segment_rows", "must be at least 2");
        }
        if !(self.penalty_per_change_ln_n > 0.0 && self.penalty_per_change_ln_n.is_finite()) {
            return bad("event_scan.penalty_per_change_ln_n", "must be positive");
        }
        if !(self.level > 0.5 && self.level < 1.0) {
            return bad("event_scan.level", "must lie in (0.5, 1)");
        }
        Ok(())
    }
}

/// Settings of the tracker. Defaults in brackets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackConfig {
    /// Whether the parameter is tracked over the whole record after the loop, for the report
    /// and the parameter now [true]. (The loop's time-varying-parameter effect tracks it over
    /// the calibration window with these settings either way.)
    pub enabled: bool,
    /// Window length (hours) [24].
    pub window_hours: f64,
    /// In-control average run length of the change alarm, in windows [3650: ten years of
    /// daily windows between false alarms].
    pub in_control_windows: f64,
    /// CUSUM reference value (standard deviations of an innovation) [0.5].
    pub cusum_k: f64,
    /// Nodes of the coarse grid over the prior support [41].
    pub grid_nodes: usize,
}

impl Default for TrackConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            window_hours: 24.0,
            in_control_windows: 3650.0,
            cusum_k: 0.5,
            grid_nodes: 41,
        }
    }
}

impl TrackConfig {
    pub(super) fn validate(&self) -> Result<()> {
        let bad = |key: &'static str, why: &str| Err(CloseLoopError::config(key, why.to_string()));
        if !(self.window_hours > 0.0 && self.window_hours.is_finite()) {
            return bad("track.window_hours", "must be positive");
        }
        if !(self.in_control_windows > 1.0 && self.in_control_windows.is_finite()) {
            return bad("track.in_control_windows", "must exceed 1");
        }
        if !(self.cusum_k > 0.0 && self.cusum_k.is_finite()) {
            return bad("track.cusum_k", "must be positive");
        }
        if self.grid_nodes < 5 {
            return bad("track.grid_nodes", "must be at least 5");
        }
        Ok(())
    }
}

/// Settings of the sensor pass (TOML section `[sensor]`).
///
/// ```
/// use bamudi_closeloop::{CloseLoopConfig, SensorConfig};
/// let cfg: CloseLoopConfig = toml::from_str("[sensor]\nnoise_ratio = 3.0\n").unwrap();
/// assert_eq!(cfg.sensor.noise_ratio, 3.0);
/// assert!(cfg.sensor.enabled); // the pass runs unless `enabled = false`
/// assert_eq!(cfg.sensor.uncertainty_draws, SensorConfig::default().uncertainty_draws);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SensorConfig {
    /// Look for sensor faults and correct them [true].
    pub enabled: bool,
    /// Penalty of one change found by a scan (exchange, noise), in units of `ln n` of the
    /// residual sum of squares over the noise variance, as the event scan's modified BIC [3].
    pub penalty_per_change_ln_n: f64,
    /// Fewest rows a stuck reading must repeat, and a noise change must last [12].
    pub min_span_rows: usize,
    /// Smallest ratio of noise sd after / before for a gauge to be set aside [1.5].
    pub noise_ratio: f64,
    /// Draws of the accepted effects' and corrections' parameters propagated to `θ` (one
    /// calibration each; 0 = the last calibration's posterior alone) [4].
    pub uncertainty_draws: usize,
    /// Seed of those draws [58].
    pub seed: u64,
    /// Offer a change seen on several gauges after the calibration window a third answer
    /// beside the gap and one sensor: a library effect from that day on (the onset test of `docs/closeloop.md`)
    /// [true].
    pub onset_effects: bool,
}

impl Default for SensorConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            penalty_per_change_ln_n: 3.0,
            min_span_rows: 12,
            noise_ratio: 1.5,
            uncertainty_draws: 4,
            seed: 58,
            onset_effects: true,
        }
    }
}

impl SensorConfig {
    pub(super) fn validate(&self) -> Result<()> {
        let bad = |key: &'static str, why: &str| Err(CloseLoopError::config(key, why.to_string()));
        if !(self.penalty_per_change_ln_n > 0.0 && self.penalty_per_change_ln_n.is_finite()) {
            return bad("sensor.penalty_per_change_ln_n", "must be positive");
        }
        if self.min_span_rows < 3 {
            return bad("sensor.min_span_rows", "must be at least 3");
        }
        if !(self.noise_ratio > 1.0 && self.noise_ratio.is_finite()) {
            return bad("sensor.noise_ratio", "must be above 1");
        }
        Ok(())
    }
}
