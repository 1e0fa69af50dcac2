//! Eigendecomposition of symmetric matrices (faer's self-adjoint solver behind nalgebra types).

use crate::NumericsError;
use faer::MatRef;
use nalgebra::{DMatrix, DVector};

/// Eigenvalues (non-decreasing) and eigenvectors (columns) of the symmetric `a` (its lower
/// triangle is read). `what` names the matrix in errors.
///
/// ```
/// use nalgebra::DMatrix;
/// let a = DMatrix::from_row_slice(2, 2, &[2.0, 1.0, 1.0, 2.0]);
/// let e = numerics::SymmetricEigen::new(&a, "a").unwrap();
/// assert!((e.values[0] - 1.0).abs() < 1e-12 && (e.values[1] - 3.0).abs() < 1e-12);
/// let back = &e.vectors * DMatrix::from_diagonal(&e.values) * e.vectors.transpose();
/// assert!((back - a).amax() < 1e-12);
/// ```
#[derive(Debug, Clone)]
pub struct SymmetricEigen {
    /// Eigenvalues, non-decreasing.
    pub values: DVector<f64>,
    /// Orthonormal eigenvectors, one per column, in the order of `values`.
    pub vectors: DMatrix<f64>,
}

impl SymmetricEigen {
    /// Decomposes `a`.
    pub fn new(a: &DMatrix<f64>, what: &str) -> Result<Self, NumericsError> {
        let (n, m) = a.shape();
        if n != m {
            return Err(NumericsError::Dimension {
                what: format!("{what}: columns of a square matrix"),
                expected: n,
                got: m,
            });
        }
        if let Some(index) = a.iter().position(|v| !v.is_finite()) {
            return Err(NumericsError::NonFinite {
                what: what.to_string(),
                index,
            });
        }
        let view = MatRef::from_column_major_slice(a.as_slice(), n, n);
        let evd = view.self_adjoint_eigen(faer::Side::Lower).map_err(|e| {
            NumericsError::NoConvergence {
                what: format!("{what}: symmetric eigendecomposition ({e:?})"),
            }
        })?;
        let (s, u) = (evd.S().column_vector(), evd.U());
        Ok(Self {
            values: DVector::from_fn(n, |i, _| s[i]),
            vectors: DMatrix::from_fn(n, n, |i, j| u[(i, j)]),
        })
    }
}
