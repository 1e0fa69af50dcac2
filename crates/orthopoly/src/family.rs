//! Polynomial families, scaling conventions and the three-term recurrences.

use serde::{Deserialize, Serialize};

/// A classical orthogonal-polynomial family.
///
/// Each family is orthogonal with respect to its own weight on the reference variable `z`:
///
/// | family | classical polynomial | probability measure in `z` |
/// |---|---|---|
/// | `Legendre` | `P_n` | uniform on `[-1, 1]`, density `1/2` |
/// | `Chebyshev` | `T_n` (first kind) | arcsine on `[-1, 1]`, density `1/(π sqrt(1 - z²))` |
/// | `Hermite` | `He_n` (probabilists') | standard normal, density `exp(-z²/2)/sqrt(2π)` |
///
/// ```
/// use orthopoly::Family;
/// assert_eq!(Family::Legendre.classical_norm_squared(2), 1.0 / 5.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Family {
    /// Legendre polynomials `P_n`, orthogonal under the uniform measure.
    Legendre,
    /// Chebyshev polynomials of the first kind `T_n`, orthogonal under the arcsine measure.
    Chebyshev,
    /// Probabilists' Hermite polynomials `He_n`, orthogonal under the standard normal measure.
    Hermite,
}

impl Family {
    /// `E[p_n(Z)²]` of the classical polynomial `p_n` under the family's probability measure:
    /// `1/(2n+1)` (Legendre), `1` for `n = 0` else `1/2` (Chebyshev), `n!` (Hermite).
    ///
    /// Dividing a classical polynomial by the square root of this gives the orthonormal one.
    ///
    /// ```
    /// use orthopoly::Family;
    /// assert_eq!(Family::Chebyshev.classical_norm_squared(0), 1.0);
    /// assert_eq!(Family::Chebyshev.classical_norm_squared(3), 0.5);
    /// assert_eq!(Family::Hermite.classical_norm_squared(4), 24.0);
    /// ```
    pub fn classical_norm_squared(self, n: usize) -> f64 {
        match self {
            Family::Legendre => 1.0 / (2 * n + 1) as f64,
            Family::Chebyshev if n == 0 => 1.0,
            Family::Chebyshev => 0.5,
            Family::Hermite => (1..=n).map(|k| k as f64).product(),
        }
    }

    /// Whether the family lives on the bounded reference interval `[-1, 1]` (Legendre,
    /// Chebyshev) rather than the whole real line (Hermite).
    ///
    /// ```
    /// use orthopoly::Family;
    /// assert!(Family::Legendre.is_bounded());
    /// assert!(!Family::Hermite.is_bounded());
    /// ```
    pub fn is_bounded(self) -> bool {
        !matches!(self, Family::Hermite)
    }

    /// Off-diagonal Jacobi coefficient `b_n` (`n >= 1`) of the orthonormal recurrence
    /// `z φ_n = b_{n+1} φ_{n+1} + b_n φ_{n-1}` (all three families are symmetric, so the
    /// diagonal coefficients vanish).
    fn jacobi_b(self, n: usize) -> f64 {
        let nf = n as f64;
        match self {
            Family::Legendre => nf / (4.0 * nf * nf - 1.0).sqrt(),
            Family::Chebyshev if n == 1 => std::f64::consts::FRAC_1_SQRT_2,
            Family::Chebyshev => 0.5,
            Family::Hermite => nf.sqrt(),
        }
    }
}

/// Scaling of the polynomials.
///
/// ```
/// use orthopoly::{Basis, Family, Normalization};
/// let classical =
///     Basis::with_normalization(Family::Legendre, -1.0, 1.0, 3, Normalization::Classical).unwrap();
/// let orthonormal = Basis::new(Family::Legendre, -1.0, 1.0, 3).unwrap();
/// assert_eq!(classical.eval(1.0).unwrap()[2], 1.0); // P_2(1) = 1
/// assert!((orthonormal.eval(1.0).unwrap()[2] - 5f64.sqrt()).abs() < 1e-14); // sqrt(5) P_2(1)
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Normalization {
    /// Orthonormal under the family's weight normalised to a probability measure on `[a, b]`:
    /// `E[φ_j φ_k] = δ_jk`, `φ_0 = 1`, so the constant coefficient is the field's mean.
    #[default]
    Orthonormal,
    /// The textbook polynomials `P_n`, `T_n`, `He_n` (e.g. `P_n(1) = 1`, leading coefficient
    /// of `He_n` is 1).
    Classical,
}

/// Coefficients `(A_n, C_n)` of `p_{n+1}(z) = A_n z p_n(z) - C_n p_{n-1}(z)`, with `p_0 = 1`.
pub(crate) fn recurrence(family: Family, normalization: Normalization, n: usize) -> (f64, f64) {
    let nf = n as f64;
    match normalization {
        Normalization::Classical => match family {
            Family::Legendre => ((2.0 * nf + 1.0) / (nf + 1.0), nf / (nf + 1.0)),
            Family::Chebyshev if n == 0 => (1.0, 0.0),
            Family::Chebyshev => (2.0, 1.0),
            Family::Hermite => (1.0, nf),
        },
        Normalization::Orthonormal => {
            let b_next = family.jacobi_b(n + 1);
            let b_this = if n == 0 { 0.0 } else { family.jacobi_b(n) };
            (1.0 / b_next, b_this / b_next)
        }
    }
}

/// Values (and, if `derivs` is non-empty, first derivatives) of degrees `0..values.len()` at the
/// reference coordinate `z`; derivatives are with respect to `z`.
pub(crate) fn eval_reference(
    family: Family,
    normalization: Normalization,
    z: f64,
    values: &mut [f64],
    derivs: &mut [f64],
) {
    let with_derivs = !derivs.is_empty();
    let (mut p_prev, mut p) = (0.0, 1.0);
    let (mut d_prev, mut d) = (0.0, 0.0);
    for k in 0..values.len() {
        values[k] = p;
        if with_derivs {
            derivs[k] = d;
        }
        let (a_k, c_k) = recurrence(family, normalization, k);
        let p_next = a_k * z * p - c_k * p_prev;
        // Differentiating the recurrence keeps derivatives exact at z = ±1 (no (1 - z²) division).
        let d_next = a_k * (p + z * d) - c_k * d_prev;
        (p_prev, p) = (p, p_next);
        (d_prev, d) = (d, d_next);
    }
}
