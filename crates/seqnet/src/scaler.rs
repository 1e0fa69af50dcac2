//! Per-column standardisation stored with the model.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Column means and standard deviations learned from training data; maps a column `v` to
/// `(v - mean) / std`. A constant column gets `std = 1`, so it maps to 0 instead of dividing
/// by zero.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Standardizer {
    /// Column means, in the data's own units.
    pub mean: Vec<f64>,
    /// Column (population) standard deviations, in the data's own units.
    pub std: Vec<f64>,
}

impl Standardizer {
    /// Fits means and population standard deviations of each column of `m`.
    ///
    /// ```
    /// let m = nalgebra::DMatrix::from_row_slice(2, 2, &[1.0, 5.0, 3.0, 5.0]);
    /// let s = seqnet::Standardizer::fit(&m);
    /// assert_eq!(s.mean, vec![2.0, 5.0]);
    /// assert_eq!(s.std, vec![1.0, 1.0]); // second column is constant -> 1
    /// ```
    pub fn fit(m: &DMatrix<f64>) -> Self {
        let n = m.nrows().max(1) as f64;
        let mut mean = Vec::with_capacity(m.ncols());
        let mut std = Vec::with_capacity(m.ncols());
        for c in m.column_iter() {
            let mu = c.iter().sum::<f64>() / n;
            let var = c.iter().map(|v| (v - mu).powi(2)).sum::<f64>() / n;
            let sd = var.sqrt();
            mean.push(mu);
            // Relative threshold: a column whose spread is round-off of its mean is constant.
            std.push(if sd > 1e-12 * mu.abs().max(1.0) {
                sd
            } else {
                1.0
            });
        }
        Self { mean, std }
    }

    /// Standardises `m` into a row-major buffer (rows = samples) of the kernel's float type.
    pub(crate) fn to_row_major<T: crate::Float>(&self, m: &DMatrix<f64>) -> Vec<T> {
        let mut out = Vec::with_capacity(m.len());
        for r in 0..m.nrows() {
            for c in 0..m.ncols() {
                out.push(T::of((m[(r, c)] - self.mean[c]) / self.std[c]));
            }
        }
        out
    }

    /// Maps a standardised value of column `c` back to data units.
    #[inline]
    pub(crate) fn inverse(&self, c: usize, v: f64) -> f64 {
        v * self.std[c] + self.mean[c]
    }
}
