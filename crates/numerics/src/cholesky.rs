//! Cholesky factorisation `A + (d + j) I = L Lᵀ` with a documented diagonal-jitter ladder.
//!
//! A covariance assembled in floating point can be positive definite in exact arithmetic and
//! still fail a Cholesky pivot by rounding. The factorisation then retries with a diagonal
//! jitter `j = r · mean(diag A)` for `r` along [`JITTER_LADDER`] and reports the `j` it needed
//! (never silent: every caller stores or logs it). Past the top of the ladder it is an error
//! naming the failing pivot.
//!
//! Two layers, as in faer itself:
//! * [`cholesky_in_place`]: the kernel, on faer views with caller-owned scratch, so a caller
//!   that factors many matrices of one size (the GP hyper-parameter search) allocates nothing
//!   per factorisation;
//! * [`Cholesky`]: an owned factor built from a `nalgebra` matrix, with the log-determinant and
//!   the quadratic form that Gaussian log densities need.

use crate::NumericsError;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::{LltError, LltRegularization, cholesky_in_place_scratch};
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Mat, MatMut, MatRef, Par};
use nalgebra::DMatrix;

/// Relative diagonal jitters tried in order, each times the mean diagonal. The first (zero)
/// means "no jitter"; the largest (1e-4 of the mean variance) is far below any noise level a
/// user would care about but well above rounding-level negative eigenvalues.
pub const JITTER_LADDER: [f64; 8] = [0.0, 1e-10, 1e-9, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4];

/// Scratch needed by [`cholesky_in_place`] for an `n x n` matrix.
pub fn scratch(n: usize, par: Par) -> StackReq {
    cholesky_in_place_scratch::<f64>(n, par, Default::default())
}

/// Copies `a` into `out` (both `n x n`; only the lower triangle of `a` is read by the
/// factorisation), adds `diag_add + jitter` to the diagonal and factors `out = L Lᵀ` in place,
/// escalating the jitter along [`JITTER_LADDER`]. On success the strict upper triangle of `out`
/// is zeroed and the absolute jitter used (0 if none) is returned. `what` names the matrix in
/// the error. With `par = faer::get_global_parallelism()` and no jitter the factor is bitwise
/// the one of faer's `Mat::llt`.
pub fn cholesky_in_place(
    a: MatRef<'_, f64>,
    diag_add: f64,
    out: &mut Mat<f64>,
    buf: &mut MemBuffer,
    par: Par,
    what: &str,
) -> Result<f64, NumericsError> {
    let n = a.nrows();
    if a.ncols() != n {
        return Err(NumericsError::Dimension {
            what: format!("{what}: columns of a square matrix"),
            expected: n,
            got: a.ncols(),
        });
    }
    let mean_diag = (0..n).map(|i| a[(i, i)]).sum::<f64>() / n.max(1) as f64 + diag_add;
    let mut last_index = 0;
    for rel in JITTER_LADDER {
        let jitter = rel * mean_diag.abs();
        out.resize_with(n, n, |_, _| 0.0);
        out.copy_from(a);
        for i in 0..n {
            out[(i, i)] += diag_add + jitter;
        }
        let stack = MemStack::new(buf);
        let factored = faer::linalg::cholesky::llt::factor::cholesky_in_place(
            out.as_mut(),
            LltRegularization::default(),
            par,
            stack,
            Default::default(),
        );
        match factored {
            Ok(_) => {
                zero_strict_upper(out.as_mut());
                return Ok(jitter);
            }
            Err(LltError::NonPositivePivot { index }) => last_index = index,
        }
    }
    Err(NumericsError::NotPositiveDefinite {
        what: what.to_string(),
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

/// An owned Cholesky factor `A + j I = L Lᵀ` with its log-determinant and the jitter `j`.
///
/// ```
/// use nalgebra::DMatrix;
/// let a = DMatrix::from_row_slice(2, 2, &[4.0, 2.0, 2.0, 3.0]);
/// let c = numerics::Cholesky::new(&a, "example").unwrap();
/// assert!((c.log_det() - 8f64.ln()).abs() < 1e-12);
/// // rᵀ A⁻¹ r for r = (2, 0): A⁻¹ = [[3, -2], [-2, 4]] / 8
/// assert!((c.quad_form(&[2.0, 0.0]).unwrap() - 1.5).abs() < 1e-12);
/// assert_eq!(c.jitter(), 0.0);
/// ```
#[derive(Debug, Clone)]
pub struct Cholesky {
    l: Mat<f64>,
    log_det: f64,
    jitter: f64,
}

impl Cholesky {
    /// Factors the symmetric positive-definite `a` (only its lower triangle is read) with the
    /// jitter ladder and faer's global parallelism. `what` names the matrix in errors.
    pub fn new(a: &DMatrix<f64>, what: &str) -> Result<Self, NumericsError> {
        if let Some(index) = a.iter().position(|v| !v.is_finite()) {
            return Err(NumericsError::NonFinite {
                what: what.to_string(),
                index,
            });
        }
        let (n, m) = a.shape();
        let view = MatRef::from_column_major_slice(a.as_slice(), n, m);
        let par = faer::get_global_parallelism();
        let mut buf = MemBuffer::new(scratch(n, par));
        let mut l = Mat::zeros(0, 0);
        let jitter = cholesky_in_place(view, 0.0, &mut l, &mut buf, par, what)?;
        let log_det = 2.0 * (0..n).map(|i| l[(i, i)].ln()).sum::<f64>();
        Ok(Self { l, log_det, jitter })
    }

    /// Size `n`.
    pub fn size(&self) -> usize {
        self.l.nrows()
    }

    /// `ln |A + j I|`.
    pub fn log_det(&self) -> f64 {
        self.log_det
    }

    /// The absolute diagonal jitter that was added (0 when the first attempt succeeded).
    pub fn jitter(&self) -> f64 {
        self.jitter
    }

    /// `rᵀ (A + j I)⁻¹ r` by one sequential triangular solve (meant to be called inside an
    /// outer parallel loop).
    pub fn quad_form(&self, r: &[f64]) -> Result<f64, NumericsError> {
        let n = self.size();
        if r.len() != n {
            return Err(NumericsError::Dimension {
                what: "vector length vs factor size".into(),
                expected: n,
                got: r.len(),
            });
        }
        let mut z = Mat::from_fn(n, 1, |i, _| r[i]);
        solve_lower_triangular_in_place(self.l.as_ref(), z.as_mut(), Par::Seq);
        Ok((0..n).map(|i| z[(i, 0)] * z[(i, 0)]).sum())
    }

    /// `r_cᵀ (A + j I)⁻¹ r_c` for every column `r_c` of `r` (`n x m`), by one blocked
    /// triangular solve `L Z = R` with faer's global parallelism. Equal to [`quad_form`] per
    /// column up to round-off (the blocked solve sums in another order), and much cheaper per
    /// column than `m` calls of it: a single-vector solve streams all of `L` from memory
    /// (98 MB at `n` = 3500) for `n²` flops, the blocked one streams it once for all columns.
    ///
    /// [`quad_form`]: Self::quad_form
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let a = DMatrix::from_row_slice(2, 2, &[4.0, 2.0, 2.0, 3.0]);
    /// let c = numerics::Cholesky::new(&a, "example").unwrap();
    /// let r = DMatrix::from_column_slice(2, 2, &[2.0, 0.0, 0.0, 1.0]);
    /// let q = c.quad_forms(&r).unwrap();
    /// assert!((q[0] - c.quad_form(&[2.0, 0.0]).unwrap()).abs() < 1e-12);
    /// assert!((q[1] - 0.5).abs() < 1e-12); // A⁻¹[1][1] = 4 / 8
    /// ```
    pub fn quad_forms(&self, r: &DMatrix<f64>) -> Result<Vec<f64>, NumericsError> {
        let n = self.size();
        if r.nrows() != n {
            return Err(NumericsError::Dimension {
                what: "rows of the vectors vs factor size".into(),
                expected: n,
                got: r.nrows(),
            });
        }
        let mut z = Mat::from_fn(n, r.ncols(), |i, j| r[(i, j)]);
        let par = faer::get_global_parallelism();
        solve_lower_triangular_in_place(self.l.as_ref(), z.as_mut(), par);
        Ok((0..r.ncols())
            .map(|j| z.col(j).iter().map(|v| v * v).sum())
            .collect())
    }

    /// `(A + j I)⁻¹ B` for the columns of `b` (two triangular solves, faer's global
    /// parallelism).
    pub fn solve(&self, b: &DMatrix<f64>) -> Result<DMatrix<f64>, NumericsError> {
        let n = self.size();
        if b.nrows() != n {
            return Err(NumericsError::Dimension {
                what: "rows of the right-hand side vs factor size".into(),
                expected: n,
                got: b.nrows(),
            });
        }
        let mut z = Mat::from_fn(n, b.ncols(), |i, j| b[(i, j)]);
        let par = faer::get_global_parallelism();
        solve_lower_triangular_in_place(self.l.as_ref(), z.as_mut(), par);
        faer::linalg::triangular_solve::solve_upper_triangular_in_place(
            self.l.transpose(),
            z.as_mut(),
            par,
        );
        Ok(DMatrix::from_fn(n, b.ncols(), |i, j| z[(i, j)]))
    }

    /// The lower factor `L` as a nalgebra matrix (a copy).
    pub fn l(&self) -> DMatrix<f64> {
        let n = self.size();
        DMatrix::from_fn(n, n, |i, j| self.l[(i, j)])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spd(n: usize) -> DMatrix<f64> {
        let m = DMatrix::from_fn(n, n, |i, j| ((i * 7 + j * 13) % 11) as f64 / 11.0 - 0.5);
        &m * m.transpose() + DMatrix::identity(n, n) * 0.1
    }

    #[test]
    fn owned_factor_is_bitwise_faers_llt() {
        // the engine's Module-3 numbers were produced by `Mat::llt`; the shared kernel must give
        // the same bits, not merely close ones
        let a = spd(150);
        let ours = Cholesky::new(&a, "a").unwrap();
        let f = Mat::from_fn(150, 150, |i, j| a[(i, j)]);
        let theirs = f.llt(faer::Side::Lower).unwrap();
        for j in 0..150 {
            for i in 0..150 {
                assert_eq!(ours.l[(i, j)].to_bits(), theirs.L()[(i, j)].to_bits());
            }
        }
        assert_eq!(ours.jitter(), 0.0);
    }

    #[test]
    fn solve_inverts_the_matrix() {
        let a = spd(20);
        let c = Cholesky::new(&a, "a").unwrap();
        let b = DMatrix::from_fn(20, 3, |i, j| (i * 3 + j) as f64 / 10.0 - 1.0);
        let x = c.solve(&b).unwrap();
        // well conditioned (eigenvalues >= 0.1): round-off of a 20 x 20 solve
        assert!((&a * x - b).amax() < 1e-10);
    }

    #[test]
    fn batched_quadratic_forms_match_one_solve_per_vector_and_the_inverse() {
        let a = spd(40);
        let c = Cholesky::new(&a, "a").unwrap();
        let r = DMatrix::from_fn(40, 9, |i, j| ((i * 5 + j * 11) % 17) as f64 / 17.0 - 0.5);
        let batched = c.quad_forms(&r).unwrap();
        let inverse = a.clone().try_inverse().unwrap();
        for (j, q) in batched.iter().enumerate() {
            let col: Vec<f64> = r.column(j).iter().copied().collect();
            let one = c.quad_form(&col).unwrap();
            let direct = (r.column(j).transpose() * &inverse * r.column(j))[(0, 0)];
            // the same triangular system summed in another order: relative round-off of a
            // 40 x 40 solve with condition number <= 1e4 (eigenvalues >= 0.1, norm <= ~1e3)
            assert!(
                (q - one).abs() <= 1e-10 * one.abs().max(1.0),
                "{q} vs {one}"
            );
            assert!(
                (q - direct).abs() <= 1e-8 * direct.abs().max(1.0),
                "{q} vs {direct}"
            );
        }
        let wrong = DMatrix::zeros(39, 2);
        assert!(matches!(
            c.quad_forms(&wrong),
            Err(NumericsError::Dimension {
                expected: 40,
                got: 39,
                ..
            })
        ));
    }

    #[test]
    fn jitter_rescues_a_rounding_level_semidefinite_matrix_and_is_reported() {
        // rank one: exactly singular, so the first attempts fail and a small jitter is needed
        let v = DMatrix::from_fn(5, 1, |i, _| 1.0 + i as f64);
        let a = &v * v.transpose();
        let c = Cholesky::new(&a, "rank one").unwrap();
        let mean_diag = a.diagonal().mean();
        assert!(c.jitter() > 0.0 && c.jitter() <= 1e-4 * mean_diag);
    }

    #[test]
    fn indefinite_matrix_is_an_error_naming_it() {
        let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]);
        let e = Cholesky::new(&a, "the test matrix").unwrap_err();
        assert!(e.to_string().contains("the test matrix"), "{e}");
        assert!(matches!(
            e,
            NumericsError::NotPositiveDefinite { index: 1, .. }
        ));
    }

    #[test]
    fn non_finite_input_is_refused() {
        let a = DMatrix::from_row_slice(1, 1, &[f64::NAN]);
        assert!(matches!(
            Cholesky::new(&a, "m"),
            Err(NumericsError::NonFinite { index: 0, .. })
        ));
    }
}
