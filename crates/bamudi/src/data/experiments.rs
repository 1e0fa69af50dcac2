//! Experimental data `{x_e, y_o^e}` (Eq. 13) and its CSV form.

use super::{Empty, Table};
use crate::error::{BamudiError, Result};
use nalgebra::DMatrix;
use ndarray::ArrayView2;
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

    /// The CSV text: a header `input_names..., output_names...` and one row per experiment,
    /// every value printed so that it reads back exactly.
    pub fn to_csv_string(&self) -> String {
        let mut out = self
            .input_names
            .iter()
            .chain(&self.output_names)
            .map(|n| csv_field(n))
            .collect::<Vec<_>>()
            .join(",");
        out.push('\n');
        for i in 0..self.len() {
            // `{:?}` prints the shortest string that round-trips exactly
            let row: Vec<String> = (0..self.x.ncols())
                .map(|j| format!("{:?}", self.x[(i, j)]))
                .chain((0..self.y.ncols()).map(|j| format!("{:?}", self.y[(i, j)])))
                .collect();
            out.push_str(&row.join(","));
            out.push('\n');
        }
        out
    }

    /// Writes [`to_csv_string`](Self::to_csv_string) to `path` atomically (a temporary file in
    /// the same directory, renamed when complete).
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
        super::write_atomic(path, self.to_csv_string().as_bytes())
    }

    /// Reads the columns `inputs` and `outputs` of a CSV file (by header name, any order; other
    /// columns are ignored) with the [`Table`] error policy.
    ///
    /// ```
    /// # use bamudi::Experiments;
    /// let path = std::env::temp_dir().join("bamudi_doc_read.csv");
    /// std::fs::write(&path, "s,p\n1.0,2.0\n3.0,abc\n").unwrap();
    /// let err = Experiments::read_csv(&path, &["p"], &["s"]).unwrap_err().to_string();
    /// assert!(err.contains("line 3") && err.contains("`p`"), "{err}");
    /// ```
    pub fn read_csv(path: &Path, inputs: &[&str], outputs: &[&str]) -> Result<Self> {
        Self::from_table(&Table::read(path)?, inputs, outputs)
    }

    /// The experiments in the named columns of a parsed table.
    pub fn from_table(table: &Table, inputs: &[&str], outputs: &[&str]) -> Result<Self> {
        let x = table.numbers(inputs, Empty::Refuse)?;
        let y = table.numbers(outputs, Empty::Refuse)?;
        Self::from_arrays(
            inputs.iter().map(|s| s.to_string()).collect(),
            outputs.iter().map(|s| s.to_string()).collect(),
            x.view(),
            y.view(),
        )
    }

    /// The experiments from `ndarray` views (rows = experiments), e.g. numpy arrays.
    ///
    /// ```
    /// use bamudi::Experiments;
    /// let x = ndarray::array![[1.0], [2.0]];
    /// let y = ndarray::array![[3.0, 4.0], [5.0, 6.0]];
    /// let e = Experiments::from_arrays(vec!["p".into()], vec!["a".into(), "b".into()], x.view(), y.view()).unwrap();
    /// assert_eq!((e.len(), e.y[(1, 0)]), (2, 5.0));
    /// ```
    pub fn from_arrays(
        input_names: Vec<String>,
        output_names: Vec<String>,
        x: ArrayView2<'_, f64>,
        y: ArrayView2<'_, f64>,
    ) -> Result<Self> {
        let to_matrix =
            |a: ArrayView2<'_, f64>| DMatrix::from_fn(a.nrows(), a.ncols(), |i, j| a[[i, j]]);
        Self::new(input_names, output_names, to_matrix(x), to_matrix(y))
    }
}

/// A CSV field, quoted when it holds a separator, a quote or a line break.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}
