//! The candidate covariates of a record: time, the model inputs, the load (when the record has
//! one, e.g. a gate's head), every other numeric column, and the rate of change per hour of
//! all but time.

use super::MeasuredRecord;
use super::config::LoadSpec;

/// Candidate features derived from a record, in this order: `time_days`, the inputs, the load
/// (if declared), the CSV covariates, then `d_<name>_per_h` of every column but time.
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
    /// The features of `rec` with the optional declared `load`.
    pub fn new(rec: &MeasuredRecord, load: Option<&LoadSpec>) -> Self {
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
        for k in 1..n_base {
            names.push(format!("d_{}_per_h", names[k]));
            cols.push(backward_rate(&t, &cols[k]));
        }
        let load_rate = backward_rate(&t, &load_values);
        Self {
            names,
            cols,
            time_h: t,
            load: load_values,
            load_rate,
            model_columns,
        }
    }

    /// The position of the feature `name`.
    pub fn position(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }
}

fn row(rec: &MeasuredRecord, i: usize) -> Vec<f64> {
    rec.x.row(i).iter().copied().collect()
}
