//! Thin row-major wrappers around faer's matrix multiply.
//!
//! Every buffer in this crate is a dense row-major slice; faer views carry arbitrary strides, so
//! transposes and row blocks of a weight matrix are free views rather than copies.

use crate::float::Float;
use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};

/// A `rows x cols` row-major view of `s`.
#[inline]
pub(crate) fn view<T: Float>(s: &[T], rows: usize, cols: usize) -> MatRef<'_, T> {
    MatRef::from_row_major_slice(&s[..rows * cols], rows, cols)
}

/// A mutable `rows x cols` row-major view of `s`.
#[inline]
pub(crate) fn view_mut<T: Float>(s: &mut [T], rows: usize, cols: usize) -> MatMut<'_, T> {
    MatMut::from_row_major_slice_mut(&mut s[..rows * cols], rows, cols)
}

/// `dst = a * b` (`accum = Replace`) or `dst += a * b` (`accum = Add`).
#[inline]
pub(crate) fn gemm<T: Float>(
    dst: MatMut<'_, T>,
    accum: Accum,
    a: MatRef<'_, T>,
    b: MatRef<'_, T>,
    par: Par,
) {
    matmul(dst, accum, a, b, T::of(1.0), par);
}
