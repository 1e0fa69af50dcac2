//! The [`Basis`] type: a family of polynomials on a physical interval `[a, b]`.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::OrthoError;
use crate::family::{Family, Normalization, eval_reference, recurrence};
use crate::quadrature::{gauss_chebyshev, gauss_hermite_prob, gauss_legendre};
use crate::validate::{check_finite_slice, check_interval, check_order};

/// Polynomials of degrees `0..n_terms` of one [`Family`] on the physical interval `[a, b]`.
///
/// Points `t` (physical units, e.g. inches along the quoin) map to the reference variable
/// `z = (t - (a+b)/2) / ((b-a)/2)`. For Legendre and Chebyshev this sends `[a, b]` onto
/// `[-1, 1]`; for Hermite it means `z ~ N(0, 1)` corresponds to `t ~ N((a+b)/2, ((b-a)/2)²)`,
/// i.e. `a` and `b` sit one standard deviation either side of the mean.
///
/// The default ([`Basis::new`]) is [`Normalization::Orthonormal`]. Derivatives are with respect
/// to `t`, so they carry units of 1/(unit of t) (e.g. per inch).
///
/// ```
/// use orthopoly::{Basis, Family};
/// let basis = Basis::new(Family::Legendre, 0.0, 762.0, 6).unwrap();
/// let l = basis.matrix(&[0.0, 381.0, 762.0]).unwrap();
/// assert_eq!(l.shape(), (3, 6));
/// assert_eq!(l[(1, 0)], 1.0); // φ_0 = 1
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RawBasis")]
pub struct Basis {
    family: Family,
    a: f64,
    b: f64,
    n_terms: usize,
    normalization: Normalization,
}

/// Unvalidated mirror of [`Basis`], so deserialisation re-runs the constructor's checks.
#[derive(Deserialize)]
struct RawBasis {
    family: Family,
    a: f64,
    b: f64,
    n_terms: usize,
    normalization: Normalization,
}

impl TryFrom<RawBasis> for Basis {
    type Error = OrthoError;
    fn try_from(raw: RawBasis) -> Result<Self, OrthoError> {
        Basis::with_normalization(raw.family, raw.a, raw.b, raw.n_terms, raw.normalization)
    }
}

impl Basis {
    /// Orthonormal basis of degrees `0..n_terms` of `family` on `[a, b]`.
    ///
    /// Errors: `n_terms == 0`, non-finite `a`/`b`, or `a >= b`.
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// let basis = Basis::new(Family::Chebyshev, -2.0, 2.0, 4).unwrap();
    /// assert_eq!(basis.n_terms(), 4);
    /// assert!(Basis::new(Family::Chebyshev, 2.0, 2.0, 4).is_err());
    /// ```
    pub fn new(family: Family, a: f64, b: f64, n_terms: usize) -> Result<Self, OrthoError> {
        Self::with_normalization(family, a, b, n_terms, Normalization::Orthonormal)
    }

    /// Basis with an explicit [`Normalization`].
    ///
    /// ```
    /// use orthopoly::{Basis, Family, Normalization};
    /// let he = Basis::with_normalization(Family::Hermite, -1.0, 1.0, 4, Normalization::Classical)
    ///     .unwrap();
    /// // He_3(z) = z³ - 3z at z = 2
    /// assert_eq!(he.eval(2.0).unwrap()[3], 2.0);
    /// ```
    pub fn with_normalization(
        family: Family,
        a: f64,
        b: f64,
        n_terms: usize,
        normalization: Normalization,
    ) -> Result<Self, OrthoError> {
        check_order("n_terms", n_terms)?;
        check_interval(a, b)?;
        Ok(Self {
            family,
            a,
            b,
            n_terms,
            normalization,
        })
    }

    /// The polynomial family.
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// assert_eq!(Basis::new(Family::Hermite, 0.0, 1.0, 2).unwrap().family(), Family::Hermite);
    /// ```
    pub fn family(&self) -> Family {
        self.family
    }

    /// The physical interval `(a, b)`.
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// assert_eq!(Basis::new(Family::Legendre, 0.0, 762.0, 6).unwrap().interval(), (0.0, 762.0));
    /// ```
    pub fn interval(&self) -> (f64, f64) {
        (self.a, self.b)
    }

    /// Number of terms `K` (degrees `0..K`).
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// assert_eq!(Basis::new(Family::Legendre, 0.0, 1.0, 6).unwrap().n_terms(), 6);
    /// ```
    pub fn n_terms(&self) -> usize {
        self.n_terms
    }

    /// The scaling convention.
    ///
    /// ```
    /// use orthopoly::{Basis, Family, Normalization};
    /// let basis = Basis::new(Family::Legendre, 0.0, 1.0, 6).unwrap();
    /// assert_eq!(basis.normalization(), Normalization::Orthonormal);
    /// ```
    pub fn normalization(&self) -> Normalization {
        self.normalization
    }

    /// Maps a physical point `t` to the reference variable `z = (t - (a+b)/2) / ((b-a)/2)`.
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// let basis = Basis::new(Family::Legendre, 0.0, 762.0, 6).unwrap();
    /// assert_eq!(basis.to_reference(0.0), -1.0);
    /// assert_eq!(basis.to_reference(381.0), 0.0);
    /// ```
    pub fn to_reference(&self, t: f64) -> f64 {
        (t - self.center()) / self.half_width()
    }

    /// Inverse of [`Basis::to_reference`]: `t = (a+b)/2 + z (b-a)/2`.
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// let basis = Basis::new(Family::Legendre, 0.0, 762.0, 6).unwrap();
    /// assert_eq!(basis.from_reference(1.0), 762.0);
    /// ```
    pub fn from_reference(&self, z: f64) -> f64 {
        self.center() + z * self.half_width()
    }

    /// Values of all `K` polynomials at the physical point `t`.
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// let basis = Basis::new(Family::Legendre, 0.0, 2.0, 3).unwrap();
    /// let v = basis.eval(2.0).unwrap(); // z = 1
    /// assert!((v[1] - 3f64.sqrt()).abs() < 1e-15);
    /// ```
    pub fn eval(&self, t: f64) -> Result<Vec<f64>, OrthoError> {
        let mut values = vec![0.0; self.n_terms];
        self.eval_into(t, &mut values)?;
        Ok(values)
    }

    /// In-place version of [`Basis::eval`]: writes the `K` values into `values`.
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// let basis = Basis::new(Family::Hermite, -1.0, 1.0, 3).unwrap();
    /// let mut v = [0.0; 3];
    /// basis.eval_into(0.0, &mut v).unwrap();
    /// assert!((v[2] + 1.0 / 2f64.sqrt()).abs() < 1e-15); // He_2(0)/sqrt(2!) = -1/sqrt(2)
    /// ```
    pub fn eval_into(&self, t: f64, values: &mut [f64]) -> Result<(), OrthoError> {
        self.check_len("values", values.len())?;
        let z = self.checked_reference("t", 0, t)?;
        eval_reference(self.family, self.normalization, z, values, &mut []);
        Ok(())
    }

    /// Values and first derivatives `d/dt` (units 1/(unit of t)) of all `K` polynomials at `t`.
    ///
    /// ```
    /// use orthopoly::{Basis, Family, Normalization};
    /// let basis =
    ///     Basis::with_normalization(Family::Chebyshev, 0.0, 2.0, 3, Normalization::Classical)
    ///         .unwrap();
    /// let (v, d) = basis.eval_with_derivatives(2.0).unwrap(); // z = 1, dz/dt = 1
    /// assert_eq!(v[2], 1.0); // T_2(1)
    /// assert_eq!(d[2], 4.0); // T_2'(1) = 4
    /// ```
    pub fn eval_with_derivatives(&self, t: f64) -> Result<(Vec<f64>, Vec<f64>), OrthoError> {
        let mut values = vec![0.0; self.n_terms];
        let mut derivs = vec![0.0; self.n_terms];
        self.eval_with_derivatives_into(t, &mut values, &mut derivs)?;
        Ok((values, derivs))
    }

    /// In-place version of [`Basis::eval_with_derivatives`].
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// let basis = Basis::new(Family::Legendre, 0.0, 762.0, 2).unwrap();
    /// let (mut v, mut d) = ([0.0; 2], [0.0; 2]);
    /// basis.eval_with_derivatives_into(100.0, &mut v, &mut d).unwrap();
    /// // φ_1 = sqrt(3) z, dz/dt = 2/762 per inch
    /// assert!((d[1] - 3f64.sqrt() * 2.0 / 762.0).abs() < 1e-15);
    /// ```
    pub fn eval_with_derivatives_into(
        &self,
        t: f64,
        values: &mut [f64],
        derivs: &mut [f64],
    ) -> Result<(), OrthoError> {
        self.check_len("values", values.len())?;
        self.check_len("derivs", derivs.len())?;
        let z = self.checked_reference("t", 0, t)?;
        eval_reference(self.family, self.normalization, z, values, derivs);
        // d/dt = (dz/dt) d/dz with dz/dt = 1/half_width (divide, exactly as `derivative_matrix`).
        let half_width = self.half_width();
        derivs.iter_mut().for_each(|d| *d /= half_width);
        Ok(())
    }

    /// The `N x K` basis matrix `L(d)` of Eq. 15: row `i` holds the `K` polynomials at
    /// `points[i]`.
    ///
    /// Errors: a non-finite point, or (Legendre, Chebyshev) a point outside `[a, b]` beyond a
    /// round-off tolerance of `1e-12 · max(|a|, |b|, b - a)`.
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// let basis = Basis::new(Family::Legendre, 0.0, 762.0, 6).unwrap();
    /// let d: Vec<f64> = (0..509).map(|i| 762.0 * i as f64 / 508.0).collect();
    /// let l = basis.matrix(&d).unwrap();
    /// assert_eq!(l.shape(), (509, 6));
    /// assert!(basis.matrix(&[800.0]).is_err()); // beyond the quoin height
    /// ```
    pub fn matrix(&self, points: &[f64]) -> Result<DMatrix<f64>, OrthoError> {
        let z = self.reference_points(points)?;
        let mut values = DMatrix::zeros(points.len(), self.n_terms);
        self.fill_columns(&z, &mut values, None);
        Ok(values)
    }

    /// The `N x K` matrix of first derivatives `d/dt` (units 1/(unit of t)) at `points`.
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// let basis = Basis::new(Family::Legendre, -1.0, 1.0, 3).unwrap();
    /// let dl = basis.derivative_matrix(&[0.5]).unwrap();
    /// assert_eq!(dl[(0, 0)], 0.0);
    /// assert!((dl[(0, 2)] - 5f64.sqrt() * 1.5).abs() < 1e-14); // sqrt(5) · 3z at z = 0.5
    /// ```
    pub fn derivative_matrix(&self, points: &[f64]) -> Result<DMatrix<f64>, OrthoError> {
        let z = self.reference_points(points)?;
        let mut values = DMatrix::zeros(points.len(), self.n_terms);
        let mut derivs = DMatrix::zeros(points.len(), self.n_terms);
        self.fill_columns(&z, &mut values, Some(&mut derivs));
        derivs /= self.half_width();
        Ok(derivs)
    }

    /// Least-squares coefficients `c` minimising `Σ_i (Σ_k c_k φ_k(points[i]) - values[i])²`.
    ///
    /// Solved by Householder QR of the basis matrix after an SVD rank check (never the normal
    /// equations, whose condition number is the square). Errors if lengths differ, inputs are non-finite, or the points do not
    /// determine all `K` coefficients ([`OrthoError::RankDeficient`], e.g. fewer distinct
    /// points than terms). The fit is unweighted; for the continuous `L²` projection use
    /// [`Basis::probability_quadrature`] nodes as the points.
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// let basis = Basis::new(Family::Legendre, 0.0, 762.0, 3).unwrap();
    /// let d: Vec<f64> = (0..50).map(|i| 762.0 * i as f64 / 49.0).collect();
    /// let force: Vec<f64> = d.iter().map(|t| 10.0 + 0.5 * t).collect(); // lbf/in
    /// let c = basis.project(&d, &force).unwrap();
    /// assert!((c[0] - (10.0 + 0.5 * 381.0)).abs() < 1e-9); // φ_0 coefficient = mean
    /// assert!(c[2].abs() < 1e-9);
    /// ```
    pub fn project(&self, points: &[f64], values: &[f64]) -> Result<Vec<f64>, OrthoError> {
        if values.len() != points.len() {
            return Err(OrthoError::LengthMismatch {
                name: "values",
                expected: points.len(),
                found: values.len(),
            });
        }
        check_finite_slice("values", values)?;
        let l = self.matrix(points)?;
        let rank_deficient = |rank| OrthoError::RankDeficient {
            rank,
            n_terms: self.n_terms,
            n_points: points.len(),
        };
        if points.len() < self.n_terms {
            return Err(rank_deficient(points.len()));
        }
        // Rank from the singular values, with numpy.linalg.lstsq's cut-off: singular values
        // below max(N, K)·eps·s_max are indistinguishable from zero at double precision.
        let singular = l.singular_values();
        let cutoff = points.len().max(self.n_terms) as f64 * f64::EPSILON * singular.max();
        let rank = singular.iter().filter(|&&s| s > cutoff).count();
        if rank < self.n_terms {
            return Err(rank_deficient(rank));
        }
        // Full column rank: Householder QR is backward stable (nalgebra's SVD vectors are
        // not accurate enough for a solve; its singular values are fine for the rank test).
        let qr = l.qr();
        let mut qt_y = DVector::from_column_slice(values);
        qr.q_tr_mul(&mut qt_y);
        let mut coefficients = qt_y.rows(0, self.n_terms).into_owned();
        if !qr.r().solve_upper_triangular_mut(&mut coefficients) {
            return Err(rank_deficient(rank));
        }
        Ok(coefficients.iter().copied().collect())
    }

    /// Evaluates the expansion `Σ_k coefficients[k] φ_k(t)` at every point (Eq. 15 with fixed
    /// `α`).
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// let basis = Basis::new(Family::Legendre, 0.0, 762.0, 2).unwrap();
    /// let f = basis.reconstruct(&[2.0, 0.0], &[0.0, 500.0]).unwrap();
    /// assert_eq!(f, vec![2.0, 2.0]);
    /// ```
    pub fn reconstruct(
        &self,
        coefficients: &[f64],
        points: &[f64],
    ) -> Result<Vec<f64>, OrthoError> {
        self.check_len("coefficients", coefficients.len())?;
        check_finite_slice("coefficients", coefficients)?;
        let l = self.matrix(points)?;
        let field = l * DVector::from_column_slice(coefficients);
        Ok(field.iter().copied().collect())
    }

    /// An `n`-point Gauss rule for the basis's own probability measure, in physical
    /// coordinates: returns `(nodes, weights)` with weights summing to 1, exact for
    /// polynomials of degree `<= 2n - 1`, so `Σ_i w_i φ_j(t_i) φ_k(t_i) = δ_jk` whenever
    /// `j + k <= 2n - 1` (orthonormal basis).
    ///
    /// Legendre: Gauss-Legendre on `[a, b]` divided by `b - a`; Chebyshev: Gauss-Chebyshev
    /// (weights `1/n`); Hermite: Gauss-Hermite mapped to `N((a+b)/2, ((b-a)/2)²)`.
    ///
    /// ```
    /// use orthopoly::{Basis, Family};
    /// let basis = Basis::new(Family::Hermite, 90.0, 110.0, 4).unwrap(); // N(100, 10²)
    /// let (t, w) = basis.probability_quadrature(3).unwrap();
    /// let var: f64 = t.iter().zip(&w).map(|(t, w)| w * (t - 100.0).powi(2)).sum();
    /// assert!((var - 100.0).abs() < 1e-10);
    /// ```
    pub fn probability_quadrature(&self, n: usize) -> Result<(Vec<f64>, Vec<f64>), OrthoError> {
        let (nodes, mut weights) = match self.family {
            Family::Legendre => gauss_legendre(n, self.a, self.b)?,
            Family::Chebyshev => gauss_chebyshev(n, self.a, self.b)?,
            Family::Hermite => {
                let (z, w) = gauss_hermite_prob(n)?;
                (z.iter().map(|&z| self.from_reference(z)).collect(), w)
            }
        };
        let total = match self.family {
            Family::Legendre => self.b - self.a,
            Family::Chebyshev => std::f64::consts::PI,
            Family::Hermite => (2.0 * std::f64::consts::PI).sqrt(),
        };
        weights.iter_mut().for_each(|w| *w /= total);
        Ok((nodes, weights))
    }

    fn center(&self) -> f64 {
        0.5 * (self.a + self.b)
    }

    fn half_width(&self) -> f64 {
        0.5 * (self.b - self.a)
    }

    fn check_len(&self, name: &'static str, found: usize) -> Result<(), OrthoError> {
        if found == self.n_terms {
            Ok(())
        } else {
            Err(OrthoError::LengthMismatch {
                name,
                expected: self.n_terms,
                found,
            })
        }
    }

    /// Validates one physical point and maps it to `z`.
    fn checked_reference(
        &self,
        name: &'static str,
        index: usize,
        t: f64,
    ) -> Result<f64, OrthoError> {
        if !t.is_finite() {
            return Err(OrthoError::NonFinite {
                name,
                index,
                value: t,
            });
        }
        if self.family.is_bounded() {
            // Round-off slack so that computed grids such as 762·i/508 are accepted.
            let tol = 1e-12 * self.a.abs().max(self.b.abs()).max(self.b - self.a);
            if t < self.a - tol || t > self.b + tol {
                return Err(OrthoError::OutOfInterval {
                    index,
                    point: t,
                    a: self.a,
                    b: self.b,
                });
            }
        }
        Ok(self.to_reference(t))
    }

    fn reference_points(&self, points: &[f64]) -> Result<Vec<f64>, OrthoError> {
        points
            .iter()
            .enumerate()
            .map(|(i, &t)| self.checked_reference("points", i, t))
            .collect()
    }

    /// Runs the three-term recurrence column by column (contiguous in column-major storage),
    /// optionally with `d/dz` derivatives.
    fn fill_columns(
        &self,
        z: &[f64],
        values: &mut DMatrix<f64>,
        derivs: Option<&mut DMatrix<f64>>,
    ) {
        values.column_mut(0).fill(1.0);
        if self.n_terms == 1 {
            return;
        }
        let (a0, _) = recurrence(self.family, self.normalization, 0);
        for (v, &zi) in values.column_mut(1).iter_mut().zip(z) {
            *v = a0 * zi;
        }
        for k in 1..self.n_terms - 1 {
            let (a_k, c_k) = recurrence(self.family, self.normalization, k);
            let (done, mut rest) = values.columns_range_pair_mut(..k + 1, k + 1..);
            let (prev, this) = (done.column(k - 1), done.column(k));
            for (i, v) in rest.column_mut(0).iter_mut().enumerate() {
                *v = a_k * z[i] * this[i] - c_k * prev[i];
            }
        }
        if let Some(derivs) = derivs {
            derivs.column_mut(0).fill(0.0);
            derivs.column_mut(1).fill(a0);
            for k in 1..self.n_terms - 1 {
                let (a_k, c_k) = recurrence(self.family, self.normalization, k);
                let (done, mut rest) = derivs.columns_range_pair_mut(..k + 1, k + 1..);
                let (prev, this) = (done.column(k - 1), done.column(k));
                let p = values.column(k);
                for (i, d) in rest.column_mut(0).iter_mut().enumerate() {
                    *d = a_k * (p[i] + z[i] * this[i]) - c_k * prev[i];
                }
            }
        }
    }
}
