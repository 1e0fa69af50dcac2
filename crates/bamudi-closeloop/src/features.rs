//! The feature library of a record: time, the model inputs, the load (when the record has one,
//! e.g. a gate's head), every other numeric column and the rate of change per hour of all but
//! time (the residual checks look at these); then the derived candidates of the data-driven
//! term: differences of covariates with the same declared unit, their rates, and daily and
//! seasonal harmonics. Lags with a fitted time constant are built by the data-driven term
//! itself, since the constant is fitted to the residual.

use super::MeasuredRecord;
use super::config::LoadSpec;
use std::collections::BTreeMap;

/// Hours in a day and in a (Julian) year: the harmonics' periods.
const DAY_H: f64 = 24.0;
const YEAR_H: f64 = 365.25 * DAY_H;

/// Whether `unit` is a temperature unit: `degF`, `degC`, `K`, `°F`, `°C`, `fahrenheit`,
/// `celsius`, `kelvin` (any letter case). Such a declared column is a thermal candidate.
///
/// ```
/// use bamudi_closeloop::is_temperature_unit;
/// assert!(is_temperature_unit("degF") && is_temperature_unit("°c"));
/// assert!(!is_temperature_unit("in") && !is_temperature_unit("F_per_h"));
/// ```
pub fn is_temperature_unit(unit: &str) -> bool {
    matches!(canonical_unit(unit).as_str(), "degf" | "degc" | "k")
}

/// A unit in lower case with the spellings of one temperature scale made one (`°F`,
/// `fahrenheit` → `degf`), so that columns in `degF` and `°F` pair up for differences.
fn canonical_unit(unit: &str) -> String {
    let u = unit.trim().to_lowercase();
    match u.as_str() {
        "°f" | "fahrenheit" => "degf".into(),
        "°c" | "celsius" => "degc".into(),
        "kelvin" => "k".into(),
        _ => u,
    }
}

/// The temperatures (°C) a covariate declared in a temperature unit may read: the air, water
/// and steel around a structure outdoors. The lowest and highest air temperatures ever
/// recorded on Earth are −89 °C and +57 °C, water is liquid between 0 and 100 °C, and sunlit
/// steel stays well below 100 °C; a reading outside [−100, 100] °C is a fault code (−999),
/// a wrong declared unit (kelvin declared as °C) or an overflow, not a temperature.
pub const TEMPERATURE_RANGE_C: (f64, f64) = (-100.0, 100.0);

/// [`TEMPERATURE_RANGE_C`] in a temperature unit (`None` for another unit).
///
/// ```
/// use bamudi_closeloop::temperature_range;
/// assert_eq!(temperature_range("degF"), Some((-148.0, 212.0)));
/// assert_eq!(temperature_range("in"), None);
/// ```
pub fn temperature_range(unit: &str) -> Option<(f64, f64)> {
    let (lo, hi) = TEMPERATURE_RANGE_C;
    match canonical_unit(unit).as_str() {
        "degc" => Some((lo, hi)),
        "degf" => Some((lo * 1.8 + 32.0, hi * 1.8 + 32.0)),
        "k" => Some((lo + 273.15, hi + 273.15)),
        _ => None,
    }
}

/// Refuses a covariate value declared in a temperature unit (`units`, the configuration's
/// `column_units`) outside [`temperature_range`], naming the file, line and column.
pub(crate) fn check_covariate_values(
    rec: &MeasuredRecord,
    units: &BTreeMap<String, String>,
) -> crate::Result<()> {
    for (k, name) in rec.covariate_names.iter().enumerate() {
        let Some(unit) = units.get(name) else {
            continue;
        };
        let Some((lo, hi)) = temperature_range(unit) else {
            continue;
        };
        let col = rec.covariates.column(k);
        if let Some(i) = (0..rec.len()).find(|&i| !(lo..=hi).contains(&col[i])) {
            return Err(crate::CloseLoopError::Csv {
                file: rec.file.clone(),
                row: rec.source_lines[i] as usize,
                column: name.clone(),
                reason: format!(
                    "value {:?} {unit} is outside [{lo}, {hi}] {unit} ([{}, {}] °C, the \
                     temperatures of a structure's surroundings): a fault code, a wrong \
                     declared unit (`column_units`) or an overflow?",
                    col[i], TEMPERATURE_RANGE_C.0, TEMPERATURE_RANGE_C.1
                ),
            });
        }
    }
    Ok(())
}

/// Whether a unit measures nothing a difference would make sense of (a phase, a count).
fn dimensionless(unit: &str) -> bool {
    matches!(unit.trim(), "" | "1" | "-" | "none" | "dimensionless")
}

/// Candidate features derived from a record, in this order: `time_days`, the inputs, the load
/// (if declared), the CSV covariates, `d_<name>_per_h` of every column so far but time (the
/// first [`checked`](Self::checked) columns); then `<a>_minus_<b>` for covariates `a`, `b` of
/// one declared unit (not a dimensionless one) and their rates; then the harmonics
/// `daily_sin`, `daily_cos` (period 24 h; when the record spans two days at a median step of
/// at most 6 h), `semidaily_sin`, `semidaily_cos` (12 h; step at most 3 h: a daily cycle that
/// is not a sinusoid, such as sun on a gauge, needs its second harmonic) and `seasonal_sin`,
/// `seasonal_cos` (365.25 d; when the record spans a year: over a shorter record they are a
/// smooth trend, which the drift and the track already are). Time is measured from the first
/// row, so the phases are relative to it.
#[derive(Debug, Clone)]
pub struct Features {
    /// Feature names.
    pub names: Vec<String>,
    /// Feature values, one vector per name.
    pub cols: Vec<Vec<f64>>,
    /// Hours since the first row.
    pub time_h: Vec<f64>,
    /// The load at every row (zeros when none is declared).
    pub load: Vec<f64>,
    /// Its rate of change per hour.
    pub load_rate: Vec<f64>,
    /// Columns `1..=model_columns` are the model's own inputs (and the load): effects that
    /// look beyond the model skip them.
    pub model_columns: usize,
    /// Columns `0..checked` are the record's own columns and their rates: the residual checks
    /// correlate with these; the rest are derived candidates of the data-driven term.
    pub checked: usize,
    /// The level columns (covariates and same-unit differences, not rates or harmonics) whose
    /// first-order lag the data-driven term may use.
    pub lag_sources: Vec<usize>,
}

/// Backward difference `dv/dt` (forward at the first row; 0 for a single row).
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
    /// The features of `rec` with the optional declared `load` and the covariates' declared
    /// `units` (column name → unit).
    pub fn new(
        rec: &MeasuredRecord,
        load: Option<&LoadSpec>,
        units: &BTreeMap<String, String>,
    ) -> Self {
        let t = rec.time_h.clone();
        let mut names = vec!["time_days".to_string()];
        let mut cols = vec![t.iter().map(|h| h / 24.0).collect::<Vec<f64>>()];
        for (j, name) in rec.input_names.iter().enumerate() {
            names.push(name.clone());
            cols.push(rec.x.column(j).iter().copied().collect());
        }
        let load_values = match load {
            Some(l) => {
                let v: Vec<f64> = (0..rec.len()).map(|i| l.value(&row(rec, i))).collect();
                names.push(l.name.clone());
                cols.push(v.clone());
                v
            }
            None => vec![0.0; rec.len()],
        };
        let model_columns = names.len() - 1;
        for (k, nm) in rec.covariate_names.iter().enumerate() {
            names.push(nm.clone());
            cols.push(rec.covariates.column(k).iter().copied().collect());
        }
        let n_base = names.len();
        let mut lag_sources: Vec<usize> = (model_columns + 1..n_base).collect();
        push_rates(&mut names, &mut cols, &t, 1..n_base);
        let checked = names.len();
        let first_difference = names.len();
        for (a, b) in same_unit_pairs(&rec.covariate_names, units) {
            let (ca, cb) = (model_columns + 1 + a, model_columns + 1 + b);
            names.push(format!("{}_minus_{}", names[ca], names[cb]));
            cols.push(cols[ca].iter().zip(&cols[cb]).map(|(x, y)| x - y).collect());
        }
        let differences = first_difference..names.len();
        lag_sources.extend(differences.clone());
        push_rates(&mut names, &mut cols, &t, differences);
        push_harmonics(&mut names, &mut cols, &t);
        let load_rate = backward_rate(&t, &load_values);
        Self {
            names,
            cols,
            time_h: t,
            load: load_values,
            load_rate,
            model_columns,
            checked,
            lag_sources,
        }
    }

    /// The position of the feature `name`.
    pub fn position(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }
}

/// Appends `d_<name>_per_h` of the columns `range`.
fn push_rates(
    names: &mut Vec<String>,
    cols: &mut Vec<Vec<f64>>,
    t: &[f64],
    range: std::ops::Range<usize>,
) {
    for k in range {
        names.push(format!("d_{}_per_h", names[k]));
        cols.push(backward_rate(t, &cols[k]));
    }
}

/// The pairs `(a, b)`, `a < b`, of covariates (positions in `covariates`) declared in one
/// unit that is not dimensionless.
fn same_unit_pairs(covariates: &[String], units: &BTreeMap<String, String>) -> Vec<(usize, usize)> {
    let unit = |k: usize| units.get(&covariates[k]).map(|u| canonical_unit(u));
    let mut pairs = Vec::new();
    for a in 0..covariates.len() {
        for b in a + 1..covariates.len() {
            if let (Some(ua), Some(ub)) = (unit(a), unit(b))
                && ua == ub
                && !dimensionless(&ua)
            {
                pairs.push((a, b));
            }
        }
    }
    pairs
}

/// Appends the daily and seasonal harmonics the record can resolve (see [`Features`]).
fn push_harmonics(names: &mut Vec<String>, cols: &mut Vec<Vec<f64>>, t: &[f64]) {
    let span = t.last().copied().unwrap_or(0.0) - t.first().copied().unwrap_or(0.0);
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    let median_step = steps.get(steps.len() / 2).copied().unwrap_or(f64::INFINITY);
    let mut push = |label: &str, period_h: f64| {
        let w = std::f64::consts::TAU / period_h;
        names.push(format!("{label}_sin"));
        cols.push(t.iter().map(|h| (w * h).sin()).collect());
        names.push(format!("{label}_cos"));
        cols.push(t.iter().map(|h| (w * h).cos()).collect());
    };
    // at least four rows per period: two would sample a sinusoid at its zeros only
    if span >= 2.0 * DAY_H && median_step <= DAY_H / 4.0 {
        push("daily", DAY_H);
    }
    if span >= 2.0 * DAY_H && median_step <= DAY_H / 8.0 {
        push("semidaily", DAY_H / 2.0);
    }
    if span >= YEAR_H {
        push("seasonal", YEAR_H);
    }
}

fn row(rec: &MeasuredRecord, i: usize) -> Vec<f64> {
    rec.x.row(i).iter().copied().collect()
}
