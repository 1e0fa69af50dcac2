//! The third level (paper Eq. 8, 11; Fig. 2): the calibrated distributed response pushed
//! through any [`PredictionModel`], with bands.
//!
//! A prediction model is usually nonlinear in the response (a contact pressure goes as the
//! square root of the line load), so its band is not the response band mapped point by point:
//! it needs joint draws of the whole response. One draw follows the mixture of Eq. 52 exactly
//! as Module 4 describes it: a support point `θ_j` with probability `w_j`; `ρ` from its
//! Gaussian given `θ_j` (the marginal mode; `ρ*` otherwise); the coefficients from their
//! Gaussian given `θ_j` and that `ρ` — mean `μ_j + (∂μ_j/∂ρ)(ρ − ρ_j)`, covariance `Σ_α(x)`,
//! all directions of it, also those the gauges cannot see; the response
//! `ρ g_u(x, θ_j) + L α`. With declared build tolerances (marginal mode) the deviations `η`
//! are drawn jointly with the coefficients (mean `η̂`, covariance `M⁻¹`, and their covariance
//! with `α`) and add `R η`, `R` the tolerances' response columns. Each draw goes through the prediction model with its own `θ_j`; the
//! band is the draws' empirical 2.5 % and 97.5 % quantiles. Draws are seeded: the same seed
//! gives the same band.
//!
//! When the models with and without a discrepancy were weighed ([`crate::posterior::average`]),
//! a draw first picks the model without one with its posterior probability
//! ([`Predictor::probability_without`]), then a point of that calibration's `θ` posterior by
//! its weight, and is `ρ g_u(x, θ_j) + L z` with `ρ` from its Gaussian given `θ_j` and `z`
//! from the coefficients' covariance at `x` with mean zero: no correction, the spread of the
//! one the discrepancy model cannot exclude.

use super::{Band, Predictor};
use crate::error::{BamudiError, Result};
use mlmodel::{LinearObservableModel, PredictionModel, UnobservableModel};
use nalgebra::{DMatrix, DVector};
use numerics::random::standard_normal;
use rand::{RngExt, SeedableRng, rngs::StdRng};

/// The basis the draws multiply, the covariance of what it multiplies, and the tolerances'
/// mean deviations when they are drawn too (see [`Predictor::draws_at`]).
type DrawBasis = (DMatrix<f64>, DMatrix<f64>, Option<DVector<f64>>);

/// One joint draw of the corrected response: the `θ` it was drawn at and the response
/// (component blocked, length `C N_u`).
#[derive(Debug, Clone, PartialEq)]
pub struct ResponseDraw {
    /// The support point `θ_j` of the draw.
    pub theta: Vec<f64>,
    /// The response.
    pub response: Vec<f64>,
}

/// The randomness of `n` joint draws, fixed so that the same draws can be evaluated at many
/// conditions (a load history): per draw, the support point, `ρ`'s standard normal and the
/// coefficients' standard normals. Evaluated at `x` ([`Predictor::draws_at`]), draw `k` is
/// `ρ_k = ρ_j(x) + σ_ρ,j(x) z_ρ,k` and `α_k = μ_j(x) + (∂μ_j/∂ρ)(ρ_k − ρ_j) + L_Σ(x) z_k`:
/// at every `x` a draw of the mixture of Eq. 52; along a history the same `z_k`, i.e. a
/// coefficient error that stays the same from one condition to the next. That is the
/// conservative choice for a sum over the history (a fatigue damage): errors that persist do
/// not average out, so the sum's band is the widest the marginals allow.
#[derive(Debug, Clone)]
pub struct DrawPaths {
    /// Support index per draw; from the support's length on, the points of the calibration
    /// without a discrepancy (when the two models were weighed).
    picks: Vec<usize>,
    /// Standard normal of `ρ` per draw.
    rho_z: Vec<f64>,
    /// Standard normals of the coefficients per draw.
    alpha_z: Vec<DVector<f64>>,
    /// Fingerprint of the predictor the paths were drawn for (its support and coefficient
    /// count): paths index its support, so another predictor's are refused.
    source: u64,
}

impl DrawPaths {
    /// Number of draws.
    pub fn len(&self) -> usize {
        self.picks.len()
    }

    /// No draws.
    pub fn is_empty(&self) -> bool {
        self.picks.is_empty()
    }
}

impl<U: UnobservableModel, O: LinearObservableModel> Predictor<'_, U, O> {
    /// `n` joint draws of the corrected distributed response at `x` (see the module docs).
    ///
    /// Their mean and spread agree with [`response`](Self::response) (the same mixture); their
    /// point-to-point correlation is what a nonlinear prediction model needs.
    pub fn response_draws(&self, x: &[f64], n: usize, seed: u64) -> Result<Vec<ResponseDraw>> {
        self.draws_at(&self.draw_paths(n, seed), x)
    }

    /// The randomness of `n` draws from the seed (see [`DrawPaths`]).
    pub fn draw_paths(&self, n: usize, seed: u64) -> DrawPaths {
        let cumulative: Vec<f64> = self
            .support
            .iter()
            .scan(0.0, |acc, (_, w)| {
                *acc += w;
                Some(*acc)
            })
            .collect();
        let total = cumulative.last().copied().unwrap_or(0.0);
        let p0 = self.probability_without();
        let without: Vec<f64> = match p0 > 0.0 {
            true => self.no_discrepancy_nodes().map_or_else(
                |_| Vec::new(),
                |nodes| {
                    nodes
                        .iter()
                        .scan(0.0, |acc, n| {
                            *acc += n.weight;
                            Some(*acc)
                        })
                        .collect()
                },
            ),
            false => Vec::new(),
        };
        let n_coef = self.basis().0.ncols() + self.n_tolerances();
        let mut rng = StdRng::seed_from_u64(seed);
        let mut paths = DrawPaths {
            picks: Vec::with_capacity(n),
            rho_z: Vec::with_capacity(n),
            alpha_z: Vec::with_capacity(n),
            source: self.paths_fingerprint(n_coef),
        };
        for _ in 0..n {
            // the model is drawn only when the two were weighed: otherwise the stream is the
            // one of a calibration that assumes a discrepancy
            let model0 = !without.is_empty() && rng.random::<f64>() < p0;
            let j = match model0 {
                false => {
                    let u = rng.random::<f64>() * total;
                    let j = cumulative.partition_point(|c| *c < u);
                    j.min(self.support.len().saturating_sub(1))
                }
                true => {
                    let last = without.last().copied().unwrap_or(0.0);
                    let u = rng.random::<f64>() * last;
                    let j = without.partition_point(|c| *c < u);
                    self.support.len() + j.min(without.len() - 1)
                }
            };
            paths.picks.push(j);
            paths.rho_z.push(standard_normal(&mut rng));
            paths
                .alpha_z
                .push(DVector::from_fn(n_coef, |_, _| standard_normal(&mut rng)));
        }
        paths
    }

    /// Fingerprint of this predictor's support (`θ` nodes and weights, bit for bit) and of the
    /// number of coefficients a draw carries.
    fn paths_fingerprint(&self, n_coef: usize) -> u64 {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        n_coef.hash(&mut h);
        for (theta, w) in &self.support {
            theta.iter().for_each(|t| t.to_bits().hash(&mut h));
            w.to_bits().hash(&mut h);
        }
        // the weighing: paths of a weighed predictor index the other model's points too
        let p0 = self.probability_without();
        if p0 > 0.0 {
            p0.to_bits().hash(&mut h);
            self.no_discrepancy_nodes()
                .map_or(0, <[_]>::len)
                .hash(&mut h);
        }
        h.finish()
    }

    /// The draws of `paths` at `x`; the model is evaluated once per support point the draws
    /// use. Paths drawn by another predictor ([`Self::draw_paths`]) are an error.
    pub fn draws_at(&self, paths: &DrawPaths, x: &[f64]) -> Result<Vec<ResponseDraw>> {
        let n_coef = self.basis().0.ncols() + self.n_tolerances();
        if paths.source != self.paths_fingerprint(n_coef) {
            return Err(BamudiError::config(
                "draws",
                "the draw paths were drawn for another predictor (another support or coefficient count)".to_string(),
            ));
        }
        let at = self.coef_at(x)?;
        let (basis, cov, eta) = self.draw_basis(x, &at)?;
        let factor = match cov.iter().any(|v| *v != 0.0) {
            true => Some(covariance_factor(&cov, x)?),
            false => None,
        };
        let n1 = self.support.len();
        let without = match paths.picks.iter().any(|j| *j >= n1) {
            true => self.no_discrepancy_nodes()?,
            false => &[],
        };
        let theta_of = |j: usize| -> Result<&Vec<f64>> {
            match j < n1 {
                true => Ok(&self.support[j].0),
                false => without.get(j - n1).map(|n| &n.theta).ok_or_else(|| {
                    BamudiError::config("draws", "a draw's point is not in this calibration")
                }),
            }
        };
        let mut responses: Vec<Option<DVector<f64>>> = vec![None; n1 + without.len()];
        for &j in &paths.picks {
            if responses.get(j).is_some_and(Option::is_none) {
                let mut g = vec![0.0; basis.nrows()];
                self.model.unobservable.evaluate(x, theta_of(j)?, &mut g)?;
                responses[j] = Some(DVector::from_vec(g));
            }
        }
        (0..paths.len())
            .map(|k| {
                let j = paths.picks[k];
                let g = responses.get(j).and_then(Option::as_ref).ok_or_else(|| {
                    BamudiError::config("draws", "a draw's support point was not evaluated")
                })?;
                if j >= n1 {
                    // no correction, the spread of the one the discrepancy model cannot exclude
                    let node = &without[j - n1];
                    let rho = node.rho_mean + node.rho_var.max(0.0).sqrt() * paths.rho_z[k];
                    let mut r = g * rho;
                    if let Some(f) = &factor {
                        // the coefficients' part of the joint draw (not the tolerances'): the
                        // spread the bands add ([`Predictor::response`])
                        let z = f * paths.alpha_z[k].rows(0, basis.ncols());
                        let n_alpha = self.basis().0.ncols();
                        r += self.basis().0 * z.rows(0, n_alpha);
                    }
                    return Ok(ResponseDraw {
                        theta: node.theta.clone(),
                        response: r.iter().copied().collect(),
                    });
                }
                let (rho_j, rho_var) = at.rho[j];
                let rho = rho_j + rho_var.max(0.0).sqrt() * paths.rho_z[k];
                let alpha = &at.mean[j] + &at.slope[j] * (rho - rho_j);
                let mut z = match &eta {
                    Some(eta) => DVector::from_iterator(
                        basis.ncols(),
                        alpha.iter().chain(eta.iter()).copied(),
                    ),
                    None => alpha,
                };
                if let Some(f) = &factor {
                    z += f * paths.alpha_z[k].rows(0, z.len());
                }
                Ok(ResponseDraw {
                    theta: self.support[j].0.clone(),
                    response: (g * rho + &basis * z).iter().copied().collect(),
                })
            })
            .collect()
    }

    /// What the draws at `x` multiply: the basis `L` and the coefficients' covariance, or, with
    /// declared tolerances, `[L R]` and the joint covariance of `(α, η)` with `η̂`.
    fn draw_basis(&self, x: &[f64], at: &super::CoefAt) -> Result<DrawBasis> {
        let l = self.basis().0;
        let (Some(t), Some(cols)) = (&at.tolerance, self.tolerance_columns(x, at)?) else {
            return Ok((l.clone(), at.cov.clone(), None));
        };
        let (k, p) = (l.ncols(), t.mean.len());
        let basis = DMatrix::from_fn(l.nrows(), k + p, |r, c| match c < k {
            true => l[(r, c)],
            false => cols.response[(r, c - k)],
        });
        let cov = DMatrix::from_fn(k + p, k + p, |a, b| match (a < k, b < k) {
            (true, true) => at.cov[(a, b)],
            (true, false) => t.cross[(a, b - k)],
            (false, true) => t.cross[(b, a - k)],
            (false, false) => t.cov[(a - k, b - k)],
        });
        Ok((basis, cov, Some(t.mean.clone())))
    }

    /// The prediction model's outputs at `x` with 95 % bands: `n_draws` joint draws of the
    /// response ([`response_draws`](Self::response_draws)) pushed through `model`; mean, sd
    /// and the empirical 2.5 % / 97.5 % quantiles per output. The quantiles of `n` draws are
    /// known to about `±1/√n` in probability (`n = 2000`: the 2.5 % quantile lies between the
    /// 1.8 % and 3.2 % points).
    ///
    /// The crate README's example (`examples/analytic.rs`, run as a doc test) pushes a
    /// calibrated load through a toy prediction model (its peak and resultant).
    pub fn predict_through(
        &self,
        model: &dyn PredictionModel,
        x: &[f64],
        n_draws: usize,
        seed: u64,
    ) -> Result<Band> {
        if n_draws < 40 {
            return Err(BamudiError::config(
                "n_draws",
                format!("need at least 40 draws for a 95 % band, got {n_draws}"),
            ));
        }
        let n_out = model.output_names().len();
        let draws = self.response_draws(x, n_draws, seed)?;
        let mut values = vec![Vec::with_capacity(n_draws); n_out];
        let mut out = vec![0.0; n_out];
        for d in &draws {
            model.evaluate(x, &d.theta, &d.response, &mut out)?;
            for (v, o) in values.iter_mut().zip(&out) {
                v.push(*o);
            }
        }
        Ok(empirical_band(values))
    }
}

/// Mean, sd and the 2.5 % / 97.5 % empirical quantiles (linear interpolation between order
/// statistics) per output. An output with no values gets NaN throughout.
pub fn empirical_band(mut values: Vec<Vec<f64>>) -> Band {
    let mut band = Band {
        mean: vec![],
        sd: vec![],
        lower: vec![],
        upper: vec![],
    };
    for v in &mut values {
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let var = v.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
        band.mean.push(mean);
        band.sd.push(var.sqrt());
        band.lower.push(interpolated_quantile(v, 0.025));
        band.upper.push(interpolated_quantile(v, 0.975));
    }
    band
}

/// The `p` quantile of `v` interpolated linearly between the order statistics at
/// `p (n − 1)`: the value a full sort gives, bit for bit (the same two order statistics under
/// the same total order), found by selection in `O(n)` (a band over a quoin's outputs sorted
/// 2,000 vectors of 1,000 draws before). Reorders `v`; NaN when `v` is empty.
fn interpolated_quantile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let pos = p * (v.len() - 1) as f64;
    let (i, f) = (pos.floor() as usize, pos.fract());
    let (_, lo, above) = v.select_nth_unstable_by(i, f64::total_cmp);
    let lo = *lo;
    let hi = above.iter().copied().min_by(f64::total_cmp).unwrap_or(lo);
    lo + f * (hi - lo)
}

/// Largest negative eigenvalue, relative to the largest, that [`covariance_factor`] sets to
/// zero. The marginal mode's coefficient covariance at `x` is the prior minus what the data
/// explain (`MarginalState::coefficient_cov`, in the eigenbasis of the low-rank prior): where
/// the data pin a direction down, the numerical error of that subtraction and of the
/// eigen-decompositions behind it can exceed the small posterior eigenvalues (measured:
/// −4.3e-5 of the largest at a low-head experiment of an as-built gate, where `bamudi
/// predict` failed before). Anything more negative is not numerical error and stays an
/// error.
const INDEFINITE_TOLERANCE: f64 = 1e-3;

/// A factor `F` with `F Fᵀ = cov`: the Cholesky factor, or, when `cov` is indefinite by
/// round-off of the low-rank prior (see [`INDEFINITE_TOLERANCE`]), the eigen-factor with the
/// negative eigenvalues set to zero (logged).
fn covariance_factor(cov: &nalgebra::DMatrix<f64>, x: &[f64]) -> Result<nalgebra::DMatrix<f64>> {
    let what = "coefficient covariance at x";
    let chol_err = match numerics::Cholesky::new(cov, what) {
        Ok(c) => return Ok(c.l()),
        Err(e) => e,
    };
    let eig = numerics::SymmetricEigen::new(cov, what)?;
    let max = eig.values.iter().copied().fold(0.0f64, f64::max);
    let min = eig.values.iter().copied().fold(f64::INFINITY, f64::min);
    if min < -INDEFINITE_TOLERANCE * max {
        return Err(BamudiError::Numerical {
            context: format!("{what} = {x:?}"),
            reason: format!(
                "smallest eigenvalue {min:.3e} against a largest of {max:.3e}, beyond the \
                 {INDEFINITE_TOLERANCE:e} that numerical error explains ({chol_err})"
            ),
        });
    }
    log::warn!(
        "{what} {x:?} is indefinite (smallest eigenvalue {min:.3e}, largest {max:.3e}); the \
         negative eigenvalues are set to zero"
    );
    let n = cov.nrows();
    Ok(nalgebra::DMatrix::from_fn(n, n, |i, j| {
        eig.vectors[(i, j)] * eig.values[j].max(0.0).sqrt()
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    proptest::proptest! {
        /// Selection gives the sorted sample's interpolated quantile bit for bit, ties, signed
        /// zeros and infinities included.
        #[test]
        fn selected_quantiles_are_the_sorted_ones(
            v in proptest::collection::vec(
                proptest::prop_oneof![
                    -1e3..1e3f64,
                    proptest::strategy::Just(0.0),
                    proptest::strategy::Just(-0.0),
                    proptest::strategy::Just(1.5),
                    proptest::strategy::Just(f64::INFINITY),
                ],
                1..300,
            ),
            p in 0.0..=1.0f64,
        ) {
            let mut sorted = v.clone();
            sorted.sort_by(f64::total_cmp);
            let pos = p * (sorted.len() - 1) as f64;
            let (i, f) = (pos.floor() as usize, pos.fract());
            let expected = sorted[i] + f * (sorted[(i + 1).min(sorted.len() - 1)] - sorted[i]);
            let got = interpolated_quantile(&mut v.clone(), p);
            proptest::prop_assert!(
                got.to_bits() == expected.to_bits() || (got.is_nan() && expected.is_nan()),
                "{got} vs {expected}"
            );
        }
    }

    #[test]
    fn empirical_quantiles_of_a_known_sample() {
        let v: Vec<f64> = (0..=1000).map(|i| i as f64).collect();
        let b = empirical_band(vec![v]);
        assert_eq!(b.mean[0], 500.0);
        assert!((b.lower[0] - 25.0).abs() < 1e-9 && (b.upper[0] - 975.0).abs() < 1e-9);
    }

    #[test]
    fn a_slightly_indefinite_covariance_is_factored_and_a_clearly_indefinite_one_is_refused() {
        // eigenvalues 4, 1 and −1e-3 (relative −2.5e-4: beyond the Cholesky jitter ladder's top,
        // 1e-4 of the mean diagonal, within the tolerance) in a rotated basis
        let r = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1).into_inner();
        let q = nalgebra::DMatrix::from_fn(3, 3, |i, j| r[(i, j)]);
        let with = |l: [f64; 3]| {
            let d = nalgebra::DMatrix::from_diagonal(&nalgebra::DVector::from_row_slice(&l));
            &q * d * q.transpose()
        };
        let f = covariance_factor(&with([4.0, 1.0, -1e-3]), &[0.0]).unwrap();
        // F Fᵀ is the matrix with the negative eigenvalue set to zero (round-off only)
        assert!((&f * f.transpose() - with([4.0, 1.0, 0.0])).amax() < 1e-12);
        // the refusal names the input and both eigenvalues (a user's only lead)
        let e = covariance_factor(&with([4.0, 1.0, -0.1]), &[7.5]).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains("[7.5]") && text.contains("-1.000e-1") && text.contains("4.000e0"),
            "{text}"
        );
        // positive definite: the Cholesky factor, as before
        let c = with([4.0, 1.0, 0.5]);
        let l = covariance_factor(&c, &[0.0]).unwrap();
        assert_eq!(l, numerics::Cholesky::new(&c, "c").unwrap().l());
    }
}
