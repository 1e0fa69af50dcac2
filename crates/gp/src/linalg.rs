//! Small dense linear-algebra helpers on top of faer (large `n × n` work) and plain slices
//! (the tiny `p × p` GLS normal matrix).

use crate::GpError;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{LltRegularization, cholesky_in_place};
use faer::{Mat, MatMut, MatRef, Par};

/// Relative diagonal jitters tried, in order, when the training covariance is not numerically
/// positive definite. Each is multiplied by the mean diagonal of `K`. The first (zero) means
/// "no jitter"; the largest (1e-4 of the mean variance) is far below any noise level a user
/// would care about but well above rounding-level negative eigenvalues.
pub(crate) const JITTER_LADDER: [f64; 8] = [0.0, 1e-10, 1e-9, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4];

/// Copies the lower triangle of `k` into `out`, adds `diag_add + jitter` on the diagonal and
/// factorises `out = L Lᵀ` in place, escalating the jitter along [`JITTER_LADDER`].
/// Returns the absolute jitter that was needed (0 if none).
pub(crate) fn cholesky_with_jitter(
    k: MatRef<'_, f64>,
    diag_add: f64,
    out: &mut Mat<f64>,
    stack_buf: &mut MemBuffer,
) -> Result<f64, GpError> {
    let n = k.nrows();
    let mean_diag = (0..n).map(|i| k[(i, i)]).sum::<f64>() / n as f64 + diag_add;
    let mut last_index = 0;
    for rel in JITTER_LADDER {
        let jitter = rel * mean_diag.abs();
        out.copy_from(k);
        for i in 0..n {
            out[(i, i)] += diag_add + jitter;
        }
        let stack = MemStack::new(stack_buf);
        match cholesky_in_place(
            out.as_mut(),
            LltRegularization::default(),
            Par::Seq,
            stack,
            Default::default(),
        ) {
            Ok(_) => {
                zero_strict_upper(out.as_mut());
                return Ok(jitter);
            }
            Err(faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index }) => {
                last_index = index;
            }
        }
    }
    Err(GpError::NotPositiveDefinite {
        matrix: "K (training covariance)",
        index: last_index,
        max_jitter: JITTER_LADDER[JITTER_LADDER.len() - 1] * mean_diag.abs(),
    })
}

/// Sets the strict upper triangle to zero so the factor can be used as a dense triangle.
fn zero_strict_upper(mut m: MatMut<'_, f64>) {
    let n = m.nrows();
    for j in 1..n {
        for i in 0..j {
            m[(i, j)] = 0.0;
        }
    }
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
