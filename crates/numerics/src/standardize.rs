//! Per-column affine standardisation `z = (v − mean) / sd`.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Column means and population standard deviations learnt from data; maps a value `v` of
/// column `c` to `(v − mean[c]) / sd[c]`. A column whose spread is rounding of its mean
/// (`sd ≤ 1e-12 max(|mean|, 1)`) is constant and gets `sd = 1`, so it maps to 0 instead of
/// dividing by zero.
///
/// ```
/// use numerics::Standardizer;
/// let m = nalgebra::DMatrix::from_row_slice(2, 2, &[1.0, 5.0, 3.0, 5.0]);
/// let s = Standardizer::fit(&m);
/// assert_eq!((s.mean.clone(), s.sd.clone()), (vec![2.0, 5.0], vec![1.0, 1.0]));
/// let z = s.apply(&m);
/// assert_eq!(z[(1, 0)], 1.0);
/// assert_eq!(s.invert(&z), m);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Standardizer {
    /// Column means, in the data's own units.
    pub mean: Vec<f64>,
    /// Column (population) standard deviations, in the data's own units (1 for a constant
    /// column). Files written before the shared type name it `std`.
    #[serde(alias = "std")]
    pub sd: Vec<f64>,
}

impl Standardizer {
    /// Fits means and population standard deviations of each column of `m`.
    pub fn fit(m: &DMatrix<f64>) -> Self {
        let n = m.nrows().max(1) as f64;
        let mut mean = Vec::with_capacity(m.ncols());
        let mut sd = Vec::with_capacity(m.ncols());
        for c in m.column_iter() {
            let mu = c.iter().sum::<f64>() / n;
            let var = c.iter().map(|v| (v - mu).powi(2)).sum::<f64>() / n;
            let s = var.sqrt();
            mean.push(mu);
            sd.push(if s > 1e-12 * mu.abs().max(1.0) {
                s
            } else {
                1.0
            });
        }
        Self { mean, sd }
    }

    /// Number of columns.
    pub fn len(&self) -> usize {
        self.mean.len()
    }

    /// True when fitted to no columns.
    pub fn is_empty(&self) -> bool {
        self.mean.is_empty()
    }

    /// Standardises one value of column `c`.
    #[inline]
    pub fn apply_value(&self, c: usize, v: f64) -> f64 {
        (v - self.mean[c]) / self.sd[c]
    }

    /// Maps a standardised value of column `c` back to data units.
    #[inline]
    pub fn invert_value(&self, c: usize, z: f64) -> f64 {
        z * self.sd[c] + self.mean[c]
    }

    /// Standardises every column of `m` (which must have [`len`](Self::len) columns).
    pub fn apply(&self, m: &DMatrix<f64>) -> DMatrix<f64> {
        DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| self.apply_value(j, m[(i, j)]))
    }

    /// Inverts [`apply`](Self::apply).
    pub fn invert(&self, z: &DMatrix<f64>) -> DMatrix<f64> {
        DMatrix::from_fn(z.nrows(), z.ncols(), |i, j| self.invert_value(j, z[(i, j)]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn apply_then_invert_is_the_identity(vals in proptest::collection::vec(-1e6..1e6f64, 6..40)) {
            let m = DMatrix::from_column_slice(vals.len() / 2, 2, &vals[..vals.len() / 2 * 2]);
            let s = Standardizer::fit(&m);
            let back = s.invert(&s.apply(&m));
            // two affine maps in f64: a few ulps of the column scale
            for (a, b) in back.iter().zip(m.iter()) {
                prop_assert!((a - b).abs() <= 1e-9 * (1.0 + b.abs()));
            }
        }
    }

    #[test]
    fn old_files_with_std_still_load() {
        let s: Standardizer = serde_json::from_str(r#"{"mean":[1.0],"std":[2.0]}"#).unwrap();
        assert_eq!(s.sd, vec![2.0]);
    }
}
