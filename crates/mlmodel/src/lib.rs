//! Traits for multi-level models with an unobservable distributed response.
//!
//! The BA-MUDI paper (Sec. 2.2) composes three models:
//!
//! | paper | trait | what it maps |
//! |---|---|---|
//! | Eq. 6, `g_u(x, d_u, θ)` | [`UnobservableModel`] | inputs `x`, parameters `θ` → distributed response at `N_u` points, for each of `C` components |
//! | Eq. 7, `g_o(x, d_o, θ, y_u)` | [`ObservableModel`] | `x`, `θ`, a distributed response `y_u` → `N_o` measurable outputs |
//! | Eq. 8, `g_p(x, d_p, θ, y_u)` | [`PredictionModel`] | same signature as `g_o`, for a quantity that is predicted, not measured |
//!
//! plus the prior of `θ` ([`Prior`], with [`UniformPrior`] and [`NormalPrior`]) and the
//! orthogonal-polynomial discrepancy basis of Eq. 15-17 / 49 ([`DiscrepancyBasis`]).
//! An observable model that is linear in `y_u` (Eq. 47: strain = `A (forces) + s_w(x)`)
//! additionally implements [`LinearObservableModel`], which lets the calibration use the
//! analytic covariance of Eq. 51.
//!
//! # Layout of a distributed response
//!
//! A distributed response with `C` components (for the miter gate: normal and tangential
//! quoin force, `C = 2`) at `N_u` points is one flat vector of length `C * N_u`, **component
//! blocked**: `[comp 0 at d_1..d_Nu, comp 1 at d_1..d_Nu, ...]`. The paper's Eq. 46 interleaves
//! the components point by point; [`interleaved_index`] converts between the two.
//!
//! Nothing here is specific to miter gates: `tests/lib.rs` of this crate implements the traits
//! for a beam on an elastic foundation.

/// The crate README's example, compiled and run as a doc test.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctest;

mod memo;

pub use memo::{Memo, RowMemo};

use nalgebra::DMatrix;
use numerics::random::standard_normal;
use orthopoly::{Basis, Family};
use rand::{RngExt, SeedableRng, rngs::StdRng};
use serde::{Deserialize, Serialize};

/// Errors from model evaluation and model set-up.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// A slice passed to a model had the wrong length.
    #[error("{what}: expected length {expected}, got {got}")]
    Dimension {
        /// Which argument.
        what: &'static str,
        /// Required length.
        expected: usize,
        /// Length received.
        got: usize,
    },
    /// An input lies outside the model's domain.
    #[error("input `{name}` = {value} is outside the model domain [{lo}, {hi}]")]
    OutOfDomain {
        /// Input name.
        name: String,
        /// Offending value.
        value: f64,
        /// Lower bound.
        lo: f64,
        /// Upper bound.
        hi: f64,
    },
    /// A parameter of a prior or basis is invalid.
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// The model's numerical solve failed.
    #[error("numerical failure in {context}: {reason}")]
    Numerical {
        /// Where it failed.
        context: String,
        /// What failed.
        reason: String,
    },
    /// Error from the polynomial basis.
    #[error(transparent)]
    Basis(#[from] orthopoly::OrthoError),
}

/// Result alias for this crate.
pub type Result<T> = std::result::Result<T, ModelError>;

/// Checks that `slice` has length `expected`.
///
/// ```
/// assert!(mlmodel::check_len("x", &[1.0, 2.0], 2).is_ok());
/// assert!(mlmodel::check_len("x", &[1.0], 2).is_err());
/// ```
pub fn check_len(what: &'static str, slice: &[f64], expected: usize) -> Result<()> {
    if slice.len() == expected {
        Ok(())
    } else {
        Err(ModelError::Dimension {
            what,
            expected,
            got: slice.len(),
        })
    }
}

/// Index of (component `c`, point `b`) in the paper's interleaved ordering (Eq. 46:
/// `[F_N(d_1), F_T(d_1), F_N(d_2), ...]`) given `components` per point.
///
/// The blocked index used throughout this workspace is `c * n_points + b`.
///
/// ```
/// // normal (0) and tangential (1) force at the third point, two components per point
/// assert_eq!(mlmodel::interleaved_index(0, 2, 2), 4);
/// assert_eq!(mlmodel::interleaved_index(1, 2, 2), 5);
/// ```
pub fn interleaved_index(c: usize, b: usize, components: usize) -> usize {
    b * components + c
}

/// The unobservable model `g_u(x, d_u, θ)` of Eq. 6: a distributed response that cannot be
/// measured (for the gate: quoin contact force intensities in lbf/in).
pub trait UnobservableModel: Send + Sync {
    /// Names of the controllable inputs `x` (e.g. `["h_up", "h_down"]`), with units in the name
    /// or the implementor's docs.
    fn input_names(&self) -> Vec<String>;
    /// Number of unknown parameters `θ`.
    fn param_dim(&self) -> usize;
    /// Number of response components `C` (2 for normal + tangential force).
    fn components(&self) -> usize;
    /// Spatial coordinates `d_u` of the `N_u` response points (shared by all components).
    fn coordinates(&self) -> &[f64];
    /// Evaluates `g_u(x, d_u, θ)` into `out` (length `C * N_u`, component blocked).
    fn evaluate(&self, x: &[f64], theta: &[f64], out: &mut [f64]) -> Result<()>;

    /// Checks that the inputs `x` lie in the model's domain (e.g. `h_up >= h_down` for the
    /// gate). Module 2 uses it to draw training inputs only where the model is defined; the
    /// default accepts every `x`.
    fn check_input(&self, x: &[f64]) -> Result<()> {
        check_len("x", x, self.input_dim())
    }

    /// Whether the response is zero at `x` for every `θ` (e.g. a gate with no head carries no
    /// contact force). The calibration's Module 4 then sets the discrepancy to zero at `x`: it
    /// corrects a response that is not there. Default: `false`.
    fn response_vanishes(&self, x: &[f64]) -> bool {
        let _ = x;
        false
    }

    /// Weights in `[0, 1]` per response point (`N_u` of them) of where a discrepancy can act
    /// at `θ`, or `None` for everywhere (the default). Where the response is zero by
    /// construction at this `θ` (for the gate: the gap below `θ` carries no contact force), so
    /// is any correction of it. The marginal coefficient mode of `bamudi` multiplies the
    /// discrepancy basis by these weights, which makes it depend on `θ`.
    fn discrepancy_support(&self, theta: &[f64]) -> Option<Vec<f64>> {
        let _ = theta;
        None
    }

    /// Number of inputs `x`.
    fn input_dim(&self) -> usize {
        self.input_names().len()
    }
    /// Length of the flat response vector, `C * N_u`.
    fn response_len(&self) -> usize {
        self.components() * self.coordinates().len()
    }
}

/// The observable model `g_o(x, d_o, θ, y_u)` of Eq. 7 (for the gate: strains in microstrain at
/// the gauges, given quoin forces and water levels).
pub trait ObservableModel: Send + Sync {
    /// Names of the `N_o` outputs (e.g. gauge names).
    fn output_names(&self) -> Vec<String>;
    /// Evaluates `g_o(x, θ, y_u)` into `out` (length `N_o`).
    fn evaluate(&self, x: &[f64], theta: &[f64], y_u: &[f64], out: &mut [f64]) -> Result<()>;
    /// Number of outputs `N_o`.
    fn output_dim(&self) -> usize {
        self.output_names().len()
    }
}

/// An observable model that is affine in the distributed response:
/// `g_o(x, θ, y_u) = A y_u + b(x, θ)` (Eq. 47 with `b = A F_water`).
///
/// Module 3 uses `A` to propagate the Gaussian-process covariance of the discrepancy
/// coefficients to the observations analytically (Eq. 51).
pub trait LinearObservableModel: ObservableModel {
    /// The matrix `A` (`N_o x C*N_u`, columns component blocked).
    fn matrix(&self) -> &DMatrix<f64>;
    /// The offset `b(x, θ)` (length `N_o`), e.g. the strain caused by the water load alone.
    fn offset(&self, x: &[f64], theta: &[f64], out: &mut [f64]) -> Result<()>;
}

/// The prediction model `g_p(x, d_p, θ, y_u)` of Eq. 8. It has the observable model's signature;
/// any [`ObservableModel`] can serve as a prediction model.
pub trait PredictionModel: Send + Sync {
    /// Names of the predicted quantities.
    fn output_names(&self) -> Vec<String>;
    /// Evaluates the prediction into `out`.
    fn evaluate(&self, x: &[f64], theta: &[f64], y_u: &[f64], out: &mut [f64]) -> Result<()>;
}

impl<T: ObservableModel> PredictionModel for T {
    fn output_names(&self) -> Vec<String> {
        ObservableModel::output_names(self)
    }
    fn evaluate(&self, x: &[f64], theta: &[f64], y_u: &[f64], out: &mut [f64]) -> Result<()> {
        ObservableModel::evaluate(self, x, theta, y_u, out)
    }
}

/// A quadrature rule over a prior: nodes `θ_j` and weights `w_j` with `Σ w_j = 1`, so that
/// `E[f(θ)] ≈ Σ w_j f(θ_j)` (used to marginalise `θ` in Eq. 25 and 27).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QuadratureRule {
    /// Nodes, each of length `param_dim`.
    pub nodes: Vec<Vec<f64>>,
    /// Probability weights summing to one.
    pub weights: Vec<f64>,
}

impl QuadratureRule {
    /// The rule's mean of `θ`, `Σ_j w_j θ_j` per dimension (empty for a rule without nodes),
    /// summed in node order.
    ///
    /// ```
    /// let q = mlmodel::QuadratureRule {
    ///     nodes: vec![vec![1.0, 10.0], vec![3.0, 20.0]],
    ///     weights: vec![0.25, 0.75],
    /// };
    /// assert_eq!(q.mean(), vec![2.5, 17.5]);
    /// ```
    pub fn mean(&self) -> Vec<f64> {
        let dim = self.nodes.first().map_or(0, Vec::len);
        let mut m = vec![0.0; dim];
        for (t, w) in self.nodes.iter().zip(&self.weights) {
            for (mi, ti) in m.iter_mut().zip(t) {
                *mi += w * ti;
            }
        }
        m
    }
}

/// The prior `f_Θ(θ)` of the unknown parameters.
pub trait Prior: Send + Sync {
    /// Dimension of `θ`.
    fn dim(&self) -> usize;
    /// Log prior density at `θ` (`-∞` outside the support).
    fn ln_pdf(&self, theta: &[f64]) -> f64;
    /// `n` independent draws, reproducible from `seed`.
    fn sample(&self, n: usize, seed: u64) -> Vec<Vec<f64>>;
    /// A quadrature rule of the given order per dimension (tensor product for `dim > 1`).
    fn quadrature(&self, order: usize) -> Result<QuadratureRule>;
    /// A box containing (almost all of) the prior mass, per dimension, for grids and plots.
    fn bounds(&self) -> Vec<(f64, f64)>;
}

/// Independent uniform priors `θ_i ~ U(lo_i, hi_i)` (Table 1: `U(81, 105)` and `U(135, 165)`).
///
/// ```
/// use mlmodel::{Prior, UniformPrior};
/// let p = UniformPrior::new(vec![(81.0, 105.0)]).unwrap();
/// let q = p.quadrature(5).unwrap();
/// let mean: f64 = q.nodes.iter().zip(&q.weights).map(|(t, w)| t[0] * w).sum();
/// assert!((mean - 93.0).abs() < 1e-10);
/// assert!((p.ln_pdf(&[90.0]) + 24f64.ln()).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UniformPrior {
    bounds: Vec<(f64, f64)>,
}

impl UniformPrior {
    /// A uniform prior on the box `bounds`; each interval must have `lo < hi`, both finite.
    pub fn new(bounds: Vec<(f64, f64)>) -> Result<Self> {
        if bounds.is_empty() {
            return Err(ModelError::InvalidParameter {
                name: "bounds",
                reason: "at least one dimension is required".into(),
            });
        }
        for &(lo, hi) in &bounds {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(ModelError::InvalidParameter {
                    name: "bounds",
                    reason: format!("need finite lo < hi, got [{lo}, {hi}]"),
                });
            }
        }
        Ok(Self { bounds })
    }
}

impl Prior for UniformPrior {
    fn dim(&self) -> usize {
        self.bounds.len()
    }
    fn ln_pdf(&self, theta: &[f64]) -> f64 {
        if theta.len() != self.bounds.len() {
            return f64::NEG_INFINITY;
        }
        let mut lp = 0.0;
        for (&t, &(lo, hi)) in theta.iter().zip(&self.bounds) {
            if !(lo..=hi).contains(&t) {
                return f64::NEG_INFINITY;
            }
            lp -= (hi - lo).ln();
        }
        lp
    }
    fn sample(&self, n: usize, seed: u64) -> Vec<Vec<f64>> {
        let mut rng = StdRng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                self.bounds
                    .iter()
                    .map(|&(lo, hi)| lo + (hi - lo) * rng.random::<f64>())
                    .collect()
            })
            .collect()
    }
    fn quadrature(&self, order: usize) -> Result<QuadratureRule> {
        let per_dim = self
            .bounds
            .iter()
            .map(|&(lo, hi)| {
                let (x, w) = orthopoly::gauss_legendre(order, lo, hi)?;
                let total = hi - lo;
                Ok(x.into_iter()
                    .zip(w.into_iter().map(|w| w / total))
                    .collect())
            })
            .collect::<Result<Vec<Vec<(f64, f64)>>>>()?;
        Ok(tensor_product(&per_dim))
    }
    fn bounds(&self) -> Vec<(f64, f64)> {
        self.bounds.clone()
    }
}

/// Independent normal priors `θ_i ~ N(mean_i, sd_i²)`.
///
/// ```
/// use mlmodel::{NormalPrior, Prior};
/// let p = NormalPrior::new(vec![(100.0, 5.0)]).unwrap();
/// let q = p.quadrature(8).unwrap();
/// let var: f64 = q.nodes.iter().zip(&q.weights).map(|(t, w)| (t[0] - 100.0).powi(2) * w).sum();
/// assert!((var - 25.0).abs() < 1e-9);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NormalPrior {
    moments: Vec<(f64, f64)>,
}

impl NormalPrior {
    /// Independent normals with `(mean, sd)` per dimension; `sd > 0`.
    pub fn new(moments: Vec<(f64, f64)>) -> Result<Self> {
        if moments.is_empty() || moments.iter().any(|&(m, s)| !(m.is_finite() && s > 0.0)) {
            return Err(ModelError::InvalidParameter {
                name: "moments",
                reason: "need at least one (finite mean, sd > 0)".into(),
            });
        }
        Ok(Self { moments })
    }
}

impl Prior for NormalPrior {
    fn dim(&self) -> usize {
        self.moments.len()
    }
    fn ln_pdf(&self, theta: &[f64]) -> f64 {
        if theta.len() != self.moments.len() {
            return f64::NEG_INFINITY;
        }
        theta
            .iter()
            .zip(&self.moments)
            .map(|(&t, &(m, s))| {
                let z = (t - m) / s;
                -0.5 * z * z - s.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln()
            })
            .sum()
    }
    fn sample(&self, n: usize, seed: u64) -> Vec<Vec<f64>> {
        let mut rng = StdRng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                self.moments
                    .iter()
                    .map(|&(m, s)| m + s * standard_normal(&mut rng))
                    .collect()
            })
            .collect()
    }
    fn quadrature(&self, order: usize) -> Result<QuadratureRule> {
        let per_dim = self
            .moments
            .iter()
            .map(|&(m, s)| {
                // Probabilists' Gauss-Hermite: weight exp(-x²/2), total mass sqrt(2π).
                let (x, w) = orthopoly::gauss_hermite_prob(order)?;
                let total: f64 = w.iter().sum();
                Ok(x.into_iter()
                    .zip(w)
                    .map(|(x, w)| (m + s * x, w / total))
                    .collect())
            })
            .collect::<Result<Vec<Vec<(f64, f64)>>>>()?;
        Ok(tensor_product(&per_dim))
    }
    fn bounds(&self) -> Vec<(f64, f64)> {
        self.moments
            .iter()
            .map(|&(m, s)| (m - 5.0 * s, m + 5.0 * s))
            .collect()
    }
}

/// One dimension of an [`IndependentPrior`]: uniform or normal.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PriorDimension {
    /// `U(lo, hi)`, finite `lo < hi`.
    Uniform {
        /// Lower bound.
        lo: f64,
        /// Upper bound.
        hi: f64,
    },
    /// `N(mean, sd²)`, finite mean, `sd > 0`.
    Normal {
        /// Mean.
        mean: f64,
        /// Standard deviation.
        sd: f64,
    },
}

/// Independent priors per dimension, each uniform or normal (a mix of the two; all-uniform and
/// all-normal priors are [`UniformPrior`] and [`NormalPrior`]). Each dimension's density,
/// quadrature (Gauss-Legendre or Gauss-Hermite, tensor product) and bounds are those of the
/// one-dimensional [`UniformPrior`] or [`NormalPrior`].
///
/// ```
/// use mlmodel::{IndependentPrior, NormalPrior, Prior, PriorDimension, UniformPrior};
/// let p = IndependentPrior::new(vec![
///     PriorDimension::Uniform { lo: 0.0, hi: 2.0 },
///     PriorDimension::Normal { mean: 1.0, sd: 0.5 },
/// ])
/// .unwrap();
/// let (u, n) = (UniformPrior::new(vec![(0.0, 2.0)]).unwrap(), NormalPrior::new(vec![(1.0, 0.5)]).unwrap());
/// assert_eq!(p.ln_pdf(&[0.3, 1.2]), u.ln_pdf(&[0.3]) + n.ln_pdf(&[1.2]));
/// assert_eq!(p.quadrature(4).unwrap().mean().len(), 2);
/// assert!(IndependentPrior::new(vec![PriorDimension::Uniform { lo: 0.0, hi: f64::INFINITY }]).is_err());
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IndependentPrior {
    dims: Vec<PriorDimension>,
}

impl IndependentPrior {
    /// The prior with one entry of `dims` per dimension (at least one, each valid).
    pub fn new(dims: Vec<PriorDimension>) -> Result<Self> {
        if dims.is_empty() {
            return Err(ModelError::InvalidParameter {
                name: "dims",
                reason: "at least one dimension is required".into(),
            });
        }
        for d in &dims {
            d.one()?;
        }
        Ok(Self { dims })
    }
}

impl PriorDimension {
    /// This dimension as a one-dimensional prior of its kind.
    fn one(&self) -> Result<Box<dyn Prior>> {
        Ok(match *self {
            Self::Uniform { lo, hi } => Box::new(UniformPrior::new(vec![(lo, hi)])?),
            Self::Normal { mean, sd } => Box::new(NormalPrior::new(vec![(mean, sd)])?),
        })
    }
}

impl Prior for IndependentPrior {
    fn dim(&self) -> usize {
        self.dims.len()
    }
    fn ln_pdf(&self, theta: &[f64]) -> f64 {
        if theta.len() != self.dims.len() {
            return f64::NEG_INFINITY;
        }
        self.dims
            .iter()
            .zip(theta)
            .map(|(d, t)| d.one().map_or(f64::NEG_INFINITY, |p| p.ln_pdf(&[*t])))
            .sum()
    }
    fn sample(&self, n: usize, seed: u64) -> Vec<Vec<f64>> {
        let mut rng = StdRng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                self.dims
                    .iter()
                    .map(|d| match *d {
                        PriorDimension::Uniform { lo, hi } => lo + (hi - lo) * rng.random::<f64>(),
                        PriorDimension::Normal { mean, sd } => {
                            mean + sd * standard_normal(&mut rng)
                        }
                    })
                    .collect()
            })
            .collect()
    }
    fn quadrature(&self, order: usize) -> Result<QuadratureRule> {
        let per_dim = self
            .dims
            .iter()
            .map(|d| {
                let q = d.one()?.quadrature(order)?;
                Ok(q.nodes.iter().map(|t| t[0]).zip(q.weights).collect())
            })
            .collect::<Result<Vec<Vec<(f64, f64)>>>>()?;
        Ok(tensor_product(&per_dim))
    }
    fn bounds(&self) -> Vec<(f64, f64)> {
        self.dims
            .iter()
            .map(|d| d.one().map_or((f64::NAN, f64::NAN), |p| p.bounds()[0]))
            .collect()
    }
}

/// Tensor product of one-dimensional rules given as (node, weight) lists.
fn tensor_product(per_dim: &[Vec<(f64, f64)>]) -> QuadratureRule {
    let mut nodes: Vec<Vec<f64>> = vec![vec![]];
    let mut weights = vec![1.0];
    for rule in per_dim {
        let mut next_nodes = Vec::with_capacity(nodes.len() * rule.len());
        let mut next_weights = Vec::with_capacity(nodes.len() * rule.len());
        for (node, w) in nodes.iter().zip(&weights) {
            for &(x, wx) in rule {
                let mut n = node.clone();
                n.push(x);
                next_nodes.push(n);
                next_weights.push(w * wx);
            }
        }
        nodes = next_nodes;
        weights = next_weights;
    }
    QuadratureRule { nodes, weights }
}

/// The distributed-discrepancy basis of Eq. 15-17 and 49: for each response component `c`, an
/// orthogonal-polynomial matrix `L_c` (`N_u x K_c`) evaluated at the response coordinates, so
/// that `δ = blockdiag(L_0, L_1, ...) α` with `α` the stacked coefficients (`Σ K_c` of them).
///
/// ```
/// use mlmodel::DiscrepancyBasis;
/// use orthopoly::Family;
/// let d: Vec<f64> = (0..509).map(|i| 762.0 * i as f64 / 508.0).collect();
/// let basis = DiscrepancyBasis::new(Family::Legendre, (0.0, 762.0), &d, &[6, 6]).unwrap();
/// assert_eq!(basis.n_coefficients(), 12);
/// let mut delta = vec![0.0; 2 * 509];
/// let mut alpha = vec![0.0; 12];
/// alpha[0] = 2.0; // constant term of the first component
/// basis.expand(&alpha, &mut delta).unwrap();
/// assert!(delta[..509].iter().all(|v| (v - delta[0]).abs() < 1e-12));
/// assert!(delta[509..].iter().all(|v| *v == 0.0));
/// ```
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DiscrepancyBasis {
    family: Family,
    interval: (f64, f64),
    terms: Vec<usize>,
    matrices: Vec<DMatrix<f64>>,
}

impl DiscrepancyBasis {
    /// Builds the basis of `family` on `interval` at the coordinates `points`, with `terms[c]`
    /// polynomial terms (degrees `0..terms[c]`) for component `c`. The polynomials are scaled to
    /// be orthonormal on the interval (see [`orthopoly::Basis`]).
    pub fn new(
        family: Family,
        interval: (f64, f64),
        points: &[f64],
        terms: &[usize],
    ) -> Result<Self> {
        if terms.is_empty() || terms.contains(&0) {
            return Err(ModelError::InvalidParameter {
                name: "terms",
                reason: "need at least one component, each with at least one term".into(),
            });
        }
        let max_terms = *terms.iter().max().unwrap_or(&1);
        let basis = Basis::new(family, interval.0, interval.1, max_terms)?;
        let full = basis.matrix(points)?;
        let matrices = terms
            .iter()
            .map(|&k| full.columns(0, k).into_owned())
            .collect();
        Ok(Self {
            family,
            interval,
            terms: terms.to_vec(),
            matrices,
        })
    }

    /// Number of response components.
    pub fn components(&self) -> usize {
        self.terms.len()
    }
    /// Terms per component.
    pub fn terms(&self) -> &[usize] {
        &self.terms
    }
    /// Total number of coefficients `Σ K_c`.
    pub fn n_coefficients(&self) -> usize {
        self.terms.iter().sum()
    }
    /// Number of response points `N_u`.
    pub fn n_points(&self) -> usize {
        self.matrices[0].nrows()
    }
    /// The polynomial family.
    pub fn family(&self) -> Family {
        self.family
    }
    /// The interval the polynomials live on.
    pub fn interval(&self) -> (f64, f64) {
        self.interval
    }
    /// The matrix `L_c` (`N_u x K_c`) of component `c`.
    pub fn matrix(&self, c: usize) -> &DMatrix<f64> {
        &self.matrices[c]
    }
    /// Offset of component `c`'s coefficients in the stacked `α`.
    pub fn coefficient_offset(&self, c: usize) -> usize {
        self.terms[..c].iter().sum()
    }

    /// `δ = blockdiag(L_c) α` into `out` (length `C * N_u`).
    pub fn expand(&self, alpha: &[f64], out: &mut [f64]) -> Result<()> {
        check_len("alpha", alpha, self.n_coefficients())?;
        check_len("out", out, self.components() * self.n_points())?;
        let n = self.n_points();
        for (c, l) in self.matrices.iter().enumerate() {
            let a = &alpha[self.coefficient_offset(c)..][..self.terms[c]];
            for (b, o) in out[c * n..(c + 1) * n].iter_mut().enumerate() {
                *o = (0..a.len()).map(|k| l[(b, k)] * a[k]).sum();
            }
        }
        Ok(())
    }

    /// Least-squares coefficients of a sampled field `y` (length `C * N_u`), per component.
    pub fn project(&self, y: &[f64]) -> Result<Vec<f64>> {
        check_len("y", y, self.components() * self.n_points())?;
        let n = self.n_points();
        let mut alpha = Vec::with_capacity(self.n_coefficients());
        for (c, l) in self.matrices.iter().enumerate() {
            let rhs = nalgebra::DVector::from_column_slice(&y[c * n..(c + 1) * n]);
            let svd = l.clone().svd(true, true);
            let sol = svd.solve(&rhs, 1e-12).map_err(|e| ModelError::Numerical {
                context: "DiscrepancyBasis::project".into(),
                reason: e.to_string(),
            })?;
            alpha.extend(sol.iter());
        }
        Ok(alpha)
    }

    /// The block-diagonal matrix `blockdiag(L_c)` (`C*N_u x Σ K_c`).
    pub fn block_matrix(&self) -> DMatrix<f64> {
        let n = self.n_points();
        let mut m = DMatrix::zeros(self.components() * n, self.n_coefficients());
        for (c, l) in self.matrices.iter().enumerate() {
            m.view_mut((c * n, self.coefficient_offset(c)), (n, self.terms[c]))
                .copy_from(l);
        }
        m
    }
}

/// A complete multi-level model: the three models, the prior and the discrepancy basis, as
/// the calibration consumes them.
pub struct MultiLevelModel<U, O> {
    /// The unobservable model `g_u`.
    pub unobservable: U,
    /// The observable model `g_o`.
    pub observable: O,
    /// The prior of `θ`.
    pub prior: Box<dyn Prior>,
    /// The discrepancy basis (its point count must equal `unobservable.coordinates().len()`).
    pub basis: DiscrepancyBasis,
    /// Declared tolerances of the system's build (none by default; see
    /// [`with_tolerances`](Self::with_tolerances)).
    pub tolerances: Vec<BuildTolerance<U, O>>,
    /// Remembered rows of [`model_row`](Self::model_row) (none by default; see
    /// [`with_row_memo`](Self::with_row_memo)).
    rows: RowMemo,
}

/// One uncertain build parameter of the modelled system (a plate thickness, a modulus, a
/// gauge's position): the models rebuilt at one standard deviation below (`low`) and above
/// (`high`) its nominal value. A calibration that integrates it treats the parameter's
/// deviation as `N(0, 1)` in these units and the responses as linear in it over that range
/// (the central difference `(high − low) / 2` per standard deviation).
pub struct BuildTolerance<U, O> {
    /// What varies (a key or a description; reported with the calibration).
    pub name: String,
    /// The observable model at the nominal value minus one standard deviation.
    pub low: O,
    /// The observable model at the nominal value plus one standard deviation.
    pub high: O,
    /// The unobservable model at the same two values, when the parameter changes it too
    /// (`None`: the nominal unobservable model serves both).
    pub responses: Option<(U, U)>,
}

impl<U: UnobservableModel, O: ObservableModel> MultiLevelModel<U, O> {
    /// Bundles the parts after checking that their dimensions agree.
    pub fn new(
        unobservable: U,
        observable: O,
        prior: Box<dyn Prior>,
        basis: DiscrepancyBasis,
    ) -> Result<Self> {
        if basis.n_points() != unobservable.coordinates().len() {
            return Err(ModelError::Dimension {
                what: "basis points vs unobservable coordinates",
                expected: unobservable.coordinates().len(),
                got: basis.n_points(),
            });
        }
        if basis.components() != unobservable.components() {
            return Err(ModelError::Dimension {
                what: "basis components vs unobservable components",
                expected: unobservable.components(),
                got: basis.components(),
            });
        }
        if prior.dim() != unobservable.param_dim() {
            return Err(ModelError::Dimension {
                what: "prior dimension vs unobservable parameters",
                expected: unobservable.param_dim(),
                got: prior.dim(),
            });
        }
        Ok(Self {
            unobservable,
            observable,
            prior,
            basis,
            tolerances: Vec::new(),
            rows: RowMemo::default(),
        })
    }

    /// Remembers up to `capacity` rows of [`model_row`](Self::model_row) (0: none), replacing
    /// any rows remembered so far (call it again after replacing `unobservable` or
    /// `observable`: the rows belong to the models they came from).
    pub fn with_row_memo(mut self, capacity: usize) -> Self {
        self.rows = RowMemo::new(capacity);
        self
    }

    /// The memo of [`model_row`](Self::model_row).
    pub fn row_memo(&self) -> &RowMemo {
        &self.rows
    }

    /// Declares tolerances of the system's build; each observable model must have the
    /// nominal one's outputs, in order, and each unobservable model its response layout.
    ///
    /// ```
    /// # use mlmodel::*;
    /// # use nalgebra::DMatrix;
    /// # struct One;
    /// # impl UnobservableModel for One {
    /// #     fn input_names(&self) -> Vec<String> { vec!["x".into()] }
    /// #     fn param_dim(&self) -> usize { 1 }
    /// #     fn components(&self) -> usize { 1 }
    /// #     fn coordinates(&self) -> &[f64] { &[0.0, 1.0] }
    /// #     fn evaluate(&self, x: &[f64], t: &[f64], out: &mut [f64]) -> Result<()> {
    /// #         out.fill(x[0] * t[0]); Ok(())
    /// #     }
    /// # }
    /// // a strain gauge reading `gain × (sum of the response)`; the gain is known to ±2 %
    /// struct Gauge(f64);
    /// impl ObservableModel for Gauge {
    ///     fn output_names(&self) -> Vec<String> { vec!["sg".into()] }
    ///     fn evaluate(&self, _: &[f64], _: &[f64], y: &[f64], out: &mut [f64]) -> Result<()> {
    ///         out[0] = self.0 * y.iter().sum::<f64>();
    ///         Ok(())
    ///     }
    /// }
    /// let basis = DiscrepancyBasis::new(orthopoly::Family::Legendre, (0.0, 1.0), &[0.0, 1.0], &[1]).unwrap();
    /// let prior = Box::new(UniformPrior::new(vec![(0.0, 1.0)]).unwrap());
    /// let model = MultiLevelModel::new(One, Gauge(1.0), prior, basis).unwrap();
    /// let tol = BuildTolerance { name: "gain".into(), low: Gauge(0.98), high: Gauge(1.02), responses: None };
    /// let model = model.with_tolerances(vec![tol]).unwrap();
    /// assert_eq!(model.tolerances[0].name, "gain");
    /// ```
    pub fn with_tolerances(mut self, tolerances: Vec<BuildTolerance<U, O>>) -> Result<Self> {
        let names = self.observable.output_names();
        for t in &tolerances {
            for (side, m) in [("low", &t.low), ("high", &t.high)] {
                if m.output_names() != names {
                    return Err(ModelError::InvalidParameter {
                        name: "tolerances",
                        reason: format!(
                            "tolerance `{}` ({side}): outputs {:?}, the nominal model's are {names:?}",
                            t.name,
                            m.output_names()
                        ),
                    });
                }
            }
            for u in t.responses.iter().flat_map(|(lo, hi)| [lo, hi]) {
                if u.response_len() != self.unobservable.response_len() {
                    return Err(ModelError::Dimension {
                        what: "tolerance response length vs the nominal unobservable model's",
                        expected: self.unobservable.response_len(),
                        got: u.response_len(),
                    });
                }
            }
        }
        self.tolerances = tolerances;
        Ok(self)
    }

    /// The corrected response of Eq. 17: `ρ g_u(x, θ) + L α` into `out`.
    pub fn corrected_response(
        &self,
        x: &[f64],
        theta: &[f64],
        rho: f64,
        alpha: &[f64],
        out: &mut [f64],
    ) -> Result<()> {
        let mut delta = vec![0.0; out.len()];
        self.basis.expand(alpha, &mut delta)?;
        self.unobservable.evaluate(x, theta, out)?;
        for (o, d) in out.iter_mut().zip(&delta) {
            *o = rho * *o + d;
        }
        Ok(())
    }
}

impl<U: UnobservableModel, O: LinearObservableModel> MultiLevelModel<U, O> {
    /// The model's row of the calibration mean (Eq. 50, with `ρ = 1` and no discrepancy) at
    /// `(x, θ)`: `A g_u(x, θ)` (the first `N_o` values) and the offset `b(x, θ)` (the last
    /// `N_o`), output units. Remembered when the model has a [row memo](Self::with_row_memo):
    /// the values are those computed the first time, bit for bit (both models are
    /// deterministic), so the memo changes no result.
    ///
    /// ```
    /// # use mlmodel::*;
    /// # use nalgebra::DMatrix;
    /// # struct Line;
    /// # impl UnobservableModel for Line {
    /// #     fn input_names(&self) -> Vec<String> { vec!["x".into()] }
    /// #     fn param_dim(&self) -> usize { 1 }
    /// #     fn components(&self) -> usize { 1 }
    /// #     fn coordinates(&self) -> &[f64] { &[0.0, 1.0] }
    /// #     fn evaluate(&self, x: &[f64], t: &[f64], out: &mut [f64]) -> Result<()> {
    /// #         out.copy_from_slice(&[x[0] * t[0], x[0]]); Ok(())
    /// #     }
    /// # }
    /// // one gauge reading the sum of the response, offset by 0.5
    /// struct Sum(DMatrix<f64>);
    /// impl ObservableModel for Sum {
    ///     fn output_names(&self) -> Vec<String> { vec!["sg".into()] }
    ///     fn evaluate(&self, _: &[f64], _: &[f64], y: &[f64], out: &mut [f64]) -> Result<()> {
    ///         out[0] = y.iter().sum::<f64>() + 0.5;
    ///         Ok(())
    ///     }
    /// }
    /// impl LinearObservableModel for Sum {
    ///     fn matrix(&self) -> &DMatrix<f64> { &self.0 }
    ///     fn offset(&self, _: &[f64], _: &[f64], out: &mut [f64]) -> Result<()> {
    ///         out[0] = 0.5;
    ///         Ok(())
    ///     }
    /// }
    /// # let basis = DiscrepancyBasis::new(orthopoly::Family::Legendre, (0.0, 1.0), &[0.0, 1.0], &[1]).unwrap();
    /// # let prior = Box::new(UniformPrior::new(vec![(0.0, 3.0)]).unwrap());
    /// let model = MultiLevelModel::new(Line, Sum(DMatrix::from_element(1, 2, 1.0)), prior, basis)
    ///     .unwrap()
    ///     .with_row_memo(100);
    /// let row = model.model_row(&[2.0], &[1.5]).unwrap();
    /// assert_eq!(&row[..], &[5.0, 0.5]); // A g = 2 * 1.5 + 2, b = 0.5
    /// assert_eq!(model.row_memo().len(), 1);
    /// ```
    pub fn model_row(&self, x: &[f64], theta: &[f64]) -> Result<std::sync::Arc<[f64]>> {
        let a = self.observable.matrix();
        let n_o = a.nrows();
        self.rows.row(x, theta, 2 * n_o, |out| {
            let mut g = vec![0.0; self.unobservable.response_len()];
            self.unobservable.evaluate(x, theta, &mut g)?;
            let ag = a * nalgebra::DVector::from_vec(g);
            out[..n_o].copy_from_slice(ag.as_slice());
            self.observable.offset(x, theta, &mut out[n_o..])
        })
    }
}
