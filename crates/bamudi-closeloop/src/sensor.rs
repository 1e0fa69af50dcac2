//! Sensor findings made corrections: the observation model of the loop.
//!
//! A sensor fault changes what a gauge reports, not what the gate does. The loop looks for
//! faults in four places and turns each finding into a correction of the readings (a fitted
//! observation-model effect with its size and sd) or, when the reading carries no usable
//! information (a stuck gauge, a gauge whose noise jumped), sets the gauge aside for the
//! affected span:
//!
//! * the first calibration's adequacy verdict, when it attributes its failures to sensors
//!   (`sensor_gain`, `sensor_offset`, `sensor_drift`, `sensor_step` on one or two gauges,
//!   jointly fitted with the calibration: [`bamudi::adequacy`]); a discrepancy can absorb a
//!   gain so that the residual looks clean, and only the verdict sees it;
//! * the exchange scan: every pair of gauges, the onset at which exchanging their readings
//!   from then on (or up to then: an exchange the calibration learnt) lowers the residual sum
//!   of squares most; a finding when the decrease exceeds a modified-BIC penalty;
//! * the gain scan: one gauge's change of slope on the fitted values from an onset to the end;
//! * the stuck scan (a reading that repeats exactly) and the noise scan (a change of level of
//!   the log squared first differences of one gauge's residual);
//! * after selection, every change of level the whole-record scan finds on one gauge alone
//!   after the calibration window, unless a change of the parameter explains it better
//!   ([`attribute`]), and the parameter's change alarm, which is withheld when a sensor
//!   hypothesis explains the change better, or when the residual shows no change from the
//!   day it dates (the gap alarm guard).
//!
//! Corrections are applied to the readings before the loop's calibrations; set-aside cells
//! are replaced by the model's prediction and left out of every error the report states.

use super::record::MeasuredRecord;
use crate::config::SensorConfig;
use crate::error::{CloseLoopError, Result};
use bamudi::adequacy::{AdequacyReport, FaultKind};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Largest loss of gain (`−k`) a correction rescales; beyond it the gauge is set aside.
pub(super) const MAX_GAIN_LOSS: f64 = 0.5;

/// Which rows of the calibration window a calibration reads once the sensor pass has set
/// cells aside.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "basis")]
pub enum CalibrationRows {
    /// Every row: no cell of the calibration window is set aside.
    Window,
    /// The rows where no gauge is set aside: the set-aside cells are left out, not filled.
    WithoutSetAside {
        /// How many rows that is.
        complete_rows: usize,
        /// The rows (indices into the record).
        #[serde(skip)]
        rows: Vec<usize>,
    },
    /// Every row, the set-aside cells filled with the latest calibration's prediction: fewer
    /// than `MIN_COMPLETE_ROWS` rows are free of set-aside cells. The fill is a fixed point,
    /// not a calibration without the gauge (the loop re-calibrates on the filled readings until
    /// the fill settles).
    Filled {
        /// Rows of the window free of set-aside cells.
        complete_rows: usize,
    },
}

impl CalibrationRows {
    /// The rows of `cal` to calibrate on, given the set-aside cells `mask`.
    pub(crate) fn of(cal: &[usize], mask: &DMatrix<bool>) -> Self {
        let complete: Vec<usize> = cal
            .iter()
            .copied()
            .filter(|&i| i < mask.nrows() && !mask.row(i).iter().any(|m| *m))
            .collect();
        if complete.len() == cal.len() {
            Self::Window
        } else if complete.len() >= MIN_COMPLETE_ROWS {
            Self::WithoutSetAside {
                complete_rows: complete.len(),
                rows: complete,
            }
        } else {
            Self::Filled {
                complete_rows: complete.len(),
            }
        }
    }

    /// The rows a calibration reads (`cal` unless some are left out).
    pub(crate) fn rows<'a>(&'a self, cal: &'a [usize]) -> &'a [usize] {
        match self {
            Self::WithoutSetAside { rows, .. } => rows,
            _ => cal,
        }
    }
}

/// Fewest calibration-window rows free of set-aside cells that a calibration reads instead of
/// filling those cells: the loop's own least calibration window (30 rows). Set before any
/// panel record was run with this rule, from clean FE-gate records (24-in mesh, seeds 7-9):
/// the first 12 hourly rows alone give the gap to ±0.16-0.18 in, the whole 864-row window to
/// ±0.09-0.10 in, so 30 complete rows lose little against filled cells that vote for the
/// first, faulty calibration.
pub(crate) const MIN_COMPLETE_ROWS: usize = 30;

/// What kind of sensor fault a finding is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SensorKind {
    /// The gauge factor is off: reading = (1 + k) × strain over the span (`size` = k).
    Gain,
    /// A constant added to the reading (`size` in output units).
    Offset,
    /// A step in the zero from the span's start (`size` in output units).
    Step,
    /// A zero that drifts linearly from the span's start (`size` in output units per day).
    Drift,
    /// Two channels exchanged from the span's start (wiring, logger remapping).
    ChannelExchange,
    /// The reading repeats exactly (a stuck or dead gauge): set aside.
    Stuck,
    /// The gauge's noise grew by `size` (ratio of sds): set aside.
    NoiseIncrease,
}

impl SensorKind {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Gain => "gain",
            Self::Offset => "offset",
            Self::Step => "step",
            Self::Drift => "drift",
            Self::ChannelExchange => "channel_exchange",
            Self::Stuck => "stuck",
            Self::NoiseIncrease => "noise_increase",
        }
    }
}

/// Corrected, or set aside for the span.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SensorAction {
    /// The readings are corrected by the fitted fault.
    Corrected,
    /// The readings of the span are not used.
    SetAside,
}

/// One sensor finding and what the loop did with it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorFinding {
    /// Fault kind.
    pub kind: SensorKind,
    /// Gauge(s) (two for an exchange).
    pub gauges: Vec<String>,
    /// Their columns.
    pub gauge_columns: Vec<usize>,
    /// First row of the span.
    pub from_row: usize,
    /// One past the last row of the span.
    pub to_row: usize,
    /// Day of the span's first row (days since the first row).
    pub from_day: f64,
    /// Day of the span's last row.
    pub to_day: f64,
    /// Fitted size (see [`SensorKind`]); `None` for an exchange or a stuck gauge.
    pub size: Option<f64>,
    /// Its standard deviation.
    pub size_sd: Option<f64>,
    /// Unit of `size` (output units, `fraction` for a gain, `ratio` for noise).
    pub unit: String,
    /// Corrected or set aside.
    pub action: SensorAction,
    /// Which analysis found it.
    pub source: String,
    /// The evidence in words.
    pub evidence: String,
}

impl SensorFinding {
    /// `"SG3 gain +0.050 ± 0.004 fraction from day 0.0 (adequacy verdict)"`.
    pub fn describe(&self) -> String {
        let size = match (self.size, self.size_sd) {
            (Some(s), Some(sd)) => format!(" {s:+.3} ± {sd:.3} {}", self.unit),
            (Some(s), None) => format!(" {s:+.3} {}", self.unit),
            _ => String::new(),
        };
        format!(
            "{} {}{size} from day {:.2} to {:.2}, {} ({})",
            self.gauges.join("<->"),
            self.kind.name(),
            self.from_day,
            self.to_day,
            match self.action {
                SensorAction::Corrected => "corrected",
                SensorAction::SetAside => "set aside",
            },
            self.source
        )
    }
}

/// The structure-or-sensor test of one change (see `attribute`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AttributionTest {
    /// What was tested (`gap alarm`, or a gauge's change of level).
    pub subject: String,
    /// Day the tested rows start.
    pub from_day: f64,
    /// Residual sum of squares over the noise variance, no change.
    pub none: f64,
    /// The same with the best change of the parameter: a step or a ramp from the change's start
    /// (one size; the model's sensitivities).
    pub structure: f64,
    /// The same with the best sensor hypothesis.
    pub sensor: f64,
    /// That hypothesis, e.g. `SG3 step`.
    pub sensor_hypothesis: String,
    /// Penalty the sensor side pays for choosing among its `m` hypotheses against the
    /// structure's two (`2 ln m − 2 ln 2`).
    pub penalty: f64,
    /// `sensor` (its score plus the penalty below the structure's), `structure` (else, when
    /// the change of the parameter lowers the score by at least the χ²₁ 99 % quantile, 6.6),
    /// or `unsupported` (neither: the residual does not show a change from that day).
    pub verdict: String,
}

/// A change alarm of the parameter the structure-or-sensor test withheld.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WithheldAlarm {
    /// The alarm as the track raised it.
    pub alarm: super::TrackAlarm,
    /// Why it was withheld, in words.
    pub reason: String,
}

/// Everything the sensor pass found and did (`sensor` in `results.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct SensorReport {
    /// The findings in the order they were applied.
    pub findings: Vec<SensorFinding>,
    /// Cells (row × gauge) set aside.
    pub set_aside_cells: usize,
    /// The structure-or-sensor tests run.
    pub attribution_tests: Vec<AttributionTest>,
    /// `θ` of a calibration on the same rows with the accepted effects but without the
    /// sensor corrections (`None` when nothing was corrected).
    pub theta_without_corrections: Option<super::ThetaSummary>,
    /// `θ` with them (the loop's `theta_after`).
    pub theta_with_corrections: Option<super::ThetaSummary>,
    /// Whether a correction's span reaches into the test window while the scan that found it
    /// dated and sized it on every row, the test window's included (every finding but the
    /// adequacy verdict's, which reads the calibration's rows only): the error after is then
    /// not fully out of sample for that gauge and span.
    pub fitted_on_test_rows: bool,
    /// Per gauge, the test window's RMSE with every correction, those that start in the test
    /// window too (fitted on its rows: in-sample); the report's `heldout_rmse_after` counts
    /// only the corrections that start before it (output units; `None` without a test window).
    #[serde(default, deserialize_with = "super::stats::nan_as_null::opt_vec")]
    pub heldout_rmse_after_all_corrections: Option<Vec<f64>>,
    /// The parameter's change alarm, withheld, and why (`attribution_tests` holds the tests).
    #[serde(default)]
    pub withheld_gap_alarm: Option<WithheldAlarm>,
    /// One-gauge findings (each a sensor's by its own test) not applied because findings on
    /// other gauges start within a day of them: one change on several gauges at once is the
    /// structure's doing, not a sensor's.
    #[serde(default)]
    pub coincident_findings: Vec<SensorFinding>,
    /// Which calibration-window rows the calibrations after the pass read: every row, the
    /// rows where no gauge is set aside, or every row with the set-aside cells filled (too few
    /// rows free of them); `None` without a finding.
    #[serde(default)]
    pub calibration_rows: Option<CalibrationRows>,
}

/// The readings with every correction applied, and the set-aside cells (`true`), whose
/// readings are replaced by `fill` (the model's prediction). `draw[k]`, when given, replaces
/// finding `k`'s size by a draw (standard normal times its sd added).
pub(crate) fn apply(
    findings: &[SensorFinding],
    y: &DMatrix<f64>,
    fill: &DMatrix<f64>,
    time_h: &[f64],
    draw: Option<&[f64]>,
) -> (DMatrix<f64>, DMatrix<bool>) {
    let mut out = y.clone();
    let mut mask = DMatrix::from_element(y.nrows(), y.ncols(), false);
    for (k, f) in findings.iter().enumerate() {
        let size = f.size.unwrap_or(0.0) + draw.map_or(0.0, |d| d[k] * f.size_sd.unwrap_or(0.0));
        let g = f.gauge_columns[0];
        let span = f.from_row..f.to_row.min(y.nrows());
        if f.action == SensorAction::SetAside {
            for i in span {
                mask[(i, g)] = true;
                out[(i, g)] = fill[(i, g)];
            }
            continue;
        }
        match f.kind {
            // a drawn size (`draw`) is kept from dividing by less than the loss a correction
            // may make (`MAX_GAIN_LOSS`)
            SensorKind::Gain => {
                let scale = (1.0 + size).max(1.0 - MAX_GAIN_LOSS);
                span.for_each(|i| out[(i, g)] /= scale)
            }
            SensorKind::Offset | SensorKind::Step => span.for_each(|i| out[(i, g)] -= size),
            SensorKind::Drift => {
                let t0 = time_h[f.from_row.min(y.nrows() - 1)];
                span.for_each(|i| out[(i, g)] -= size * (time_h[i] - t0) / 24.0);
            }
            SensorKind::ChannelExchange => {
                let h = f.gauge_columns[1];
                for i in span {
                    let t = out[(i, g)];
                    out[(i, g)] = out[(i, h)];
                    out[(i, h)] = t;
                }
            }
            // always set aside (above)
            SensorKind::Stuck | SensorKind::NoiseIncrease => {}
        }
    }
    (out, mask)
}

/// The log of the Jacobian that [`apply`]'s corrections add to a density of the corrected
/// readings on `rows` to make it one of the readings as recorded: a gain correction divides a
/// reading by its scale `s`, so each corrected cell adds `-ln s` (an exchange, a step, a drift
/// or an offset has a Jacobian of one; set-aside cells are not comparable and add nothing).
/// Two corrections of the same readings compare by their calibrations' log evidence plus
/// this.
pub(crate) fn log_jacobian(findings: &[SensorFinding], rows: &[usize]) -> f64 {
    findings
        .iter()
        .filter(|f| f.kind == SensorKind::Gain && f.action != SensorAction::SetAside)
        .map(|f| {
            let scale = (1.0 + f.size.unwrap_or(0.0)).max(1.0 - MAX_GAIN_LOSS);
            let cells = rows
                .iter()
                .filter(|&&i| (f.from_row..f.to_row).contains(&i))
                .count();
            -(cells as f64) * scale.ln()
        })
        .sum()
}

/// What the scans read: the record, the residual of the current model and its mean.
pub(crate) struct ScanInput<'a> {
    pub rec: &'a MeasuredRecord,
    /// Data − model mean (− accepted effects), every row.
    pub residual: &'a DMatrix<f64>,
    /// The model's prediction (mean + accepted effects), every row.
    pub fitted: &'a DMatrix<f64>,
    pub unit: &'a str,
    /// First row a finding may start at: after selection, the end of the calibration window
    /// (a correction there would need a new calibration, which the post-selection pass does
    /// not make).
    pub earliest: usize,
}

impl ScanInput<'_> {
    fn day(&self, i: usize) -> f64 {
        self.rec.time_h[i.min(self.rec.len() - 1)] / 24.0
    }

    fn finding(
        &self,
        kind: SensorKind,
        gauges: Vec<usize>,
        span: (usize, usize),
        size: (Option<f64>, Option<f64>, &str),
        source: &str,
        evidence: String,
    ) -> SensorFinding {
        SensorFinding {
            kind,
            gauges: gauges
                .iter()
                .map(|&g| self.rec.gauge_names[g].clone())
                .collect(),
            gauge_columns: gauges,
            from_row: span.0,
            to_row: span.1,
            from_day: self.day(span.0),
            to_day: self.day(span.1.saturating_sub(1)),
            size: size.0,
            size_sd: size.1,
            unit: size.2.to_string(),
            action: match kind {
                SensorKind::Stuck | SensorKind::NoiseIncrease => SensorAction::SetAside,
                // a gauge that lost more than half its signal is not rescaled by `1/(1+k)`
                // (the noise would be amplified with it): set aside
                SensorKind::Gain if size.0.is_some_and(|k| k < -MAX_GAIN_LOSS) => {
                    SensorAction::SetAside
                }
                _ => SensorAction::Corrected,
            },
            source: source.into(),
            evidence,
        }
    }
}

/// The faults the calibration's own verdict attributed to sensors that the loop's effect
/// library cannot fit, as corrections over the whole record: a gain, and a constant offset.
/// A step and a drift are left to the library's `gauge_offset_jump` and `gauge_drift`, which
/// date and size them on every row of the record, selected by cross-validation; the verdict
/// sees only the calibration's rows, whose positions in time it does not carry.
pub(crate) fn from_verdict(inp: &ScanInput<'_>, verdict: &AdequacyReport) -> Vec<SensorFinding> {
    let Some(corr) = &verdict.sensor_correction else {
        return vec![];
    };
    let n = inp.rec.len();
    corr.faults
        .iter()
        .filter_map(|f| {
            let g = inp.rec.gauge_names.iter().position(|n| *n == f.gauge)?;
            // a whole-record gain or offset on one gauge is also what a local deviation of the
            // structure near that gauge looks like (measured: a skin plate 5 % thinner than
            // drawn, undeclared, reads as a gain of +4.6 % on SG6): say so with the correction
            let evidence = format!(
                "the calibration's adequacy verdict: sensor_{} on {} (z {:.1}, joint fit); over \
                 the whole record this is also what a local deviation of the structure near the \
                 gauge looks like (a plate thinner than drawn, a stiffer connection): check the \
                 gauge's calibration before reading it as a sensor fault",
                f.kind.name(),
                f.gauge,
                f.z
            );
            let src = "adequacy verdict";
            let unit = inp.unit;
            Some(match f.kind {
                FaultKind::Gain => inp.finding(
                    SensorKind::Gain,
                    vec![g],
                    (0, n),
                    (Some(f.estimate), Some(f.sd), "fraction"),
                    src,
                    evidence,
                ),
                FaultKind::Offset => inp.finding(
                    SensorKind::Offset,
                    vec![g],
                    (0, n),
                    (Some(f.estimate), Some(f.sd), unit),
                    src,
                    evidence,
                ),
                FaultKind::Drift | FaultKind::Step => return None,
            })
        })
        .collect()
}

/// Per gauge, the variance the scans' scores divide by: the residual's robust long-run
/// variance (AR(1); [`numerics::changepoint::NoiseScale::robust`]), because a model's misfit
/// leaves the residual autocorrelated and a least-squares fit of one size over many rows
/// varies with the long-run variance, not the white-noise one; the white-noise variance from
/// first differences when the long-run scale cannot be estimated, and never below it. Over
/// `rows`: a change inside them would read as autocorrelation and inflate the scale.
fn noise_var(r: &DMatrix<f64>, rows: std::ops::Range<usize>) -> Vec<f64> {
    (0..r.ncols())
        .map(|g| {
            let col: Vec<f64> = rows.clone().map(|i| r[(i, g)]).collect();
            let white = numerics::robust::noise_sd_from_differences(&col).max(1e-9);
            let long =
                numerics::changepoint::NoiseScale::robust(&col).map_or(white, |s| s.long_run_sd);
            long.max(white).powi(2)
        })
        .collect()
}

/// The rows a change starting at `from` is judged against: those before it, when there are at
/// least a quarter of the record's rows, else every row.
fn quiet_rows(from: usize, n: usize) -> std::ops::Range<usize> {
    if 4 * from >= n { 0..from } else { 0..n }
}

/// What is left of gain change `f` in residual `r` of fitted values `m`: the change of the
/// gauge's slope at the finding's onset ([`GainContrast`]) and its sd (`None` when the fitted
/// values vanish on either side).
pub(crate) fn gain_remainder(
    r: &DMatrix<f64>,
    m: &DMatrix<f64>,
    f: &SensorFinding,
) -> Option<(f64, f64)> {
    let g = f.gauge_columns[0];
    let c = GainContrast::at(r, m, g, f.from_row)?;
    let var = noise_var(r, quiet_rows(f.from_row, r.nrows()))[g];
    Some((c.size, (var / c.information).sqrt()))
}

/// The onset among `rows` at which gauge `g`'s change of slope on fitted values `m` removes the
/// most of residual `r` ([`GainContrast`]), with the change's size and sd there (`None` when
/// the fitted values vanish on either side of every candidate).
pub(crate) fn gain_onset(
    r: &DMatrix<f64>,
    m: &DMatrix<f64>,
    g: usize,
    rows: std::ops::Range<usize>,
) -> Option<(usize, f64, f64)> {
    let n = r.nrows();
    let (at, c) = rows
        .filter(|&i| i > 0 && i + 1 < n)
        .filter_map(|i| GainContrast::at(r, m, g, i).map(|c| (i, c)))
        .max_by(|a, b| a.1.explained.total_cmp(&b.1.explained))?;
    let var = noise_var(r, quiet_rows(at, n))[g];
    Some((at, c.size, (var / c.information).sqrt()))
}

/// Channel exchanges: for every pair `(a, b)` and onset `τ`, the decrease of the residual sum
/// of squares when their readings are exchanged from `τ` to the end, over the noise variance
/// (the larger of the two gauges'); a finding when its best exceeds the threshold of
/// [`exchange_candidates`] and the exchange also beats a free level change on each gauge (an
/// exchange is a specific pattern; two steps are not one). One exchange per gauge, the
/// strongest.
pub(crate) fn exchange_scan(inp: &ScanInput<'_>, cfg: &SensorConfig) -> Vec<SensorFinding> {
    let mut used = vec![false; inp.residual.ncols()];
    let mut out = vec![];
    for f in exchange_candidates(inp, cfg, Side::After) {
        let (a, b) = (f.gauge_columns[0], f.gauge_columns[1]);
        if !(used[a] || used[b]) {
            used[a] = true;
            used[b] = true;
            out.push(f);
        }
    }
    out
}

/// Which rows of a candidate exchange are exchanged: from its day to the end, or from the
/// first row up to its day.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Side {
    After,
    Before,
}

/// Every pair's best exchange on `side` of an onset `τ` whose decrease of the residual sum of
/// squares exceeds `penalty_per_change_ln_n · ln n + 2 ln(pairs) + 2 ln 2` (the modified BIC,
/// with one choice among the pairs and one between the two sides) and beats two free level
/// changes, strongest first.
///
/// The side before `τ` is where an exchange that covers most of the calibration window shows:
/// the calibration learnt it (its discrepancy maps one gauge's strain onto the other's), so the
/// residual is large where the readings are right. Which side was wired right is then decided
/// by re-calibrating both ways (`correct::pre_pass`).
pub(crate) fn exchange_candidates(
    inp: &ScanInput<'_>,
    cfg: &SensorConfig,
    side: Side,
) -> Vec<SensorFinding> {
    let (r, m) = (inp.residual, inp.fitted);
    let (n, k) = (r.nrows(), r.ncols());
    if n < 2 * cfg.min_span_rows || k < 2 {
        return vec![];
    }
    let var = noise_var(r, 0..r.nrows());
    let pairs = (k * (k - 1) / 2) as f64;
    let threshold =
        cfg.penalty_per_change_ln_n * (n as f64).ln() + 2.0 * pairs.ln() + 2.0 * 2f64.ln();
    let (edge, min_span) = (cfg.min_span_rows.min(n), cfg.min_span_rows.min(8));
    let mut found: Vec<(f64, usize, usize, (usize, usize))> = vec![];
    for a in 0..k {
        for b in a + 1..k {
            let s2 = var[a].max(var[b]);
            let gain = |i: usize| {
                let ya = r[(i, a)] + m[(i, a)];
                let yb = r[(i, b)] + m[(i, b)];
                let before = r[(i, a)].powi(2) + r[(i, b)].powi(2);
                let after = (yb - m[(i, a)]).powi(2) + (ya - m[(i, b)]).powi(2);
                (before - after) / s2
            };
            // running sums of the gain of exchanging each row, from the end or from the start
            let mut best = (0.0, (n, n));
            let mut s = 0.0;
            match side {
                Side::After => {
                    for i in (edge..n).rev() {
                        s += gain(i);
                        if n - i >= min_span && s > best.0 {
                            best = (s, (i, n));
                        }
                    }
                }
                Side::Before => {
                    for i in 0..n - edge {
                        s += gain(i);
                        if i + 1 >= min_span && s > best.0 {
                            best = (s, (0, i + 1));
                        }
                    }
                }
            }
            if best.0 > threshold && beats_two_steps(r, a, b, best.1, best.0, &var) {
                found.push((best.0, a, b, best.1));
            }
        }
    }
    found.sort_by(|x, y| y.0.total_cmp(&x.0));
    found
        .into_iter()
        .map(|(stat, a, b, span)| {
            inp.finding(
                SensorKind::ChannelExchange,
                vec![a, b],
                span,
                (None, None, ""),
                "exchange scan",
                format!(
                    "exchanging {} and {} from day {:.2} to {:.2} lowers the residual sum of squares by {stat:.0} noise variances (threshold {threshold:.1})",
                    inp.rec.gauge_names[a],
                    inp.rec.gauge_names[b],
                    inp.day(span.0),
                    inp.day(span.1 - 1)
                ),
            )
        })
        .collect()
}

/// The day an exchange of `a` and `b` starts or ends, read without trusting the fit's map of
/// the pair: the row `τ` at which regressing both gauges' readings on the pair's fitted values
/// (and a constant) separately before and after `τ` leaves the smallest residual sum of
/// squares (each gauge over its noise variance, at least `min_span` rows a side). A fit that
/// learnt an exchange in part maps each gauge onto a mixture of the two strains; the mixture
/// changes at `τ` whichever the fit learnt, so the two-segment regression dates it where the
/// exchange scan's running sums, which read the fit's map as the truth, may not.
pub(crate) fn exchange_onset(
    y: &DMatrix<f64>,
    m: &DMatrix<f64>,
    (a, b): (usize, usize),
    min_span: usize,
) -> Option<usize> {
    use nalgebra::{Matrix3, Vector3};
    let n = y.nrows();
    if n < 2 * min_span.max(4) {
        return None;
    }
    let r = y - m;
    let var = noise_var(&r, 0..n);
    // running sums of X'X, X'y and y'y (X = [1, m_a, m_b]) per gauge
    let x = |i: usize| Vector3::new(1.0, m[(i, a)], m[(i, b)]);
    let mut xx = vec![Matrix3::zeros(); n + 1];
    let mut xy = vec![[Vector3::zeros(); 2]; n + 1];
    let mut yy = vec![[0.0; 2]; n + 1];
    for i in 0..n {
        let xi = x(i);
        xx[i + 1] = xx[i] + xi * xi.transpose();
        for (k, g) in [a, b].into_iter().enumerate() {
            xy[i + 1][k] = xy[i][k] + xi * y[(i, g)];
            yy[i + 1][k] = yy[i][k] + y[(i, g)].powi(2);
        }
    }
    let rss = |lo: usize, hi: usize| -> f64 {
        let sxx = xx[hi] - xx[lo];
        // a ridge of a billionth of the trace keeps a flat segment solvable
        let ridge = 1e-9 * sxx.trace().max(1e-12);
        let Some(inv) = (sxx + Matrix3::identity() * ridge).try_inverse() else {
            return f64::INFINITY;
        };
        [a, b]
            .into_iter()
            .enumerate()
            .map(|(k, g)| {
                let sxy = xy[hi][k] - xy[lo][k];
                (yy[hi][k] - yy[lo][k] - sxy.dot(&(inv * sxy))).max(0.0) / var[g]
            })
            .sum()
    };
    let min_span = min_span.max(4);
    (min_span..=n - min_span)
        .min_by(|&i, &j| (rss(0, i) + rss(i, n)).total_cmp(&(rss(0, j) + rss(j, n))))
}

/// Changes of gain: for every gauge and onset `τ`, the decrease of the residual sum of squares
/// (over the gauge's noise variance) when the gauge's slope on the fitted values changes at
/// `τ` ([`GainContrast`]: one slope before, another from `τ` to the end, against one slope for
/// every row); a finding when its best exceeds `penalty_per_change_ln_n · ln n + 2 ln(gauges)`,
/// the exchange scan's modified BIC with one choice among the gauges. It finds a gain change
/// too small to move the gauge's level or its noise (on a gauge whose strain swings about
/// zero), which the whole-record scan and the noise scan cannot see. Gauges in `skip` are not
/// scanned.
pub(crate) fn gain_scan(
    inp: &ScanInput<'_>,
    cfg: &SensorConfig,
    skip: &[usize],
) -> Vec<SensorFinding> {
    let (r, m) = (inp.residual, inp.fitted);
    let (n, k) = (r.nrows(), r.ncols());
    if n < 2 * cfg.min_span_rows {
        return vec![];
    }
    let var = noise_var(r, 0..r.nrows());
    let threshold = cfg.penalty_per_change_ln_n * (n as f64).ln() + 2.0 * (k as f64).ln();
    let mut out = vec![];
    for g in (0..k).filter(|g| !skip.contains(g)) {
        let all = GainContrast::sums(r, m, g, 0..n);
        let mut after = (0.0, 0.0);
        let mut best: Option<(f64, usize, GainContrast)> = None;
        for i in (cfg.min_span_rows.max(inp.earliest)..n).rev() {
            after.0 += m[(i, g)] * r[(i, g)];
            after.1 += m[(i, g)] * m[(i, g)];
            if n - i < cfg.min_span_rows {
                continue;
            }
            let Some(c) = GainContrast::of(all, after) else {
                continue;
            };
            let stat = c.explained / var[g];
            if best.as_ref().is_none_or(|b| stat > b.0) {
                best = Some((stat, i, c));
            }
        }
        let Some((stat, at, c)) = best.filter(|b| b.0 > threshold) else {
            continue;
        };
        out.push(inp.finding(
            SensorKind::Gain,
            vec![g],
            (at, n),
            (Some(c.size), Some((var[g] / c.information).sqrt()), "fraction"),
            "gain scan",
            format!(
                "a gain change of {} from day {:.2} lowers the residual sum of squares by {stat:.0} noise variances (threshold {threshold:.1})",
                inp.rec.gauge_names[g],
                inp.day(at)
            ),
        ));
    }
    out
}

/// A change of one gauge's slope on the fitted values at a row: the slope after it less the
/// slope before it, with one slope for every row as the null. The slope before the change is
/// estimated, not taken as zero, because a calibration whose window holds the change absorbs
/// part of it: its fitted values then carry a compromise gain, the residual shows a slope of
/// one sign before the change and of the other after it, and only their difference is the
/// gauge's change of gain (on panel seed 1000, a 10 % change from day 5 read as +1 % from the
/// slope after it alone).
#[derive(Clone, Copy, Debug)]
pub(crate) struct GainContrast {
    /// The slope after the change less the slope before it (fraction of the fitted values).
    pub size: f64,
    /// The decrease of the residual sum of squares over one slope for every row.
    pub explained: f64,
    /// The size's information per unit noise variance: its sd is `sqrt(var / information)`.
    pub information: f64,
}

impl GainContrast {
    /// `(Σ m·r, Σ m·m)` of gauge `g` over `rows`.
    fn sums(
        r: &DMatrix<f64>,
        m: &DMatrix<f64>,
        g: usize,
        rows: std::ops::Range<usize>,
    ) -> (f64, f64) {
        rows.fold((0.0, 0.0), |(a, b), i| {
            (a + m[(i, g)] * r[(i, g)], b + m[(i, g)] * m[(i, g)])
        })
    }

    /// From the sums over every row and over the rows after the change (`None` when the
    /// fitted values vanish on either side).
    fn of(all: (f64, f64), after: (f64, f64)) -> Option<Self> {
        let before = (all.0 - after.0, all.1 - after.1);
        // a side whose fitted values carry under a millionth of the record's leaves no slope
        let tiny = 1e-6 * all.1;
        if !(after.1 > tiny && before.1 > tiny) {
            return None;
        }
        let (ka, kb) = (after.0 / after.1, before.0 / before.1);
        Some(Self {
            size: ka - kb,
            explained: after.0 * ka + before.0 * kb - all.0 * all.0 / all.1,
            information: 1.0 / (1.0 / after.1 + 1.0 / before.1),
        })
    }

    /// The change of gauge `g`'s slope at row `from` of `n`.
    pub(crate) fn at(r: &DMatrix<f64>, m: &DMatrix<f64>, g: usize, from: usize) -> Option<Self> {
        let n = r.nrows();
        Self::of(Self::sums(r, m, g, 0..n), Self::sums(r, m, g, from..n))
    }
}

/// Whether exchanging `a` and `b` over rows `span` lowers the residual more than a free level
/// change of each gauge over them (two parameters).
fn beats_two_steps(
    r: &DMatrix<f64>,
    a: usize,
    b: usize,
    span: (usize, usize),
    exchange_gain: f64,
    var: &[f64],
) -> bool {
    let n = r.nrows();
    let s2 = var[a].max(var[b]);
    let level_gain = |g: usize| {
        let v: Vec<f64> = (span.0..span.1).map(|i| r[(i, g)]).collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        v.len() as f64 * mean * mean / s2
    };
    exchange_gain > level_gain(a) + level_gain(b) + 2.0 * (n as f64).ln()
}

/// Stuck gauges: a reading that repeats exactly for at least `min_span_rows` rows; the gauge is
/// set aside over the repeat.
pub(crate) fn stuck_scan(inp: &ScanInput<'_>, cfg: &SensorConfig) -> Vec<SensorFinding> {
    let y = &inp.rec.y;
    let (n, k) = (y.nrows(), y.ncols());
    let mut out = vec![];
    for g in 0..k {
        let mut start = 0;
        for i in 1..=n {
            let same = i < n && (y[(i, g)] - y[(i - 1, g)]).abs() <= 1e-9 * (1.0 + y[(i, g)].abs());
            if same {
                continue;
            }
            if i - start >= cfg.min_span_rows {
                out.push(inp.finding(
                    SensorKind::Stuck,
                    vec![g],
                    (start, i),
                    (Some(y[(start, g)]), None, inp.unit),
                    "stuck scan",
                    format!(
                        "{} reads {:.3} for {} rows in a row",
                        inp.rec.gauge_names[g],
                        y[(start, g)],
                        i - start
                    ),
                ));
            }
            start = i;
        }
    }
    out
}

/// Noise increases: on each gauge, changes of level of `ln(d²)` (`d` the residual's first
/// differences) by the event scan's method; an increase by at least `2 ln(noise_ratio)` (the
/// sd ratio) on one or two gauges sets the gauge aside until the level falls back. Three or
/// more gauges at once are not a sensor (the model's misfit grew). Gauges in `skip` (already
/// set aside or exchanged) are not scanned: their corrected residual is the model's own
/// prediction over the span, whose differences carry no noise to measure.
pub(crate) fn noise_scan(
    inp: &ScanInput<'_>,
    cfg: &SensorConfig,
    skip: &[usize],
) -> Result<Vec<SensorFinding>> {
    use numerics::changepoint::{MeanChangeParams, detect_mean_changes};
    let r = inp.residual;
    let (n, k) = (r.nrows(), r.ncols());
    if n < 4 * cfg.min_span_rows {
        return Ok(vec![]);
    }
    let params = MeanChangeParams {
        min_segment: cfg.min_span_rows,
        penalty_per_change_ln_n: cfg.penalty_per_change_ln_n,
        ..MeanChangeParams::default()
    };
    let jump = 2.0 * cfg.noise_ratio.ln();
    let mut out = vec![];
    for g in (0..k).filter(|g| !skip.contains(g)) {
        let z: Vec<f64> = (1..n)
            .map(|i| ((r[(i, g)] - r[(i - 1, g)]).powi(2) + 1e-12).ln())
            .collect();
        let found = detect_mean_changes(&z, &params).map_err(|e| CloseLoopError::Numerical {
            context: format!("noise scan of gauge {}", inp.rec.gauge_names[g]),
            reason: e.to_string(),
        })?;
        for (j, c) in found.changes.iter().enumerate() {
            if c.size < jump {
                continue;
            }
            let from = c.first_row_after + 1;
            let to = found
                .changes
                .get(j + 1)
                .map_or(n, |next| next.first_row_after + 1);
            if explained_by_gain(inp, g, (from, to), cfg)
                || moves_with_the_load(inp, g, (from, to), c.size, cfg)
            {
                // a change of gain, or the model's misfit growing as the load moves faster,
                // not of the gauge's noise (the gain scan after selection judges a gain)
                continue;
            }
            let ratio = (0.5 * c.size).exp();
            out.push(inp.finding(
                SensorKind::NoiseIncrease,
                vec![g],
                (from, to),
                (Some(ratio), Some(ratio * 0.5 * c.size_sd), "ratio"),
                "noise scan",
                format!(
                    "the noise of {} grows {ratio:.1}-fold on day {:.2}",
                    inp.rec.gauge_names[g],
                    inp.day(from)
                ),
            ));
        }
    }
    let gauges: std::collections::BTreeSet<usize> =
        out.iter().map(|f| f.gauge_columns[0]).collect();
    Ok(if gauges.len() >= 3 { vec![] } else { out })
}

/// Whether the residual's first differences grew on `from..to` because the gauge's fitted
/// strain moves faster there (a model misfit that scales with the load's motion) rather than
/// because the gauge's noise grew. Judged on the quiet rows: those whose fitted strain moves by
/// no more than its median step over the record. There a misfit that follows the load barely
/// shows, while a gauge's own noise shows in full. The growth is the load's when the robust sd
/// of the residual's differences on the span's quiet rows, over that on the quiet rows outside
/// the span, stays below `exp(size / 4)` (`size` the scan's change of `ln d²`): the geometric
/// midpoint between no growth and the growth `exp(size / 2)` the scan measured on every row.
/// Too few quiet rows on either side (under `min_span_rows / 2` in the span, `min_span_rows`
/// outside) cannot tell the two apart, and the finding stands.
///
/// Outside the span, not only before it, and quiet rows, not the fitted strain's overall
/// motion: the rule this replaces compared the span with the rows before it, scaled by how much
/// faster the fitted strain moved. A noise increase from day 5 leaves five quiet days before
/// it, and a five-fold increase was taken for load motion (tuning seeds 1-2 of the panel's
/// `noise` kind; docs/closeloop.md, "The panel").
fn moves_with_the_load(
    inp: &ScanInput<'_>,
    g: usize,
    (from, to): (usize, usize),
    size: f64,
    cfg: &SensorConfig,
) -> bool {
    use numerics::robust::{mad, median};
    let (r, m) = (inp.residual, inp.fitted);
    let n = r.nrows();
    let mut steps: Vec<f64> = (1..n).map(|i| (m[(i, g)] - m[(i - 1, g)]).abs()).collect();
    let quiet_step = median(&mut steps);
    let (mut inside, mut outside) = (vec![], vec![]);
    for i in 1..n {
        if (m[(i, g)] - m[(i - 1, g)]).abs() > quiet_step {
            continue;
        }
        let d = r[(i, g)] - r[(i - 1, g)];
        // a difference whose two rows are both in the span is the span's; one that straddles
        // its edge belongs to neither
        match (i > from && i < to, i < from || i > to) {
            (true, _) => inside.push(d),
            (_, true) => outside.push(d),
            _ => {}
        }
    }
    if inside.len() < cfg.min_span_rows / 2 || outside.len() < cfg.min_span_rows {
        return false;
    }
    let (s_in, s_out) = (mad(&mut inside), mad(&mut outside));
    s_out > 0.0 && s_in / s_out < (0.25 * size).exp()
}

/// A change of a gauge's gain from row `from` looks like a noise increase in the residual's
/// first differences (the residual is `k · fitted`, which moves with the load): it is a gain
/// change, not noise, when the span's slope on the fitted values passes the scans'
/// modified-BIC penalty (`z² > penalty_per_change_ln_n · ln n`) and removing it brings the
/// noise of the span back below `noise_ratio` times the gauge's noise on the rows outside the
/// span. Outside, not only before: a span that starts a few rows into the record (a gain
/// change the first calibration learnt shows on the rows before its day, panel seed 1003,
/// rows 13-113 of SG3) has too few rows before it to measure the noise by (0.21 microstrain
/// from 13 rows, for 1).
fn explained_by_gain(
    inp: &ScanInput<'_>,
    g: usize,
    (from, to): (usize, usize),
    cfg: &SensorConfig,
) -> bool {
    use numerics::robust::noise_sd_from_differences as sd_of;
    let (r, m) = (inp.residual, inp.fitted);
    let outside: Vec<f64> = (0..from).chain(to..r.nrows()).map(|i| r[(i, g)]).collect();
    if outside.len() < cfg.min_span_rows {
        return false;
    }
    let sd_ref = sd_of(&outside);
    let (mr, mm) = (from..to).fold((0.0, 0.0), |(a, b), i| {
        (a + m[(i, g)] * r[(i, g)], b + m[(i, g)] * m[(i, g)])
    });
    if !(mm > 0.0 && sd_ref > 0.0) {
        return false;
    }
    let k = mr / mm;
    let sd_after = sd_of(
        &(from..to)
            .map(|i| r[(i, g)] - k * m[(i, g)])
            .collect::<Vec<_>>(),
    );
    let z2 = k * k * mm / sd_after.max(sd_ref).powi(2);
    let n = r.nrows() as f64;
    z2 >= cfg.penalty_per_change_ln_n * n.ln() && sd_after < cfg.noise_ratio * sd_ref
}

/// The structure-or-sensor test of a change starting at `from` on the residual `r` (every
/// gauge, rows `from..n`): the best change of the parameter, `Δ · J` or `Δ · J · (t − t_from)`
/// with `J` the model's sensitivity to it at each row (one size for every gauge; a step or a
/// ramp), against the best sensor hypothesis on one gauge (a step, a drift from `from`, a gain
/// change `k · fitted`) or a pair (an exchange of readings), each scored by its residual sum of
/// squares over the noise variance. Each side fits one size (the exchange none) and pays `2 ln`
/// of the number of hypotheses it chose among. Sensor when its score plus the difference of
/// those penalties is below the structure's; structure when, otherwise, the parameter's change
/// removes at least [`CHANGE_EVIDENCE`]; `unsupported` when neither.
pub(crate) fn attribute(
    subject: &str,
    inp: &ScanInput<'_>,
    sensitivity: &DMatrix<f64>,
    from: usize,
) -> (AttributionTest, Option<SensorFinding>) {
    attribute_span(subject, inp, sensitivity, (from, inp.residual.nrows()))
}

/// [`attribute`] over the rows `span.0..span.1` (judged against the noise of the rows outside
/// them): a change that holds before a day rather than after it, as an exchange the
/// calibration learnt shows (see [`exchange_candidates`]).
pub(crate) fn attribute_span(
    subject: &str,
    inp: &ScanInput<'_>,
    sensitivity: &DMatrix<f64>,
    span: (usize, usize),
) -> (AttributionTest, Option<SensorFinding>) {
    let c = Change::new(inp, span);
    // structure: one Δ over every gauge, a step of the parameter from `from` or a ramp from it
    // (a gap that opens suddenly or grows)
    let structure = c
        .all_gauges(|i, g| sensitivity[(i, g)])
        .min(c.all_gauges(|i, g| sensitivity[(i, g)] * c.days(i)));
    let Best(sensor, hypothesis, best) = best_sensor(&c);
    // each side pays 2 ln of the number of hypotheses it chose among (the structure 2)
    let k = inp.residual.ncols();
    let m_hyp = (3 * k + k * (k - 1) / 2) as f64;
    let penalty = 2.0 * (m_hyp.ln() - 2f64.ln());
    let sensor_wins = sensor + penalty < structure;
    let verdict = match (sensor_wins, c.none - structure >= CHANGE_EVIDENCE) {
        (true, _) => "sensor",
        (false, true) => "structure",
        (false, false) => "unsupported",
    };
    let test = AttributionTest {
        subject: subject.into(),
        from_day: inp.day(span.0),
        none: c.none,
        structure,
        sensor,
        sensor_hypothesis: hypothesis.clone(),
        penalty,
        verdict: verdict.into(),
    };
    let finding = best
        .filter(|_| sensor_wins)
        // a change up to a day is dated by its span's end, which the scan set
        .map(|f| match span.1 == inp.residual.nrows() {
            true => step_or_earlier_drift(inp, refine_onset(inp, f)),
            false => f,
        })
        .filter(|f| f.from_row >= inp.earliest)
        .map(|mut f| {
            let redrawn = std::mem::take(&mut f.evidence);
            f.evidence = format!(
                "{subject} from day {:.2}: {hypothesis} explains the change better than a change of the parameter (residual sum of squares {sensor:.0} + penalty {penalty:.1} against {structure:.0} noise variances){redrawn}",
                test.from_day
            );
            f
        });
    (test, finding)
}

/// Scores over the rows from a change to the end of the record, on the scale of
/// [`attribute`]'s (residual sum of squares over each gauge's noise variance from the rows
/// before the change), for hypotheses the test does not hold ([`super::onset`]).
pub(crate) struct SpanScores {
    /// No change.
    pub none: f64,
    /// A level change on every gauge (its mean over the rows removed).
    pub steps_all: f64,
    var: Vec<f64>,
    from: usize,
    r: DMatrix<f64>,
}

impl SpanScores {
    pub(crate) fn new(inp: &ScanInput<'_>, from: usize) -> Self {
        let c = Change::new(inp, (from, inp.residual.nrows()));
        let r = inp.residual;
        let steps_all = (0..r.ncols())
            .filter_map(|g| c.one_gauge(g, |_| 1.0).map(|(s, _, _)| c.none - s))
            .fold(c.none, |acc, gain| acc - gain);
        Self {
            none: c.none,
            steps_all,
            var: c.var,
            from,
            r: r.clone(),
        }
    }

    /// The score with `removed` (every row; only rows from the change are read) taken off.
    pub(crate) fn with_removed(&self, removed: &DMatrix<f64>) -> f64 {
        (0..self.r.ncols())
            .map(|g| {
                (self.from..self.r.nrows())
                    .map(|i| (self.r[(i, g)] - removed[(i, g)]).powi(2))
                    .sum::<f64>()
                    / self.var[g]
            })
            .sum()
    }
}

/// One tested change: the residual over rows `from..to`, judged against the noise variances
/// of the rows outside them; `none` is its score with no change.
struct Change<'a, 'b> {
    inp: &'a ScanInput<'b>,
    var: Vec<f64>,
    from: usize,
    to: usize,
    none: f64,
}

impl<'a, 'b> Change<'a, 'b> {
    fn new(inp: &'a ScanInput<'b>, (from, to): (usize, usize)) -> Self {
        let r = inp.residual;
        let n = r.nrows();
        let quiet = match from {
            0 if 4 * (n - to) >= n => to..n,
            0 => 0..n,
            _ => quiet_rows(from, n),
        };
        let var = noise_var(r, quiet);
        let none = (0..r.ncols())
            .map(|g| (from..to).map(|i| r[(i, g)].powi(2)).sum::<f64>() / var[g])
            .sum();
        Self {
            inp,
            var,
            from,
            to,
            none,
        }
    }

    fn rows(&self) -> std::ops::Range<usize> {
        self.from..self.to
    }

    /// Days from the change's start to row `i`.
    fn days(&self, i: usize) -> f64 {
        (self.inp.rec.time_h[i] - self.inp.rec.time_h[self.from]) / 24.0
    }

    /// The score with one size times `x(i, g)` removed from every gauge at once.
    fn all_gauges(&self, x: impl Fn(usize, usize) -> f64) -> f64 {
        let r = self.inp.residual;
        let (mut xr, mut xx) = (0.0, 0.0);
        for g in 0..r.ncols() {
            for i in self.rows() {
                let v = x(i, g);
                xr += v * r[(i, g)] / self.var[g];
                xx += v * v / self.var[g];
            }
        }
        self.none - if xx > 0.0 { xr * xr / xx } else { 0.0 }
    }

    /// On gauge `g` alone, one size times `x(i)` removed: the score, the size and its sd
    /// (`None` when `x` vanishes on the rows).
    fn one_gauge(&self, g: usize, x: impl Fn(usize) -> f64) -> Option<(f64, f64, f64)> {
        let r = self.inp.residual;
        let (xr, xx) = self.rows().fold((0.0, 0.0), |(a, b), i| {
            let v = x(i);
            (a + v * r[(i, g)], b + v * v)
        });
        (xx > 0.0).then(|| {
            (
                self.none - xr * xr / xx / self.var[g],
                xr / xx,
                (self.var[g] / xx).sqrt(),
            )
        })
    }

    /// The score with the readings of gauges `a` and `b` exchanged back.
    fn exchange(&self, a: usize, b: usize) -> f64 {
        let (r, m, var) = (self.inp.residual, self.inp.fitted, &self.var);
        let mut score = self.none;
        for i in self.rows() {
            let (ya, yb) = (r[(i, a)] + m[(i, a)], r[(i, b)] + m[(i, b)]);
            score -= r[(i, a)].powi(2) / var[a] + r[(i, b)].powi(2) / var[b];
            score += (yb - m[(i, a)]).powi(2) / var[a] + (ya - m[(i, b)]).powi(2) / var[b];
        }
        score
    }
}

/// The best sensor hypothesis so far: its score, its name and its finding.
struct Best(f64, String, Option<SensorFinding>);

impl Best {
    fn offer(&mut self, score: f64, name: String, finding: impl FnOnce() -> SensorFinding) {
        if score < self.0 {
            *self = Best(score, name, Some(finding()));
        }
    }
}

/// The best sensor hypothesis for a change: a drift, a step or a gain change on one gauge, or
/// an exchange of one pair's readings.
fn best_sensor(c: &Change<'_, '_>) -> Best {
    let (inp, m) = (c.inp, c.inp.fitted);
    let k = m.ncols();
    let src = "structure-or-sensor test";
    let per_day = format!("{} per day", inp.unit);
    let mut best = Best(f64::INFINITY, String::new(), None);
    for g in 0..k {
        let name = &inp.rec.gauge_names[g];
        let hypotheses = [
            (
                SensorKind::Drift,
                "drift",
                per_day.as_str(),
                c.one_gauge(g, |i| c.days(i)),
            ),
            (SensorKind::Step, "step", inp.unit, c.one_gauge(g, |_| 1.0)),
            (
                SensorKind::Gain,
                "gain change",
                "fraction",
                c.one_gauge(g, |i| m[(i, g)]),
            ),
        ];
        for (kind, what, unit, fit) in hypotheses {
            let Some((score, size, sd)) = fit else {
                continue;
            };
            best.offer(score, format!("{name} {what}"), || {
                let span = (c.from, c.to);
                inp.finding(
                    kind,
                    vec![g],
                    span,
                    (Some(size), Some(sd), unit),
                    src,
                    String::new(),
                )
            });
        }
    }
    for a in 0..k {
        for b in a + 1..k {
            let names = &inp.rec.gauge_names;
            best.offer(
                c.exchange(a, b),
                format!("{}<->{} exchange", names[a], names[b]),
                || {
                    let none = (None, None, "");
                    inp.finding(
                        SensorKind::ChannelExchange,
                        vec![a, b],
                        (c.from, c.to),
                        none,
                        src,
                        String::new(),
                    )
                },
            );
        }
    }
    best
}

/// Least decrease of the residual sum of squares (in noise variances) a change of the
/// parameter must bring to be called structure: the 99 % quantile of χ² with one degree of
/// freedom (one size fitted). A change below it is `unsupported`: the residual does not show
/// the change the alarm dates.
const CHANGE_EVIDENCE: f64 = 6.635;

/// Days either side of a tested change's start over which a one-gauge finding's own onset is
/// looked for: the scan dates a change by its first clear level shift, which for a slow drift
/// or a small gain comes days after the fault began.
pub(crate) const ONSET_SEARCH_DAYS: f64 = 3.0;

/// A one-gauge finding (step, drift, gain change) re-dated and re-sized at the onset within
/// [`ONSET_SEARCH_DAYS`] of its start whose single regressor removes the most of the gauge's
/// residual sum of squares (the start the test used is one of the candidates); a gain change
/// as the change of the gauge's slope on the fitted values ([`GainContrast`]).
fn refine_onset(inp: &ScanInput<'_>, f: SensorFinding) -> SensorFinding {
    let (r, m) = (inp.residual, inp.fitted);
    let t = &inp.rec.time_h;
    let (n, g) = (r.nrows(), f.gauge_columns[0]);
    let regressor = |i: usize, from: usize| match f.kind {
        SensorKind::Step => Some(1.0),
        SensorKind::Drift => Some((t[i] - t[from]) / 24.0),
        _ => None,
    };
    let near =
        |i: usize| i >= inp.earliest && (t[i] - t[f.from_row]).abs() <= ONSET_SEARCH_DAYS * 24.0;
    if f.kind == SensorKind::Gain {
        // a change of slope, sized against the slope before it ([`GainContrast`])
        let best = (0..n.saturating_sub(2))
            .filter(|&i| near(i))
            .filter_map(|i| GainContrast::at(r, m, g, i).map(|c| (i, c)))
            .max_by(|a, b| a.1.explained.total_cmp(&b.1.explained));
        let Some((from, c)) = best else {
            return f;
        };
        let var = noise_var(r, quiet_rows(f.from_row, n))[g];
        return SensorFinding {
            from_row: from,
            from_day: inp.day(from),
            size: Some(c.size),
            size_sd: Some((var / c.information).sqrt()),
            ..f
        };
    }
    if regressor(f.from_row, f.from_row).is_none() {
        return f;
    }
    let fit = |from: usize| {
        let (xr, xx) = (from..n).fold((0.0, 0.0), |(a, b), i| {
            let x = regressor(i, from).unwrap_or(0.0);
            (a + x * r[(i, g)], b + x * x)
        });
        (if xx > 0.0 { xr * xr / xx } else { 0.0 }, xr, xx)
    };
    let best = (0..n.saturating_sub(2))
        .filter(|&i| near(i))
        .map(|i| (i, fit(i)))
        .max_by(|a, b| a.1.0.total_cmp(&b.1.0));
    let Some((from, (_, xr, xx))) = best.filter(|b| b.1.2 > 0.0) else {
        return f;
    };
    let var = noise_var(r, quiet_rows(f.from_row, n))[g];
    SensorFinding {
        from_row: from,
        from_day: inp.day(from),
        size: Some(xr / xx),
        size_sd: Some((var / xx).sqrt()),
        ..f
    }
}

/// A step found on one gauge, or a drift that began before it: a slow drift is first seen as
/// a level shift days after it began, and from there a step fits the drift's mean over the
/// remaining rows but not its slope (the step's correction then leaves a ramp in the test
/// window). The step (onset within [`ONSET_SEARCH_DAYS`] of its own, as refined) against the
/// best drift `size · (t − t₀)` with onset `t₀` anywhere from the first row a finding may
/// start at to [`ONSET_SEARCH_DAYS`] after the step's, both scored by the residual sum of
/// squares they leave on the gauge's rows from the earliest of those onsets, over the noise
/// variance of the rows before the step. Each fits one size and one onset; the drift chose
/// among more onsets and pays `2 ln` of the ratio of the two counts. A drift that wins is
/// returned dated and sized at its own onset; otherwise the step as it was.
fn step_or_earlier_drift(inp: &ScanInput<'_>, f: SensorFinding) -> SensorFinding {
    if f.kind != SensorKind::Step || f.gauge_columns.len() != 1 {
        return f;
    }
    let (r, t) = (inp.residual, &inp.rec.time_h);
    let (n, g, s) = (r.nrows(), f.gauge_columns[0], f.from_row);
    let window = ONSET_SEARCH_DAYS * 24.0;
    let within = |i: usize| (t[i] - t[s]).abs() <= window;
    let step_onsets = (0..n).filter(|&i| i >= inp.earliest && within(i)).count();
    let last = (s..n)
        .take_while(|&i| t[i] - t[s] <= window)
        .last()
        .unwrap_or(s);
    let lo = inp.earliest.min(s);
    if last + 2 >= n || step_onsets == 0 {
        return f;
    }
    // suffix sums over rows i..n of r, t·r, t, t² and the count
    let mut suf = vec![[0.0f64; 5]; n + 1];
    for i in (0..n).rev() {
        let (x, y) = (t[i] / 24.0, r[(i, g)]);
        let a = suf[i + 1];
        suf[i] = [a[0] + y, a[1] + x * y, a[2] + x, a[3] + x * x, a[4] + 1.0];
    }
    let step_explained = {
        let [sr, .., cnt] = suf[s];
        sr * sr / cnt
    };
    // drift from row j: x = t − t_j on rows j..n
    let drift = |j: usize| {
        let [sr, str_, st, stt, cnt] = suf[j];
        let tj = t[j] / 24.0;
        let xr = str_ - tj * sr;
        let xx = stt - 2.0 * tj * st + tj * tj * cnt;
        (xx > 0.0).then(|| (xr * xr / xx, xr, xx))
    };
    let best = (lo..=last)
        .filter_map(|j| drift(j).map(|d| (j, d)))
        .max_by(|a, b| a.1.0.total_cmp(&b.1.0));
    let Some((from, (explained, xr, xx))) = best else {
        return f;
    };
    let var = noise_var(r, quiet_rows(s, n))[g];
    let drift_onsets = last + 1 - lo;
    let penalty = 2.0 * (drift_onsets as f64 / step_onsets as f64).max(1.0).ln();
    if (explained - step_explained) / var <= penalty {
        return f;
    }
    let evidence = format!(
        "; as a drift from day {:.2} rather than a step from day {:.2}: it leaves {:.1} noise variances less on the gauge (penalty {penalty:.1} for choosing among {drift_onsets} onsets against {step_onsets})",
        inp.day(from),
        f.from_day,
        (explained - step_explained) / var
    );
    SensorFinding {
        kind: SensorKind::Drift,
        from_row: from,
        evidence,
        from_day: inp.day(from),
        size: Some(xr / xx),
        size_sd: Some((var / xx).sqrt()),
        unit: format!("{} per day", inp.unit),
        ..f
    }
}

/// The model's sensitivity to its parameter at every row: half the difference of its means at
/// `θ ± h` over `h` (output units per unit of `θ`).
pub(crate) fn sensitivity(
    model: &dyn super::CalibratedModel,
    x: &DMatrix<f64>,
) -> Result<DMatrix<f64>> {
    let t = model.theta_summary();
    let (lo, hi) = model.theta_bounds();
    let h = (0.005 * (hi - lo)).max(1e-6);
    let (a, b) = ((t.mean - h).max(lo), (t.mean + h).min(hi));
    let at = model.predict_at_thetas(x, &[a, b])?;
    Ok((&at[1] - &at[0]) / (b - a).max(1e-12))
}

/// RMSE per gauge over `rows`, the set-aside cells left out (`NaN` for a gauge with none left).
pub(crate) fn rmse_unmasked(r: &DMatrix<f64>, rows: &[usize], mask: &DMatrix<bool>) -> Vec<f64> {
    (0..r.ncols())
        .map(|g| {
            let (s, c) = rows
                .iter()
                .filter(|&&i| !mask[(i, g)])
                .fold((0.0, 0usize), |(s, c), &i| (s + r[(i, g)].powi(2), c + 1));
            if c == 0 {
                f64::NAN
            } else {
                (s / c as f64).sqrt()
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What a scan reads: `rec`, the residual `r` and the fitted values `m` (microstrain).
    fn input<'a>(
        rec: &'a MeasuredRecord,
        r: &'a DMatrix<f64>,
        m: &'a DMatrix<f64>,
    ) -> ScanInput<'a> {
        ScanInput {
            rec,
            residual: r,
            fitted: m,
            unit: "microstrain",
            earliest: 0,
        }
    }

    fn record(y: DMatrix<f64>) -> MeasuredRecord {
        let n = y.nrows();
        MeasuredRecord {
            file: "t.csv".into(),
            start_unix_s: 0.0,
            time_h: (0..n).map(|i| i as f64).collect(),
            input_names: vec![],
            x: DMatrix::zeros(n, 0),
            gauge_names: (0..y.ncols()).map(|g| format!("SG{}", g + 1)).collect(),
            y,
            covariate_names: vec![],
            covariates: DMatrix::zeros(n, 0),
            source_lines: (0..n as u64).collect(),
            dropped_missing: 0,
            imputed: 0,
        }
    }

    /// White noise of sd 1, a pure function of the cell (a hash turned into a normal draw by
    /// Box-Muller), so that the tests need no random state. A deterministic sinusoid would not
    /// do: the scans read its regular swings as autocorrelation.
    fn wiggle(i: usize, g: usize) -> f64 {
        let u = |salt: u64| {
            let mut z = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ (g as u64 + 1).wrapping_mul(0xBF58_476D_1CE4_E5B9)
                ^ salt;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        (-2.0 * u(1).ln()).sqrt() * (2.0 * std::f64::consts::PI * u(2)).cos()
    }

    /// A 10 % gain from row 250 on one gauge: [`gain_onset`] dates it among the candidate rows
    /// and sizes it. Tolerances: the onset within 3 rows (with a swing of period 57 rows and
    /// unit noise, a few rows either side change the contrast by less than its noise); the
    /// size within 4 of its own sds, which a wrong sd would fail; and a window of candidates
    /// that ends before the change returns its last row, not a row outside it.
    #[test]
    fn gain_onset_dates_and_sizes_a_change_of_slope_among_its_rows() {
        let n = 400;
        let m = DMatrix::from_fn(n, 3, |i, g| {
            (g as f64 + 1.0) * 10.0 * ((i as f64) / 9.0).sin()
        });
        let r = DMatrix::from_fn(n, 3, |i, g| {
            wiggle(i, g)
                + if g == 2 && i >= 250 {
                    0.1 * m[(i, g)]
                } else {
                    0.0
                }
        });
        let (at, k, sd) = gain_onset(&r, &m, 2, 200..320).expect("fitted values do not vanish");
        assert!(at.abs_diff(250) <= 3, "{at}");
        assert!((k - 0.1).abs() <= 4.0 * sd, "{k} ± {sd}");
        assert!(sd > 0.0 && sd < 0.01, "{sd}");
        let (at, _, _) = gain_onset(&r, &m, 2, 200..240).expect("fitted values do not vanish");
        assert!((200..240).contains(&at), "{at}");
    }

    #[test]
    fn an_exchange_is_found_from_its_day_and_undone() {
        let n = 400;
        let truth = |i: usize, g: usize| (g as f64 + 1.0) * 10.0 * ((i as f64) / 9.0).sin();
        let swap_at = 300;
        let y = DMatrix::from_fn(n, 4, |i, g| {
            let g2 = match (i >= swap_at, g) {
                (true, 1) => 3,
                (true, 3) => 1,
                _ => g,
            };
            truth(i, g2) + wiggle(i, g)
        });
        let fitted = DMatrix::from_fn(n, 4, truth);
        let r = &y - &fitted;
        let rec = record(y.clone());
        let inp = input(&rec, &r, &fitted);
        let f = exchange_scan(&inp, &SensorConfig::default());
        assert_eq!(f.len(), 1, "{f:?}");
        assert_eq!(f[0].gauges, vec!["SG2", "SG4"]);
        assert!(
            (f[0].from_row as i64 - swap_at as i64).abs() <= 2,
            "{}",
            f[0].from_row
        );
        let (fixed, _) = apply(&f, &y, &fitted, &rec.time_h, None);
        let left = (&fixed - &fitted).abs().max();
        assert!(left < 10.0, "{left}");
        // a clean record: nothing
        let clean = DMatrix::from_fn(n, 4, |i, g| truth(i, g) + wiggle(i, g));
        let rc = &clean - &fitted;
        let rec = record(clean);
        let inp = ScanInput {
            residual: &rc,
            rec: &rec,
            ..inp
        };
        assert!(exchange_scan(&inp, &SensorConfig::default()).is_empty());
    }

    /// An exchange from early in the record that the calibration learnt: the fitted values
    /// are the exchanged strains everywhere, so the residual shows the exchange only before
    /// its day. The scan finds it there, over rows `0..τ`, and nothing on a record whose fit
    /// and readings agree.
    #[test]
    fn an_exchange_the_fit_learnt_is_found_before_its_day() {
        let n = 400;
        let truth = |i: usize, g: usize| (g as f64 + 1.0) * 10.0 * ((i as f64) / 9.0).sin();
        let swap = |g: usize| match g {
            0 => 2,
            2 => 0,
            g => g,
        };
        let swap_at = 40;
        let y = DMatrix::from_fn(n, 4, |i, g| {
            let g2 = if i >= swap_at { swap(g) } else { g };
            truth(i, g2) + wiggle(i, g)
        });
        let fitted = DMatrix::from_fn(n, 4, |i, g| truth(i, swap(g)));
        let r = &y - &fitted;
        let rec = record(y.clone());
        let inp = input(&rec, &r, &fitted);
        let f = exchange_candidates(&inp, &SensorConfig::default(), Side::Before);
        assert_eq!(f[0].gauges, vec!["SG1", "SG3"], "{f:?}");
        assert!(exchange_scan(&inp, &SensorConfig::default()).is_empty());
        assert_eq!(f[0].from_row, 0);
        assert!(
            (f[0].to_row as i64 - swap_at as i64).abs() <= 2,
            "{}",
            f[0].to_row
        );
        // relabelled up to its day, the readings agree with the fit (within the noise)
        let (fixed, _) = apply(&f[..1], &y, &fitted, &rec.time_h, None);
        let left = (&fixed - &fitted).abs().max();
        assert!(left < 10.0, "{left}");
        // the structure-or-sensor test over that span calls it the exchange
        let sens = DMatrix::from_fn(n, 4, |i, g| 0.1 * (g as f64 + 1.0) + 0.01 * (i % 7) as f64);
        let (test, found) = attribute_span("SG1<->SG3", &inp, &sens, (f[0].from_row, f[0].to_row));
        assert_eq!(test.verdict, "sensor", "{test:?}");
        assert_eq!(found.map(|x| x.gauge_columns), Some(vec![0, 2]));
        // dated without trusting the fit's map of the pair: also on a fit that learnt a
        // mixture of the two strains (60 % exchanged), which the running sums misdate
        let onset = |fit: &DMatrix<f64>| exchange_onset(&y, fit, (0, 2), 12).unwrap();
        assert!(onset(&fitted).abs_diff(swap_at) <= 2, "{}", onset(&fitted));
        let mixed = DMatrix::from_fn(n, 4, |i, g| 0.6 * truth(i, swap(g)) + 0.4 * truth(i, g));
        assert!(onset(&mixed).abs_diff(swap_at) <= 2, "{}", onset(&mixed));
        // fit and readings that agree: nothing either side
        let agree = DMatrix::from_fn(n, 4, |i, g| truth(i, swap(g)) + wiggle(i, g));
        let ra = &agree - &fitted;
        let rec = record(agree);
        let inp = ScanInput {
            residual: &ra,
            rec: &rec,
            ..inp
        };
        assert!(exchange_candidates(&inp, &SensorConfig::default(), Side::Before).is_empty());
    }

    /// A fit whose window held a gain change absorbs part of it: its fitted values carry a
    /// compromise gain `c`, so the residual has slope `-c` before the change and `k - c` after
    /// it. The scan and the re-sizing read the change of slope, `k`, not the slope after it
    /// (`k - c`, what they read before). The strain swings about zero (a gauge whose level
    /// the change does not move), and the sizes are checked against their own sds.
    #[test]
    fn a_gain_change_the_fit_absorbed_in_part_is_sized_by_its_change_of_slope() {
        let n = 1200;
        let (at, k, c) = (100, 0.10, 0.07);
        let strain = |i: usize| 40.0 * ((i as f64) / 7.0).sin();
        let y = DMatrix::from_fn(n, 3, |i, g| {
            let gain = if g == 1 && i >= at { 1.0 + k } else { 1.0 };
            gain * strain(i) + wiggle(i, g)
        });
        // gauge 3's fitted values are 5 % low on every row: no change of gain there
        let fitted = DMatrix::from_fn(n, 3, |i, g| {
            strain(i)
                * match g {
                    1 => 1.0 + c,
                    2 => 0.95,
                    _ => 1.0,
                }
        });
        let r = &y - &fitted;
        let rec = record(y);
        let inp = input(&rec, &r, &fitted);
        let found = gain_scan(&inp, &SensorConfig::default(), &[]);
        // one finding: gauge 3's whole-record slope is not a change (the slope after a row
        // alone would read it as one at the first row the scan tries)
        assert_eq!(found.len(), 1, "{found:?}");
        let f = &found[0];
        assert_eq!(f.gauge_columns, vec![1]);
        assert!((f.from_row as i64 - at as i64).abs() <= 2, "{}", f.from_row);
        // relative to the fitted values, the change is k / (1 + c); within 3 sds of it (the sd
        // from the noise alone: about 0.004 here)
        let (size, sd) = (f.size.unwrap(), f.size_sd.unwrap());
        let want = k / (1.0 + c);
        assert!((size - want).abs() < 3.0 * sd, "{size} ± {sd}, want {want}");
        assert!(sd < 0.01, "{sd}");
        let (step, sd) = gain_remainder(&r, &fitted, f).unwrap();
        assert!((step - want).abs() < 3.0 * sd, "{step} ± {sd}");
    }

    #[test]
    fn the_verdicts_gain_and_offset_become_corrections_and_its_step_and_drift_do_not() {
        use bamudi::adequacy::{SensorCorrection, SensorFault};
        let n = 50;
        let rec = record(DMatrix::from_element(n, 3, 10.0));
        let fault = |gauge: &str, kind, estimate| SensorFault {
            gauge: gauge.into(),
            kind,
            estimate,
            sd: 0.01,
            z: estimate / 0.01,
            at_fraction: (kind == FaultKind::Step).then_some(0.5),
            p_value: 1e-6,
        };
        let mut verdict = AdequacyReport::not_assessed("a test", 0.01);
        verdict.sensor_correction = Some(SensorCorrection {
            faults: vec![
                fault("SG1", FaultKind::Gain, 0.05),
                fault("SG2", FaultKind::Offset, 2.0),
                fault("SG3", FaultKind::Step, 4.0),
                fault("SG3", FaultKind::Drift, 1.0),
            ],
            shift: DMatrix::zeros(0, 0),
        });
        let zeros = DMatrix::zeros(n, 3);
        let inp = ScanInput {
            rec: &rec,
            residual: &zeros,
            fitted: &rec.y,
            unit: "microstrain",
            earliest: 0,
        };
        let f = from_verdict(&inp, &verdict);
        let got: Vec<(SensorKind, usize, usize)> = f
            .iter()
            .map(|f| (f.kind, f.gauge_columns[0], f.from_row))
            .collect();
        assert_eq!(
            got,
            vec![(SensorKind::Gain, 0, 0), (SensorKind::Offset, 1, 0)]
        );
        // applied over the whole record: 10.5 read with a +5 % gain is 10.5 / 1.05 = 10
        let mut y = rec.y.clone();
        y.column_mut(0).fill(10.5);
        y.column_mut(1).fill(12.0);
        let (fixed, mask) = apply(&f, &y, &zeros, &rec.time_h, None);
        assert!((&fixed - &rec.y).abs().max() < 1e-12, "{fixed}");
        assert!(!mask.iter().any(|m| *m));
    }

    /// A gain change the fit learnt (fitted on readings with the change in them) shows on the
    /// rows before its day as `-k · strain`, whose first differences swing with the load like
    /// noise: the noise scan must leave it (for the gain scan), judging the span against the
    /// gauge's noise on the rows outside it. As on panel seed 1003 (SG3, +10 % from day 5), the
    /// fit's in-sample residual on the record's first rows is shrunk (a discrepancy GP follows
    /// rows whose inputs no other row is near: 0.21 there for a noise of 1), so the scan sees
    /// the span start a few rows in; judged against those rows alone, it set the gauge aside as
    /// a noise increase (checked: this test fails with that rule). A true noise increase
    /// (3-fold, from the same row on) is still found.
    #[test]
    fn a_gain_change_the_fit_learnt_is_not_a_noise_increase_before_its_day() {
        let (n, at, k) = (600, 120, 0.10);
        let strain = |i: usize| 300.0 * ((i as f64) / 2.0).sin();
        let fitted = DMatrix::from_fn(n, 3, |i, g| {
            (if g == 1 { 1.0 + k } else { 1.0 }) * strain(i)
        });
        let cfg = SensorConfig::default();
        let scan = |y: DMatrix<f64>| {
            let r = &y - &fitted;
            let rec = record(y);
            let inp = input(&rec, &r, &fitted);
            noise_scan(&inp, &cfg, &[]).unwrap()
        };
        let quiet = 15;
        let learnt = DMatrix::from_fn(n, 3, |i, g| {
            let gain = if g == 1 && i >= at { 1.0 + k } else { 1.0 };
            match g == 1 && i < quiet {
                true => fitted[(i, g)] + 0.2 * wiggle(i, g),
                false => gain * strain(i) + wiggle(i, g),
            }
        });
        let found = scan(learnt);
        assert!(found.is_empty(), "{found:?}");
        // noise 3x on gauge 2 from row `at`, the fit right: a noise increase
        let noisy = DMatrix::from_fn(n, 3, |i, g| {
            let sd = if g == 1 && i >= at { 3.0 } else { 1.0 };
            fitted[(i, g)] + sd * wiggle(i, g)
        });
        let found = scan(noisy);
        assert_eq!(found.len(), 1, "{found:?}");
        assert_eq!(found[0].gauge_columns, vec![1]);
        assert!(found[0].from_row.abs_diff(at) <= 3, "{:?}", found[0]);
    }

    /// A lock's load holds between fillings and emptyings: the fitted strain of every gauge
    /// holds for 6 rows, ramps between `±a` in 6, and its swing `a` is 5 microstrain for the
    /// record's first 60 rows and 300 after. Two records on that load, noise sd 1:
    /// - gauge 2's noise grows 3-fold from row 60 (the fit right): a noise increase, found,
    ///   though the fitted strain moves 60 times faster in the span than before it (the rule
    ///   this test came with compared the span with the rows before it, scaled by that motion,
    ///   and let such an increase pass as load motion: panel tuning seed 2, a five-fold increase
    ///   from day 5);
    /// - gauge 2's residual carries a misfit `0.03 |fitted|` that grows with the swing (not a
    ///   gain: `|fitted|` has no slope on `fitted` over whole cycles): its differences grow
    ///   on the ramps only, the hold rows show no growth, and it is load motion, not noise.
    ///
    /// The load test is also called directly with the growth it would be handed (2 ln 3 and
    /// 2 ln 2), so that the second record's empty scan is the test's answer and not a change
    /// the scan did not see.
    #[test]
    fn a_noise_increase_shows_on_the_quiet_rows_and_a_misfit_of_the_load_does_not() {
        let (n, at) = (600, 60);
        let load = |i: usize| {
            let a = if i < at { 5.0 } else { 300.0 };
            let p = (i % 24) as f64;
            a * match i % 24 {
                0..6 => 1.0,
                6..12 => 1.0 - 2.0 * (p - 5.0) / 6.0,
                12..18 => -1.0,
                _ => -1.0 + 2.0 * (p - 17.0) / 6.0,
            }
        };
        let fitted = DMatrix::from_fn(n, 3, |i, g| (1.0 + 0.2 * g as f64) * load(i));
        let cfg = SensorConfig::default();
        let run = |r: DMatrix<f64>, size: f64| {
            let rec = record(&fitted + &r);
            let inp = input(&rec, &r, &fitted);
            (
                noise_scan(&inp, &cfg, &[]).unwrap(),
                moves_with_the_load(&inp, 1, (at, n), size, &cfg),
            )
        };
        let noisy = DMatrix::from_fn(n, 3, |i, g| {
            let sd = if g == 1 && i >= at { 3.0 } else { 1.0 };
            sd * wiggle(i, g)
        });
        let (found, load_says) = run(noisy, 2.0 * 3f64.ln());
        assert!(!load_says);
        assert_eq!(found.len(), 1, "{found:?}");
        assert_eq!(found[0].kind, SensorKind::NoiseIncrease);
        assert_eq!(found[0].gauge_columns, vec![1]);
        assert!(found[0].from_row.abs_diff(at) <= 3, "{:?}", found[0]);
        let misfit = DMatrix::from_fn(n, 3, |i, g| {
            wiggle(i, g)
                + if g == 1 {
                    0.03 * fitted[(i, g)].abs()
                } else {
                    0.0
                }
        });
        let (found, load_says) = run(misfit, 2.0 * 2f64.ln());
        assert!(load_says);
        assert!(found.is_empty(), "{found:?}");
    }

    /// The Jacobian of the corrections on the calibration rows: a gain correction by `1 + k`
    /// adds `-ln(1 + k)` per corrected cell among the rows (its scale kept from falling below
    /// `1 - MAX_GAIN_LOSS`), a set-aside gain or an exchange nothing.
    #[test]
    fn a_gain_corrections_log_jacobian_counts_its_cells_on_the_rows() {
        let rec = record(DMatrix::zeros(40, 3));
        let inp = ScanInput {
            rec: &rec,
            residual: &rec.y,
            fitted: &rec.y,
            unit: "microstrain",
            earliest: 0,
        };
        let gain = |k: f64, span| {
            inp.finding(
                SensorKind::Gain,
                vec![1],
                span,
                (Some(k), Some(0.01), "fraction"),
                "t",
                String::new(),
            )
        };
        let rows: Vec<usize> = (0..20).collect();
        let j = log_jacobian(&[gain(0.25, (10, 30))], &rows);
        assert!((j + 10.0 * 1.25f64.ln()).abs() < 1e-12, "{j}");
        // clamped, as `apply` clamps a drawn size: a loss of 90 % divides by 1 - MAX_GAIN_LOSS
        // at most (a finding that large is set aside; the draw can reach it)
        let mut big = gain(-0.9, (0, 40));
        big.action = SensorAction::Corrected;
        let j = log_jacobian(&[big], &rows);
        assert!((j + 20.0 * (1.0 - MAX_GAIN_LOSS).ln()).abs() < 1e-12, "{j}");
        let mut aside = gain(0.25, (0, 40));
        aside.action = SensorAction::SetAside;
        let exchange = inp.finding(
            SensorKind::ChannelExchange,
            vec![0, 1],
            (0, 40),
            (None, None, ""),
            "t",
            String::new(),
        );
        assert_eq!(log_jacobian(&[aside, exchange], &rows), 0.0);
        // what the Jacobian is for: a density of the corrected readings plus it is the density
        // of the readings as recorded (here N(0, s²) per corrected cell, s = 1.25, read as
        // N(0, 1) after the correction divides by s)
        let f = gain(0.25, (0, 40));
        let y = DMatrix::from_fn(40, 3, |i, g| wiggle(i, g) * if g == 1 { 1.25 } else { 1.0 });
        let (yc, _) = apply(std::slice::from_ref(&f), &y, &y, &rec.time_h, None);
        let ln_n = |v: f64, sd: f64| {
            -0.5 * (v / sd).powi(2) - sd.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln()
        };
        let corrected: f64 = rows.iter().map(|&i| ln_n(yc[(i, 1)], 1.0)).sum();
        let recorded: f64 = rows.iter().map(|&i| ln_n(y[(i, 1)], 1.25)).sum();
        let j = log_jacobian(&[f], &rows);
        assert!(
            (corrected + j - recorded).abs() < 1e-9,
            "{corrected} + {j} vs {recorded}"
        );
    }

    #[test]
    fn a_stuck_gauge_is_set_aside_and_noise_is_not_stuck() {
        let n = 200;
        let mut y = DMatrix::from_fn(n, 3, wiggle);
        for i in 150..n {
            y[(i, 2)] = 0.0; // a dead channel reads zero
        }
        let fitted = DMatrix::zeros(n, 3);
        let rec = record(y.clone());
        let inp = input(&rec, &y, &fitted);
        let f = stuck_scan(&inp, &SensorConfig::default());
        assert_eq!(f.len(), 1);
        assert_eq!(
            (f[0].gauges[0].as_str(), f[0].from_row, f[0].to_row),
            ("SG3", 150, n)
        );
        let (_, mask) = apply(&f, &y, &fitted, &rec.time_h, None);
        assert_eq!(mask.iter().filter(|m| **m).count(), 50);
    }

    /// A drift of 0.1 microstrain per day from day 30 on one gauge of a 60-day hourly record,
    /// tested from day 44 (where a level-shift scan first sees so slow a drift): a drift, dated
    /// within 3 days of day 30 and sized within 4 of its sds, not a step from day 44 (which
    /// fits the ramp's mean and leaves its slope). A step of 1 microstrain from day 44 on the
    /// same noise stays a step from day 44 (within a day): the drift's extra onsets do not buy
    /// it a step. Tolerances: with unit noise the drift's onset is resolved to about a day and
    /// its rate to 0.002 per day (its sd), so both bounds hold with room and a step verdict
    /// would fail the first.
    #[test]
    fn a_drift_seen_late_is_a_drift_from_its_own_onset_and_a_step_stays_a_step() {
        let n = 1440;
        let sens = DMatrix::from_fn(n, 4, |_, g| [0.8, -0.5, 0.3, 1.1][g]);
        let fitted = DMatrix::from_fn(n, 4, |i, g| {
            20.0 * (g as f64 + 1.0) * (1.0 + (i as f64 / 9.0).sin())
        });
        let rec = record(fitted.clone());
        let (onset, seen) = (720, 1056);
        let r = DMatrix::from_fn(n, 4, |i, g| {
            wiggle(i, g)
                + if g == 1 && i >= onset {
                    0.1 * (i - onset) as f64 / 24.0
                } else {
                    0.0
                }
        });
        let inp = input(&rec, &r, &fitted);
        let (t, f) = attribute("gap alarm", &inp, &sens, seen);
        assert_eq!(t.verdict, "sensor", "{t:?}");
        let f = f.expect("a finding");
        assert_eq!(
            (f.kind, f.gauges[0].as_str()),
            (SensorKind::Drift, "SG2"),
            "{f:?}"
        );
        assert!((f.from_day - 30.0).abs() <= 3.0, "{f:?}");
        let (size, sd) = (f.size.unwrap(), f.size_sd.unwrap());
        assert!((size - 0.1).abs() <= 4.0 * sd, "{f:?}");
        assert!(f.unit.ends_with("per day"), "{f:?}");
        let r = DMatrix::from_fn(n, 4, |i, g| {
            wiggle(i, g) + if g == 1 && i >= seen { 1.0 } else { 0.0 }
        });
        let inp = ScanInput {
            residual: &r,
            ..inp
        };
        let (_, f) = attribute("gap alarm", &inp, &sens, seen);
        let f = f.expect("a finding");
        assert_eq!(f.kind, SensorKind::Step, "{f:?}");
        assert!((f.from_day - 44.0).abs() <= 1.0, "{f:?}");
    }

    #[test]
    fn one_gauge_is_a_sensor_and_the_sensitivity_pattern_is_the_structure() {
        let n = 300;
        let load = |i: usize| 1.0 + ((i as f64) / 5.0).sin().abs() * 3.0;
        // sensitivities of four gauges, different per gauge and varying with the load
        let sens = DMatrix::from_fn(n, 4, |i, g| load(i) * [0.8, -0.5, 0.3, 1.1][g]);
        let fitted = DMatrix::from_fn(n, 4, |i, g| 20.0 * load(i) * (g as f64 + 1.0));
        let rec = record(fitted.clone());
        let from = 200;
        // a change of the parameter by 4 units from row 200
        let r = DMatrix::from_fn(n, 4, |i, g| {
            wiggle(i, g) + if i >= from { 4.0 * sens[(i, g)] } else { 0.0 }
        });
        let inp = input(&rec, &r, &fitted);
        let (t, f) = attribute("gap alarm", &inp, &sens, from);
        assert_eq!(t.verdict, "structure", "{t:?}");
        assert!(f.is_none());
        // a step of 3 on gauge 3 only
        let r = DMatrix::from_fn(n, 4, |i, g| {
            wiggle(i, g) + if i >= from && g == 2 { 3.0 } else { 0.0 }
        });
        let inp = ScanInput {
            residual: &r,
            ..inp
        };
        let (t, f) = attribute("gap alarm", &inp, &sens, from);
        assert_eq!(t.verdict, "sensor", "{t:?}");
        assert_eq!(f.map(|f| f.kind), Some(SensorKind::Step));
    }
}
