//! Data plumbing shared by fitting, prediction and the hyper-parameter search: argument
//! checks, seeded splits, row selection and the standardised row-major buffers the kernels
//! read.

use crate::error::SeqError;
use crate::float::Float;
use nalgebra::DMatrix;
use numerics::Standardizer;
use rand::{RngExt, SeedableRng, rngs::StdRng};

/// Checks a data matrix's shape and finiteness; errors name the argument, row and column.
pub(crate) fn check_matrix(
    what: &'static str,
    m: &DMatrix<f64>,
    rows: Option<usize>,
    cols: usize,
) -> Result<(), SeqError> {
    if m.ncols() != cols || rows.is_some_and(|r| r != m.nrows()) || m.nrows() == 0 {
        return Err(SeqError::Shape {
            what,
            expected: format!(
                "{} x {cols}",
                rows.map_or("n >= 1".to_string(), |r| r.to_string())
            ),
            found: format!("{} x {}", m.nrows(), m.ncols()),
        });
    }
    for c in 0..m.ncols() {
        for r in 0..m.nrows() {
            let v = m[(r, c)];
            if !v.is_finite() {
                return Err(SeqError::NonFinite {
                    what,
                    row: r,
                    col: c,
                    value: v,
                });
            }
        }
    }
    Ok(())
}

/// Fisher-Yates shuffle driven by the crate's seeded generator.
pub(crate) fn shuffle(v: &mut [usize], rng: &mut StdRng) {
    for i in (1..v.len()).rev() {
        let j = rng.random_range(0..=i);
        v.swap(i, j);
    }
}

/// Seeded split of `0..n` into (train, validation) row indices.
pub(crate) fn split_indices(
    n: usize,
    fraction: f64,
    seed: u64,
) -> Result<(Vec<usize>, Vec<usize>), SeqError> {
    let mut idx: Vec<usize> = (0..n).collect();
    if fraction == 0.0 {
        return Ok((idx, Vec::new()));
    }
    // A separate stream from the shuffles and the init, so changing epochs does not move the split.
    let mut rng = StdRng::seed_from_u64(seed ^ 0x5EED_5E11_7000_0001);
    shuffle(&mut idx, &mut rng);
    let n_val = ((n as f64) * fraction).round() as usize;
    if n_val == 0 || n_val >= n {
        return Err(SeqError::NotEnoughData {
            reason: format!(
                "validation fraction {fraction} of {n} samples leaves {n_val} for validation"
            ),
        });
    }
    let val = idx.split_off(n - n_val);
    Ok((idx, val))
}

/// Rows `idx` of `m` as a new matrix.
pub(crate) fn select_rows(m: &DMatrix<f64>, idx: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(idx.len(), m.ncols(), |r, c| m[(idx[r], c)])
}

/// `m` standardised by `s` into a row-major buffer (rows = samples) of the kernel's float type.
pub(crate) fn to_row_major<T: Float>(s: &Standardizer, m: &DMatrix<f64>) -> Vec<T> {
    let mut out = Vec::with_capacity(m.len());
    for r in 0..m.nrows() {
        for c in 0..m.ncols() {
            out.push(T::of(s.apply_value(c, m[(r, c)])));
        }
    }
    out
}
