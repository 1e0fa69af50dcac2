//! Small dense linear-algebra helpers: the jittered Cholesky of the `n × n` training covariance
//! (the shared kernel of `numerics`, on faer) and plain-slice routines for the tiny `p × p` GLS
//! normal matrix.

use crate::GpError;
use faer::dyn_stack::MemBuffer;
use faer::{Mat, MatRef, Par};
use numerics::NumericsError;

/// Name of the training covariance in errors.
const TRAINING_COV: &str = "K (training covariance)";

/// Factorises the training covariance `out = L Lᵀ = K + (diag_add + jitter) I` in place with
/// [`numerics::cholesky::cholesky_in_place`] (sequential faer kernel), escalating the jitter
/// along [`numerics::JITTER_LADDER`] (relative to the mean diagonal of `K + diag_add I`).
/// Only the lower triangle of `k` is read; the strict upper triangle of `out` is zeroed.
/// Returns the absolute jitter that was needed (0 if none); past the top of the ladder the
/// error is [`GpError::NotPositiveDefinite`] with the failing pivot.
pub(crate) fn cholesky_with_jitter(
    k: MatRef<'_, f64>,
    diag_add: f64,
    out: &mut Mat<f64>,
    stack_buf: &mut MemBuffer,
) -> Result<f64, GpError> {
    let n = k.nrows().max(1);
    numerics::cholesky::cholesky_in_place(k, diag_add, out, stack_buf, Par::Seq, TRAINING_COV)
        .map_err(|e| match e {
            NumericsError::NotPositiveDefinite {
                index, max_jitter, ..
            } => GpError::NotPositiveDefinite {
                matrix: TRAINING_COV,
                index,
                max_jitter,
            },
            NumericsError::Dimension { expected, got, .. } => GpError::ShapeMismatch {
                name: TRAINING_COV,
                what: "columns",
                expected,
                found: got,
            },
            // (the Cholesky kernel never iterates nor refuses arguments; mapped for completeness)
            NumericsError::Invalid { what, reason } => GpError::OptimizationFailed {
                starts: 0,
                last: format!("{what}: {reason}"),
            },
            NumericsError::NoConvergence { what } => GpError::OptimizationFailed {
                starts: 0,
                last: format!("{what}: did not converge"),
            },
            // (the in-place kernel does not scan for non-finite entries; mapped for completeness)
            NumericsError::NonFinite { index, .. } => {
                let (row, col) = (index % n, index / n);
                GpError::NonFinite {
                    name: TRAINING_COV,
                    row,
                    col,
                    value: if col < k.ncols() {
                        k[(row, col)]
                    } else {
                        f64::NAN
                    },
                }
            }
        })
}

/// In-place Cholesky of a small column-major `p × p` matrix (lower factor, upper zeroed).
/// Returns the failing pivot on breakdown.
pub(crate) fn small_cholesky(a: &mut [f64], p: usize) -> Result<(), usize> {
    for j in 0..p {
        let mut d = a[j + j * p];
        for k in 0..j {
            d -= a[j + k * p] * a[j + k * p];
        }
        if d <= 0.0 || !d.is_finite() {
            return Err(j);
        }
        let d = d.sqrt();
        a[j + j * p] = d;
        for i in j + 1..p {
            let mut s = a[i + j * p];
            for k in 0..j {
                s -= a[i + k * p] * a[j + k * p];
            }
            a[i + j * p] = s / d;
        }
        for i in 0..j {
            a[i + j * p] = 0.0;
        }
    }
    Ok(())
}

/// Solves `L x = b` in place for a small column-major lower-triangular `L` (`p × p`).
pub(crate) fn small_forward_solve(l: &[f64], p: usize, b: &mut [f64]) {
    for i in 0..p {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i + k * p] * b[k];
        }
        b[i] = s / l[i + i * p];
    }
}

/// Solves `Lᵀ x = b` in place for a small column-major lower-triangular `L` (`p × p`).
pub(crate) fn small_backward_solve(l: &[f64], p: usize, b: &mut [f64]) {
    for i in (0..p).rev() {
        let mut s = b[i];
        for k in i + 1..p {
            s -= l[k + i * p] * b[k];
        }
        b[i] = s / l[i + i * p];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indefinite_training_covariance_maps_to_gp_error() {
        // diag(1, -1): pivot 1 fails on every rung of the ladder
        let k = Mat::from_fn(2, 2, |i, j| match (i, j) {
            (0, 0) => 1.0,
            (1, 1) => -1.0,
            _ => 0.0,
        });
        let mut out = Mat::zeros(2, 2);
        let mut buf = MemBuffer::new(numerics::cholesky::scratch(2, Par::Seq));
        let err = cholesky_with_jitter(k.as_ref(), 0.0, &mut out, &mut buf).unwrap_err();
        // mean diagonal 0: the top of the ladder is a zero jitter
        assert_eq!(
            err,
            GpError::NotPositiveDefinite {
                matrix: TRAINING_COV,
                index: 1,
                max_jitter: 0.0,
            }
        );
    }

    #[test]
    fn rank_one_covariance_is_rescued_by_a_reported_jitter() {
        let k = Mat::from_fn(3, 3, |i, j| ((i + 1) * (j + 1)) as f64);
        let mut out = Mat::zeros(3, 3);
        let mut buf = MemBuffer::new(numerics::cholesky::scratch(3, Par::Seq));
        let jitter = cholesky_with_jitter(k.as_ref(), 0.0, &mut out, &mut buf).unwrap();
        let mean_diag = 14.0 / 3.0;
        assert!(jitter > 0.0 && jitter <= 1e-4 * mean_diag, "{jitter}");
        assert_eq!(out[(0, 1)], 0.0); // strict upper triangle zeroed
    }
}
