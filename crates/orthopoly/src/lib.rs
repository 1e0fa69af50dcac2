//! `orthopoly`: orthogonal polynomial bases and Gauss quadrature on any interval.
//!
//! BA-MUDI represents the distributed model discrepancy of the unobservable model (the quoin
//! contact force along the 762 in quoin height) as an orthogonal-polynomial expansion
//! `δ_u(x, d_u) = L(d_u) α(x)` (Eq. 15-17): [`Basis::matrix`] builds the `N_u x N_k` matrix
//! `L(d_u)`, [`Basis::project`] fits `α` to a sampled field by least squares and
//! [`Basis::reconstruct`] evaluates `L(d_u) α`. The quadrature rules ([`gauss_legendre`],
//! [`gauss_hermite_prob`], [`gauss_chebyshev`]) marginalise the uncertain parameters θ over
//! their prior (Eq. 25 and 27) deterministically instead of by Monte Carlo.
//!
//! # Families and scaling conventions
//!
//! Three [`Family`]s are built by their three-term recurrences (values and first derivatives):
//! Legendre `P_n`, Chebyshev of the first kind `T_n` and probabilists' Hermite `He_n`. Each is
//! available in two [`Normalization`]s:
//!
//! * [`Normalization::Orthonormal`] (the default, used by [`Basis::new`]): orthonormal with
//!   respect to the family's weight *normalised to a probability measure*, i.e.
//!   `E[φ_j φ_k] = δ_jk` with `φ_0 = 1`:
//!   - Legendre: uniform measure, `φ_n = sqrt(2n+1) P_n`. The constant coefficient `α_0` is
//!     the mean of the field over `[a, b]`, and `Σ α_k²` is its mean square.
//!   - Chebyshev: arcsine measure `dz / (π sqrt(1-z²))`, `φ_0 = 1`, `φ_n = sqrt(2) T_n`.
//!   - Hermite: standard normal measure in `z`, `φ_n = He_n / sqrt(n!)`.
//! * [`Normalization::Classical`]: the textbook `P_n`, `T_n`, `He_n`
//!   (`E[p_n²]` is [`Family::classical_norm_squared`]).
//!
//! The orthonormal polynomials are computed by their own (Jacobi) recurrence, not by scaling
//! the classical ones, so high-degree Hermite values do not overflow through `n!`.
//!
//! # The interval map
//!
//! A [`Basis`] lives on a physical interval `[a, b]` (e.g. `[0, 762]` inches). Every family
//! uses the same affine map to the reference variable
//!
//! `z = (t - (a+b)/2) / ((b-a)/2)`,   `dz/dt = 2 / (b - a)`.
//!
//! For Legendre and Chebyshev `[a, b]` maps onto `[-1, 1]` and points outside `[a, b]` are
//! rejected ([`OrthoError::OutOfInterval`], with a round-off tolerance). For Hermite the map
//! means `z ~ N(0, 1)` ⇔ `t ~ N((a+b)/2, ((b-a)/2)²)`: `a` and `b` are the mean minus/plus one
//! standard deviation, and any finite `t` is accepted. Derivatives returned by the basis are
//! `d/dt` (per unit of `t`, e.g. per inch).
//!
//! # Example: discrepancy basis on the quoin
//!
//! ```
//! use orthopoly::{Basis, Family};
//! // 509 points along the 762 in quoin, six Legendre terms as in the paper (Eq. 49).
//! let d: Vec<f64> = (0..509).map(|i| 762.0 * i as f64 / 508.0).collect();
//! let basis = Basis::new(Family::Legendre, 0.0, 762.0, 6).unwrap();
//! let l = basis.matrix(&d).unwrap(); // L(d_u), 509 x 6
//! let alpha = [50.0, -10.0, 3.0, 0.0, 0.0, 1.0]; // lbf/in
//! let delta = &l * nalgebra::DVector::from_column_slice(&alpha);
//! let back = basis.project(&d, delta.as_slice()).unwrap();
//! for (a, b) in alpha.iter().zip(&back) {
//!     assert!((a - b).abs() < 1e-10);
//! }
//! ```
//!
//! # Quadrature
//!
//! Gauss-Legendre and probabilists' Gauss-Hermite rules of any order come from Newton
//! iteration on the recurrences with asymptotic initial guesses (`O(n²)`; checked against
//! 40-digit mpmath rules up to order 100: nodes within 4 ulps, weights within 1e-12
//! relative; Gauss-Hermite Newton steps are safeguarded by a Sturm-count bracket, so large
//! orders cannot converge to the wrong root). [`Basis::probability_quadrature`] returns the Gauss
//! rule of a basis's own probability measure, under which an orthonormal basis is exactly
//! orthonormal.

/// The crate README's example, compiled and run as a doc test.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctest;

mod basis;
mod error;
mod family;
mod quadrature;
mod validate;

pub use basis::Basis;
pub use error::OrthoError;
pub use family::{Family, Normalization};
pub use quadrature::{gauss_chebyshev, gauss_hermite_prob, gauss_legendre};
