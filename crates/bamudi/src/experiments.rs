//! Experimental data `{x_e, y_o^e}` (Eq. 13) and its CSV form.

use crate::error::{BamudiError, Result};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// `N_e` experiments: inputs `x` (`N_e x d`) and measured outputs `y` (`N_e x N_o`), with the
/// column names (units belong in the names, e.g. `h_up_in`, `gauge_1_microstrain`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Experiments {
    /// Names of the input columns.
    pub input_names: Vec<String>,
    /// Names of the output columns.
    pub output_names: Vec<String>,
    /// Inputs, one row per experiment.
    pub x: DMatrix<f64>,
    /// Measured outputs, one row per experiment.
    pub y: DMatrix<f64>,
}

impl Experiments {
    /// Bundles inputs and outputs after checking shapes, names and finiteness.
    ///
    /// ```
    /// use bamudi::Experiments;
    /// use nalgebra::DMatrix;
    /// let e = Experiments::new(vec!["p".into()], vec!["s".into()],
    ///     DMatrix::from_row_slice(2, 1, &[1.0, 2.0]), DMatrix::from_row_slice(2, 1, &[3.0, 4.0])).unwrap();
    /// assert_eq!(e.len(), 2);
    /// assert!(Experiments::new(vec!["p".into()], vec!["s".into()],
    ///     DMatrix::from_row_slice(1, 1, &[f64::NAN]), DMatrix::from_row_slice(1, 1, &[0.0])).is_err());
    /// ```
    pub fn new(
        input_names: Vec<String>,
        output_names: Vec<String>,
        x: DMatrix<f64>,
        y: DMatrix<f64>,
    ) -> Result<Self> {
        if x.nrows() != y.nrows() {
            return Err(BamudiError::dim(
                "experiments: rows of x vs y",
                x.nrows(),
                y.nrows(),
            ));
        }
        if x.ncols() != input_names.len() {
            return Err(BamudiError::dim(
                "experiments: input columns",
                input_names.len(),
                x.ncols(),
            ));
        }
        if y.ncols() != output_names.len() {
            return Err(BamudiError::dim(
                "experiments: output columns",
                output_names.len(),
                y.ncols(),
            ));
        }
        for (m, names) in [(&x, &input_names), (&y, &output_names)] {
            for i in 0..m.nrows() {
                for j in 0..m.ncols() {
                    if !m[(i, j)].is_finite() {
                        return Err(BamudiError::Csv {
                            file: "<memory>".into(),
                            row: i + 2,
                            column: names[j].clone(),
                            reason: format!("value {} is not finite", m[(i, j)]),
                        });
                    }
                }
            }
        }
        Ok(Self {
            input_names,
            output_names,
            x,
            y,
        })
    }

    /// Number of experiments `N_e`.
    ///
    /// ```
    /// # use bamudi::Experiments; use nalgebra::DMatrix;
    /// let e = Experiments::new(vec!["p".into()], vec!["s".into()], DMatrix::zeros(3, 1), DMatrix::zeros(3, 1)).unwrap();
    /// assert_eq!(e.len(), 3);
    /// ```
    pub fn len(&self) -> usize {
        self.x.nrows()
    }

    /// True when there are no experiments.
    ///
    /// ```
    /// # use bamudi::Experiments; use nalgebra::DMatrix;
    /// let e = Experiments::new(vec!["p".into()], vec!["s".into()], DMatrix::zeros(0, 1), DMatrix::zeros(0, 1)).unwrap();
    /// assert!(e.is_empty());
    /// ```
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bounding box of the inputs, per column `(min, max)`.
    ///
    /// ```
    /// # use bamudi::Experiments; use nalgebra::DMatrix;
    /// let e = Experiments::new(vec!["p".into()], vec!["s".into()],
    ///     DMatrix::from_row_slice(2, 1, &[1.0, 5.0]), DMatrix::zeros(2, 1)).unwrap();
    /// assert_eq!(e.input_bounds(), vec![(1.0, 5.0)]);
    /// ```
    pub fn input_bounds(&self) -> Vec<(f64, f64)> {
        (0..self.x.ncols())
            .map(|j| {
                let c = self.x.column(j);
                (c.min(), c.max())
            })
            .collect()
    }

    /// Writes a CSV with a header `input_names..., output_names...` and one row per experiment.
    ///
    /// ```
    /// # use bamudi::Experiments; use nalgebra::DMatrix;
    /// let e = Experiments::new(vec!["p".into()], vec!["s".into()],
    ///     DMatrix::from_row_slice(1, 1, &[1.5]), DMatrix::from_row_slice(1, 1, &[-2.0])).unwrap();
    /// let path = std::env::temp_dir().join("bamudi_doc_write.csv");
    /// e.write_csv(&path).unwrap();
    /// let back = Experiments::read_csv(&path, &["p"], &["s"]).unwrap();
    /// assert_eq!(back, e);
    /// ```
    pub fn write_csv(&self, path: &Path) -> Result<()> {
        let file = path.display().to_string();
        let mut w = csv::Writer::from_path(path).map_err(|e| BamudiError::Csv {
            file: file.clone(),
            row: 0,
            column: "-".into(),
            reason: e.to_string(),
        })?;
        let csv_err = |e: csv::Error| BamudiError::Csv {
            file: file.clone(),
            row: 0,
            column: "-".into(),
            reason: e.to_string(),
        };
        let header: Vec<&str> = self
            .input_names
            .iter()
            .chain(&self.output_names)
            .map(String::as_str)
            .collect();
        w.write_record(&header).map_err(csv_err)?;
        for i in 0..self.len() {
            // `{:?}` prints the shortest string that round-trips exactly
            let row: Vec<String> = (0..self.x.ncols())
                .map(|j| format!("{:?}", self.x[(i, j)]))
                .chain((0..self.y.ncols()).map(|j| format!("{:?}", self.y[(i, j)])))
                .collect();
            w.write_record(&row).map_err(csv_err)?;
        }
        w.flush().map_err(|e| BamudiError::Io {
            path: file.clone(),
            source: e,
        })
    }

    /// Reads the columns `inputs` and `outputs` (by header name, any order; other columns are
    /// ignored). Errors name the file, the 1-based row (header = row 1) and the column for a
    /// missing or duplicate column, a short row, an empty, non-numeric or non-finite value.
    ///
    /// ```
    /// # use bamudi::Experiments;
    /// let path = std::env::temp_dir().join("bamudi_doc_read.csv");
    /// std::fs::write(&path, "s,p\n1.0,2.0\n3.0,abc\n").unwrap();
    /// let err = Experiments::read_csv(&path, &["p"], &["s"]).unwrap_err().to_string();
    /// assert!(err.contains("row 3") && err.contains("`p`"), "{err}");
    /// ```
    pub fn read_csv(path: &Path, inputs: &[&str], outputs: &[&str]) -> Result<Self> {
        let file = path.display().to_string();
        let err = |row: usize, column: &str, reason: String| BamudiError::Csv {
            file: file.clone(),
            row,
            column: column.to_string(),
            reason,
        };
        let mut r = csv::ReaderBuilder::new()
            .has_headers(true)
            .flexible(true)
            .trim(csv::Trim::All)
            .from_path(path)
            .map_err(|e| err(0, "-", e.to_string()))?;
        let header: Vec<String> = r
            .headers()
            .map_err(|e| err(1, "-", e.to_string()))?
            .iter()
            .map(str::to_string)
            .collect();
        let locate = |name: &str| -> Result<usize> {
            let hits: Vec<usize> = header
                .iter()
                .enumerate()
                .filter(|(_, h)| h.as_str() == name)
                .map(|(i, _)| i)
                .collect();
            match hits.as_slice() {
                [i] => Ok(*i),
                [] => Err(err(
                    1,
                    name,
                    format!("missing column (header has {header:?})"),
                )),
                _ => Err(err(
                    1,
                    name,
                    format!("duplicate column (at positions {hits:?})"),
                )),
            }
        };
        let in_idx = inputs
            .iter()
            .map(|n| locate(n))
            .collect::<Result<Vec<_>>>()?;
        let out_idx = outputs
            .iter()
            .map(|n| locate(n))
            .collect::<Result<Vec<_>>>()?;
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        for (k, rec) in r.records().enumerate() {
            let row = k + 2;
            let rec = rec.map_err(|e| err(row, "-", e.to_string()))?;
            let parse = |col: usize, name: &str, dst: &mut Vec<f64>| -> Result<()> {
                let s = rec
                    .get(col)
                    .ok_or_else(|| err(row, name, format!("row has only {} fields", rec.len())))?;
                if s.is_empty() {
                    return Err(err(row, name, "empty value".into()));
                }
                let v: f64 = s
                    .parse()
                    .map_err(|_| err(row, name, format!("`{s}` is not a number")))?;
                if !v.is_finite() {
                    return Err(err(row, name, format!("value `{s}` is not finite")));
                }
                dst.push(v);
                Ok(())
            };
            for (&c, n) in in_idx.iter().zip(inputs) {
                parse(c, n, &mut xs)?;
            }
            for (&c, n) in out_idx.iter().zip(outputs) {
                parse(c, n, &mut ys)?;
            }
        }
        let n = xs.len() / inputs.len().max(1);
        Ok(Self {
            input_names: inputs.iter().map(|s| s.to_string()).collect(),
            output_names: outputs.iter().map(|s| s.to_string()).collect(),
            x: DMatrix::from_row_slice(n, inputs.len(), &xs),
            y: DMatrix::from_row_slice(n, outputs.len(), &ys),
        })
    }
}
