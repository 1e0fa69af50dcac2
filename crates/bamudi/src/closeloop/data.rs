//! Measured-data ingestion: the field CSV (`time`, `h_up`, `h_down`, gauge columns, any other
//! numeric columns as covariates) with errors naming the file, row and column.

use crate::BamudiError;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// What to do with a row whose gauge cell is empty (a missing value).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum MissingPolicy {
    /// Drop the row; the number dropped is reported.
    #[default]
    Drop,
    /// Interpolate the gauge linearly in time between its nearest valid neighbours (the
    /// nearest valid value at the ends); the number of imputed cells is reported.
    Interpolate,
}

/// A measured record, rows sorted in time.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MeasuredRecord {
    /// File (or label) the record came from.
    pub file: String,
    /// Time of the first row, seconds since the Unix epoch (0 when `time` was numeric hours).
    pub start_unix_s: f64,
    /// Hours since the first row.
    pub time_h: Vec<f64>,
    /// Model inputs `[h_up, h_down]` (in), one row per sample.
    pub x: DMatrix<f64>,
    /// Gauge strains (microstrain), one column per gauge.
    pub y: DMatrix<f64>,
    /// Gauge column names.
    pub gauge_names: Vec<String>,
    /// Names of the other numeric columns.
    pub covariate_names: Vec<String>,
    /// Covariate values, one column per covariate.
    pub covariates: DMatrix<f64>,
    /// CSV line number of every kept row (header = line 1).
    pub source_lines: Vec<u64>,
    /// Rows dropped because a gauge value was missing.
    pub dropped_missing: usize,
    /// Gauge cells imputed by interpolation.
    pub imputed: usize,
}

impl MeasuredRecord {
    /// Number of rows.
    ///
    /// ```
    /// use bamudi::closeloop::{parse_csv, IngestConfig};
    /// let csv = "time,h_up,h_down,g1\n2024-01-01T00:00:00Z,100,50,3.5\n2024-01-01T01:00:00Z,50,50,0.1\n";
    /// let rec = parse_csv(csv, "doc.csv", &IngestConfig::new(vec!["g1".into()])).unwrap();
    /// assert_eq!(rec.len(), 2);
    /// ```
    pub fn len(&self) -> usize {
        self.time_h.len()
    }

    /// `true` when there are no rows.
    ///
    /// ```
    /// use bamudi::closeloop::{parse_csv, IngestConfig};
    /// let csv = "time,h_up,h_down,g1\n2024-01-01T00:00:00Z,100,50,3.5\n";
    /// assert!(!parse_csv(csv, "doc.csv", &IngestConfig::new(vec!["g1".into()])).unwrap().is_empty());
    /// ```
    pub fn is_empty(&self) -> bool {
        self.time_h.is_empty()
    }
}

/// How to read a measured CSV.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IngestConfig {
    /// Gauge column names (microstrain), in model output order.
    pub gauge_columns: Vec<String>,
    /// Model domain of both levels (in); rows outside are errors. Default `[24, 744]`.
    pub domain_in: (f64, f64),
    /// Missing gauge values.
    pub missing: MissingPolicy,
}

impl IngestConfig {
    /// Gauge columns `gauges`, domain `[24, 744]` in, missing rows dropped.
    ///
    /// ```
    /// let c = bamudi::closeloop::IngestConfig::new(vec!["g1".into()]);
    /// assert_eq!(c.domain_in, (24.0, 744.0));
    /// ```
    pub fn new(gauges: Vec<String>) -> Self {
        Self {
            gauge_columns: gauges,
            domain_in: (24.0, 744.0),
            missing: MissingPolicy::Drop,
        }
    }
}

/// Reads a measured CSV file.
///
/// ```no_run
/// use bamudi::closeloop::{read_csv, IngestConfig};
/// let gauges = (1..=7).map(|g| format!("g{g}")).collect();
/// let rec = read_csv(std::path::Path::new("field.csv"), &IngestConfig::new(gauges)).unwrap();
/// println!("{} rows, {} dropped", rec.len(), rec.dropped_missing);
/// ```
pub fn read_csv(path: &std::path::Path, cfg: &IngestConfig) -> Result<MeasuredRecord, BamudiError> {
    let text = std::fs::read_to_string(path).map_err(|source| BamudiError::Io {
        path: path.display().to_string(),
        source,
    })?;
    parse_csv(&text, &path.display().to_string(), cfg)
}

/// Parses measured CSV text; `file` labels the errors.
///
/// ```
/// use bamudi::closeloop::{parse_csv, IngestConfig};
/// let csv = "time,h_up,h_down,air_temp_f,g1\n2024-01-01T00:00:00Z,100,50,40,3.5\n2024-01-01T00:00:00Z,90,50,41,3.0\n";
/// let err = parse_csv(csv, "doc.csv", &IngestConfig::new(vec!["g1".into()])).unwrap_err();
/// assert!(err.to_string().contains("row 3"), "{err}"); // time does not increase
/// ```
pub fn parse_csv(
    text: &str,
    file: &str,
    cfg: &IngestConfig,
) -> Result<MeasuredRecord, BamudiError> {
    let mut rdr = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let csv_err = |line: u64, e: csv::Error| BamudiError::Csv {
        file: file.into(),
        row: line as usize,
        column: "-".into(),
        reason: e.to_string(),
    };
    let header: Vec<String> = rdr
        .headers()
        .map_err(|e| csv_err(1, e))?
        .iter()
        .map(str::to_string)
        .collect();
    let find = |name: &str| -> Result<usize, BamudiError> {
        let hits: Vec<usize> = header
            .iter()
            .enumerate()
            .filter(|(_, h)| *h == name)
            .map(|(i, _)| i)
            .collect();
        match hits.len() {
            0 => Err(BamudiError::Csv {
                file: file.into(),
                row: 1,
                column: name.into(),
                reason: "missing column".into(),
            }),
            1 => Ok(hits[0]),
            _ => Err(BamudiError::Csv {
                file: file.into(),
                row: 1,
                column: name.into(),
                reason: "duplicate column".into(),
            }),
        }
    };
    if cfg.gauge_columns.is_empty() {
        return Err(BamudiError::InvalidConfig {
            name: "gauge_columns",
            reason: "no gauge columns named".into(),
        });
    }
    for (i, h) in header.iter().enumerate() {
        if header[..i].contains(h) {
            return Err(BamudiError::Csv {
                file: file.into(),
                row: 1,
                column: h.clone(),
                reason: "duplicate column".into(),
            });
        }
    }
    let (i_time, i_up, i_down) = (find("time")?, find("h_up")?, find("h_down")?);
    let i_gauges = cfg
        .gauge_columns
        .iter()
        .map(|g| find(g))
        .collect::<Result<Vec<_>, _>>()?;
    let i_cov: Vec<usize> = (0..header.len())
        .filter(|i| ![i_time, i_up, i_down].contains(i) && !i_gauges.contains(i))
        .collect();
    let (lo, hi) = cfg.domain_in;
    let ng = i_gauges.len();
    let mut time_abs = Vec::new();
    let mut x = Vec::new();
    let mut y: Vec<Option<f64>> = Vec::new();
    let mut cov = Vec::new();
    let mut lines = Vec::new();
    let mut numeric_time: Option<bool> = None;
    for rec in rdr.records() {
        let rec = rec.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line());
            csv_err(line, e)
        })?;
        let line = rec.position().map_or(0, |p| p.line());
        let bad = |col: usize, reason: String| BamudiError::Csv {
            file: file.into(),
            row: line as usize,
            column: header[col].clone(),
            reason,
        };
        if rec.len() != header.len() {
            return Err(bad(
                0,
                format!("{} fields, header has {}", rec.len(), header.len()),
            ));
        }
        let number = |col: usize| -> Result<f64, BamudiError> {
            let cell = &rec[col];
            match cell.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                Ok(v) => Err(bad(col, format!("non-finite value {v}"))),
                Err(_) if cell.is_empty() => Err(bad(col, "empty cell".into())),
                Err(_) => Err(bad(col, format!("not a number: {cell:?}"))),
            }
        };
        let t = match mitergate::field::unix_from_iso8601(&rec[i_time]) {
            Some(t) if numeric_time != Some(true) => {
                numeric_time = Some(false);
                t
            }
            _ if numeric_time != Some(false) => {
                numeric_time = Some(true);
                number(i_time).map_err(|_| {
                    bad(
                        i_time,
                        format!("neither ISO 8601 nor hours: {:?}", &rec[i_time]),
                    )
                })? * 3600.0
            }
            _ => {
                return Err(bad(
                    i_time,
                    format!("not ISO 8601 like the first row: {:?}", &rec[i_time]),
                ));
            }
        };
        if let Some(&prev) = time_abs.last()
            && t <= prev
        {
            return Err(bad(i_time, "time does not increase".into()));
        }
        let (hu, hd) = (number(i_up)?, number(i_down)?);
        for (col, v) in [(i_up, hu), (i_down, hd)] {
            if !(lo..=hi).contains(&v) {
                return Err(bad(
                    col,
                    format!("level {v} in outside the model domain [{lo}, {hi}]"),
                ));
            }
        }
        if hu < hd - 1e-9 {
            return Err(bad(i_up, format!("h_up {hu} < h_down {hd}")));
        }
        for &c in &i_gauges {
            y.push(if rec[c].is_empty() {
                None
            } else {
                Some(number(c)?)
            });
        }
        for &c in &i_cov {
            cov.push(number(c)?);
        }
        time_abs.push(t);
        x.extend([hu, hd]);
        lines.push(line);
    }
    let n = time_abs.len();
    if n == 0 {
        return Err(BamudiError::Csv {
            file: file.into(),
            row: 1,
            column: "-".into(),
            reason: "no data rows".into(),
        });
    }
    let nc = i_cov.len();
    let mut keep: Vec<usize> = (0..n).collect();
    let mut dropped = 0;
    let mut imputed = 0;
    match cfg.missing {
        MissingPolicy::Drop => {
            keep.retain(|&i| (0..ng).all(|j| y[i * ng + j].is_some()));
            dropped = n - keep.len();
        }
        MissingPolicy::Interpolate => {
            for j in 0..ng {
                let valid: Vec<usize> = (0..n).filter(|&i| y[i * ng + j].is_some()).collect();
                if valid.is_empty() {
                    return Err(BamudiError::Csv {
                        file: file.into(),
                        row: 1,
                        column: cfg.gauge_columns[j].clone(),
                        reason: "every value is missing".into(),
                    });
                }
                for i in 0..n {
                    if y[i * ng + j].is_none() {
                        y[i * ng + j] = Some(interpolate(&time_abs, &y, ng, j, &valid, i));
                        imputed += 1;
                    }
                }
            }
        }
    }
    if keep.is_empty() {
        return Err(BamudiError::Csv {
            file: file.into(),
            row: 1,
            column: "-".into(),
            reason: "every row has a missing gauge value".into(),
        });
    }
    let t0 = time_abs[keep[0]];
    Ok(MeasuredRecord {
        file: file.into(),
        start_unix_s: if numeric_time == Some(true) { 0.0 } else { t0 },
        time_h: keep.iter().map(|&i| (time_abs[i] - t0) / 3600.0).collect(),
        x: DMatrix::from_fn(keep.len(), 2, |r, c| x[keep[r] * 2 + c]),
        y: DMatrix::from_fn(keep.len(), ng, |r, c| {
            y[keep[r] * ng + c].unwrap_or(f64::NAN)
        }),
        gauge_names: cfg.gauge_columns.clone(),
        covariate_names: i_cov.iter().map(|&c| header[c].clone()).collect(),
        covariates: DMatrix::from_fn(keep.len(), nc, |r, c| cov[keep[r] * nc + c]),
        source_lines: keep.iter().map(|&i| lines[i]).collect(),
        dropped_missing: dropped,
        imputed,
    })
}

/// Linear interpolation in time of gauge `j` at row `i` from the rows `valid`.
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
