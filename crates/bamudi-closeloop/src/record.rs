//! Measured records: a time column, the model's input columns, the output (gauge) columns and
//! any other numeric columns as covariates, read with the [`Table`] error policy (file, line
//! and column in every error).

use crate::error::{CloseLoopError, Result};
use bamudi::data::{Empty, Table};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// What to do with a row whose output cell is empty (a missing value).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum MissingPolicy {
    /// Drop the row; the number dropped is reported.
    #[default]
    Drop,
    /// Interpolate the output linearly in time between its nearest valid neighbours (the
    /// nearest valid value at the ends); the number of imputed cells is reported.
    Interpolate,
}

/// A measured record, rows sorted in time.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MeasuredRecord {
    /// File (or label) the record came from.
    pub file: String,
    /// Time of the first row, seconds since the Unix epoch (0 when time was numeric hours).
    pub start_unix_s: f64,
    /// Hours since the first row.
    pub time_h: Vec<f64>,
    /// Names of the model inputs.
    pub input_names: Vec<String>,
    /// Model inputs, one row per sample.
    pub x: DMatrix<f64>,
    /// Outputs (e.g. gauge strains), one column per output.
    pub y: DMatrix<f64>,
    /// Output column names.
    pub gauge_names: Vec<String>,
    /// Names of the other numeric columns.
    pub covariate_names: Vec<String>,
    /// Covariate values, one column per covariate.
    pub covariates: DMatrix<f64>,
    /// CSV line of every kept row (header = line 1).
    pub source_lines: Vec<u64>,
    /// Rows dropped because an output value was missing.
    pub dropped_missing: usize,
    /// Output cells imputed by interpolation.
    pub imputed: usize,
}

impl MeasuredRecord {
    /// Number of rows.
    pub fn len(&self) -> usize {
        self.time_h.len()
    }

    /// `true` when there are no rows.
    pub fn is_empty(&self) -> bool {
        self.time_h.is_empty()
    }

    /// Checks every row's inputs with `check` (e.g. the model's own domain check); the error
    /// names the file and line of the first row it refuses.
    ///
    /// ```
    /// use bamudi_closeloop::{parse_csv, IngestConfig};
    /// let csv = "time,h_up,h_down,g1\n0,100,50,3.5\n1,40,50,0.1\n";
    /// let rec = parse_csv(csv, "doc.csv", &IngestConfig::new(&["h_up", "h_down"], &["g1"])).unwrap();
    /// let e = rec.check_inputs(|x| if x[0] >= x[1] { Ok(()) } else { Err("h_up < h_down".into()) });
    /// assert!(e.unwrap_err().to_string().contains("line 3"));
    /// ```
    pub fn check_inputs(
        &self,
        check: impl Fn(&[f64]) -> std::result::Result<(), String>,
    ) -> Result<()> {
        for i in 0..self.len() {
            let x: Vec<f64> = self.x.row(i).iter().copied().collect();
            if let Err(reason) = check(&x) {
                return Err(CloseLoopError::Csv {
                    file: self.file.clone(),
                    row: self.source_lines[i] as usize,
                    column: self.input_names.join(", "),
                    reason,
                });
            }
        }
        Ok(())
    }
}

/// How to read a measured CSV.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IngestConfig {
    /// The time column: ISO 8601 timestamps (UTC unless an offset is given) or hours.
    pub time_column: String,
    /// The model's input columns, in model input order.
    pub input_columns: Vec<String>,
    /// Output (gauge) columns, in model output order; none for a record of inputs only (a
    /// load history), which the close loop refuses.
    pub gauge_columns: Vec<String>,
    /// Missing output values.
    pub missing: MissingPolicy,
}

impl IngestConfig {
    /// Time column `time`, the given input and output columns, missing rows dropped.
    ///
    /// ```
    /// let c = bamudi_closeloop::IngestConfig::new(&["h_up", "h_down"], &["g1"]);
    /// assert_eq!(c.time_column, "time");
    /// ```
    pub fn new(inputs: &[&str], gauges: &[&str]) -> Self {
        Self {
            time_column: "time".into(),
            input_columns: inputs.iter().map(|s| s.to_string()).collect(),
            gauge_columns: gauges.iter().map(|s| s.to_string()).collect(),
            missing: MissingPolicy::Drop,
        }
    }

    /// Sets the missing-value policy.
    pub fn missing(mut self, m: MissingPolicy) -> Self {
        self.missing = m;
        self
    }
}

/// Reads a measured CSV file ([`Table::read`]: a file that is not UTF-8 is refused with its
/// line and column).
pub fn read_csv(path: &std::path::Path, cfg: &IngestConfig) -> Result<MeasuredRecord> {
    from_table(&Table::read(path)?, cfg)
}

/// Column positions of a record's roles in a table.
struct Columns {
    time: usize,
    inputs: Vec<usize>,
    gauges: Vec<usize>,
    covariates: Vec<usize>,
}

impl Columns {
    fn locate(t: &Table, cfg: &IngestConfig) -> Result<Self> {
        let find = |names: &[String]| {
            names
                .iter()
                .map(|n| t.column(n))
                .collect::<bamudi::Result<Vec<_>>>()
        };
        let time = t.column(&cfg.time_column)?;
        let (inputs, gauges) = (find(&cfg.input_columns)?, find(&cfg.gauge_columns)?);
        let covariates = (0..t.header().len())
            .filter(|c| *c != time && !inputs.contains(c) && !gauges.contains(c))
            .collect();
        Ok(Self {
            time,
            inputs,
            gauges,
            covariates,
        })
    }
}

/// Parses measured CSV text; `file` labels the errors.
///
/// ```
/// use bamudi_closeloop::{parse_csv, IngestConfig};
/// let cfg = IngestConfig::new(&["h_up", "h_down"], &["g1"]);
/// let csv = "time,h_up,h_down,air_temp_f,g1\n2024-01-01T00:00:00Z,100,50,40,3.5\n2024-01-01T00:00:00Z,90,50,41,3.0\n";
/// let err = parse_csv(csv, "doc.csv", &cfg).unwrap_err();
/// assert!(err.to_string().contains("line 3"), "{err}"); // time does not increase
/// ```
pub fn parse_csv(text: &str, file: &str, cfg: &IngestConfig) -> Result<MeasuredRecord> {
    from_table(&Table::parse(text, file)?, cfg)
}

/// The measured record of a parsed table (e.g. one whose values a caller has checked first).
pub fn from_table(t: &Table, cfg: &IngestConfig) -> Result<MeasuredRecord> {
    let file = t.file();
    let cols = Columns::locate(t, cfg)?;
    if t.is_empty() {
        return Err(CloseLoopError::Csv {
            file: file.into(),
            row: 1,
            column: "-".into(),
            reason: "no data rows".into(),
        });
    }
    let (time_abs, numeric_time) = times(t, cols.time)?;
    let number = |i, c| t.number(i, c, Empty::Refuse).map(|v| v.unwrap_or(f64::NAN));
    let n = t.len();
    let (ni, ng, nc) = (cols.inputs.len(), cols.gauges.len(), cols.covariates.len());
    let mut x = DMatrix::zeros(n, ni);
    let mut cov = DMatrix::zeros(n, nc);
    let mut y: Vec<Option<f64>> = Vec::with_capacity(n * ng);
    for i in 0..n {
        for (j, &c) in cols.inputs.iter().enumerate() {
            x[(i, j)] = number(i, c)?;
        }
        for &c in &cols.gauges {
            y.push(t.number(i, c, Empty::Missing)?);
        }
        for (j, &c) in cols.covariates.iter().enumerate() {
            cov[(i, j)] = number(i, c)?;
        }
    }
    let (keep, dropped, imputed) = apply_missing(t, cfg, &time_abs, &mut y, ng)?;
    let t0 = time_abs[keep[0]];
    Ok(MeasuredRecord {
        file: file.into(),
        start_unix_s: if numeric_time { 0.0 } else { t0 },
        time_h: keep.iter().map(|&i| (time_abs[i] - t0) / 3600.0).collect(),
        input_names: cfg.input_columns.clone(),
        x: x.select_rows(keep.iter()),
        y: DMatrix::from_fn(keep.len(), ng, |r, c| {
            y[keep[r] * ng + c].unwrap_or(f64::NAN)
        }),
        gauge_names: cfg.gauge_columns.clone(),
        covariate_names: cols
            .covariates
            .iter()
            .map(|&c| t.header()[c].clone())
            .collect(),
        covariates: cov.select_rows(keep.iter()),
        source_lines: keep.iter().map(|&i| t.line(i)).collect(),
        dropped_missing: dropped,
        imputed,
    })
}

/// Seconds of every row (ISO 8601, or hours when the first row is a plain number), strictly
/// increasing; `true` when the column is numeric hours.
fn times(t: &Table, c: usize) -> Result<(Vec<f64>, bool)> {
    let numeric = unix_seconds(t.cell(0, c)).is_none();
    let mut out: Vec<f64> = Vec::with_capacity(t.len());
    for i in 0..t.len() {
        let cell = t.cell(i, c);
        let s = if numeric {
            let h = t
                .number(i, c, Empty::Refuse)
                .map_err(|_| t.error_at(i, c, format!("neither ISO 8601 nor hours: {cell:?}")))?;
            h.unwrap_or(f64::NAN) * 3600.0
        } else {
            unix_seconds(cell).ok_or_else(|| {
                t.error_at(i, c, format!("not ISO 8601 like the first row: {cell:?}"))
            })?
        };
        if out.last().is_some_and(|&prev| s <= prev) {
            return Err(t.error_at(i, c, "time does not increase").into());
        }
        out.push(s);
    }
    Ok((out, numeric))
}

/// Seconds since the Unix epoch of an ISO 8601 timestamp (`2024-01-01T00:00:00Z`, an offset
/// like `+02:00`, or none for UTC; a space may replace the `T`; seconds are optional).
fn unix_seconds(s: &str) -> Option<f64> {
    let ts = match s.parse::<jiff::Timestamp>() {
        Ok(ts) => ts,
        Err(_) => {
            let civil: jiff::civil::DateTime = s.parse().ok()?;
            jiff::tz::TimeZone::UTC.to_timestamp(civil).ok()?
        }
    };
    Some(ts.as_second() as f64 + f64::from(ts.subsec_nanosecond()) * 1e-9)
}

/// Applies the missing-value policy to the outputs `y` (`n x ng`, row major); returns the rows
/// kept, the number dropped and the number imputed.
fn apply_missing(
    t: &Table,
    cfg: &IngestConfig,
    time: &[f64],
    y: &mut [Option<f64>],
    ng: usize,
) -> Result<(Vec<usize>, usize, usize)> {
    let n = time.len();
    let whole = |reason: &str, column: &str| CloseLoopError::Csv {
        file: t.file().into(),
        row: 1,
        column: column.into(),
        reason: reason.into(),
    };
    let (mut keep, mut imputed): (Vec<usize>, usize) = ((0..n).collect(), 0);
    // a gauge never read is named whatever the policy (dropping would drop every row)
    if let Some(j) = (0..ng).find(|&j| (0..n).all(|i| y[i * ng + j].is_none())) {
        return Err(whole(
            "every value is missing: the gauge has no reading in any row; fix its logging \
             or drop it (and its gauge in the gate file)",
            &cfg.gauge_columns[j],
        ));
    }
    match cfg.missing {
        MissingPolicy::Drop => keep.retain(|&i| (0..ng).all(|j| y[i * ng + j].is_some())),
        MissingPolicy::Interpolate => {
            for j in 0..ng {
                let valid: Vec<usize> = (0..n).filter(|&i| y[i * ng + j].is_some()).collect();
                for i in 0..n {
                    if y[i * ng + j].is_none() {
                        y[i * ng + j] = Some(interpolate(time, y, ng, j, &valid, i));
                        imputed += 1;
                    }
                }
            }
        }
    }
    if keep.is_empty() {
        return Err(whole(
            "every row has a missing gauge value (no row has all of them); impute the gaps \
             (`--impute`) or drop the gauges that miss most",
            &cfg.gauge_columns.join(", "),
        ));
    }
    let dropped = n - keep.len();
    Ok((keep, dropped, imputed))
}

/// Linear interpolation in time of output `j` at row `i` from the rows `valid`.
fn interpolate(
    t: &[f64],
    y: &[Option<f64>],
    ng: usize,
    j: usize,
    valid: &[usize],
    i: usize,
) -> f64 {
    let k = valid.partition_point(|&v| v < i);
    let val = |r: usize| y[r * ng + j].unwrap_or(0.0);
    match (k.checked_sub(1).map(|k| valid[k]), valid.get(k)) {
        (Some(a), Some(&b)) => {
            let w = (t[i] - t[a]) / (t[b] - t[a]);
            val(a) * (1.0 - w) + val(b) * w
        }
        (Some(a), None) => val(a),
        (None, Some(&b)) => val(b),
        (None, None) => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_parse_with_and_without_offset_and_seconds() {
        assert_eq!(unix_seconds("1970-01-01T00:00:00Z"), Some(0.0));
        assert_eq!(unix_seconds("1970-01-01T01:00:00+01:00"), Some(0.0));
        assert_eq!(unix_seconds("1970-01-01 00:01"), Some(60.0));
        assert_eq!(unix_seconds("2024-03-01T12:00:00"), Some(1_709_294_400.0));
        assert_eq!(unix_seconds("12.5"), None);
    }
}
