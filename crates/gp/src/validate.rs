//! Input validation shared by fitting and prediction.

use crate::GpError;
use nalgebra::DMatrix;

/// Checks training data: non-empty, `y.len() == x.nrows()`, all finite.
pub(crate) fn check_training(x: &DMatrix<f64>, y: &[f64]) -> Result<(), GpError> {
    check_matrix(x, "x")?;
    check_per_row(x, y, "y")
}

/// Checks values `v` (named `name`) given one per row of `x`: non-empty, as many as rows, all
/// finite.
pub(crate) fn check_per_row(
    x: &DMatrix<f64>,
    v: &[f64],
    name: &'static str,
) -> Result<(), GpError> {
    if v.is_empty() {
        return Err(GpError::EmptyData { name });
    }
    if v.len() != x.nrows() {
        return Err(GpError::ShapeMismatch {
            name,
            what: "entries (one per row of x)",
            expected: x.nrows(),
            found: v.len(),
        });
    }
    if let Some((row, &value)) = v.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(GpError::NonFinite {
            name,
            row,
            col: 0,
            value,
        });
    }
    Ok(())
}

/// Checks a point set: non-empty, all finite.
pub(crate) fn check_matrix(x: &DMatrix<f64>, name: &'static str) -> Result<(), GpError> {
    if x.nrows() == 0 || x.ncols() == 0 {
        return Err(GpError::EmptyData { name });
    }
    for col in 0..x.ncols() {
        for row in 0..x.nrows() {
            let value = x[(row, col)];
            if !value.is_finite() {
                return Err(GpError::NonFinite {
                    name,
                    row,
                    col,
                    value,
                });
            }
        }
    }
    Ok(())
}

/// Checks a prediction point set against the training dimension.
pub(crate) fn check_points(
    x: &DMatrix<f64>,
    dim: usize,
    name: &'static str,
) -> Result<(), GpError> {
    if x.ncols() != dim && x.nrows() > 0 {
        return Err(GpError::ShapeMismatch {
            name,
            what: "columns",
            expected: dim,
            found: x.ncols(),
        });
    }
    check_matrix(x, name)
}
