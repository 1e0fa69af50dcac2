//! A true discrepancy drawn from the calibration's own prior, for simulation-based calibration
//! (SBC): if the calibration is exact, the ranks of the truth among its posteriors are uniform.
//!
//! The draw follows the marginal mode's isotropic prior
//! ([`bamudi::CoefficientScales::Isotropic`]) term by term: every coefficient function is
//! `α_k(x) = √s a(x) (z_k(x) + β_k)` with `z_k` a Gaussian process of the calibration's kernel
//! (Matérn 5/2, length scales half the range the experiments span times the factor `f`),
//! `β_k ~ N(0, c)` its level, `a(x)` the root mean square of the nominal response
//! `g(x, θ̄)` at the prior mean `θ̄`, and `s` the amplitude; the discrepancy is `L α(x)` on the
//! basis supported above the true gap `θ*` and orthonormalised as the calibration's is
//! ([`bamudi::internals::orthonormalised`]). It is drawn jointly at every input the
//! replicate uses (its experiments and its new conditions) and looked up there.

use crate::error::{GateAppError, Result};
use bamudi::internals::orthonormalised;
use bamudi::posterior::CoefficientPrior;
use mitergate::{ContactModel, GateMultiLevel};
use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand::rngs::StdRng;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// The prior's hyper-parameters the discrepancy is drawn with (and, in the first half of
/// SBC, the calibration holds).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GeneratingHyper {
    /// The amplitude `s`.
    pub amplitude: f64,
    /// The factor `f` on the length scales.
    pub length_scale_factor: f64,
    /// The level variance `c` (relative to the process's).
    pub level_variance: f64,
    /// The gauges' noise sd (µε).
    pub noise_sd: f64,
}

/// A discrepancy drawn at a set of inputs (see the module docs).
#[derive(Debug, Clone)]
pub struct DrawnDelta {
    at: HashMap<[u64; 2], Vec<f64>>,
}

impl DrawnDelta {
    /// Draws `δ` jointly at `inputs` for the gap `theta_star` on `model`'s basis, the kernel's
    /// length scales from `experiments` (the inputs the calibration sees), scales `a(x)` at
    /// `theta_bar`, reproducible from `seed`.
    pub fn draw(
        model: &GateMultiLevel,
        contact: &ContactModel,
        (theta_star, theta_bar): (f64, f64),
        experiments: &[[f64; 2]],
        inputs: &[[f64; 2]],
        hyper: &GeneratingHyper,
        seed: u64,
    ) -> Result<Self> {
        let n = inputs.len();
        let half = |j: usize| {
            let (lo, hi) = experiments
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                    (lo.min(x[j]), hi.max(x[j]))
                });
            let h = 0.5 * (hi - lo);
            if h > 0.0 { h } else { 1.0 }
        };
        let prior = CoefficientPrior {
            kernel: gp::Kernel::Matern52 { ard: true },
            length_scales: (0..2)
                .map(|j| half(j) * hyper.length_scale_factor)
                .collect(),
            level_variance: hyper.level_variance,
        };
        let xm = DMatrix::from_fn(n, 2, |i, j| inputs[i][j]);
        let scale: Vec<f64> = inputs
            .iter()
            .map(|x| {
                let g = contact.solve(x[0], x[1], theta_bar)?.forces;
                Ok((g.iter().map(|v| v * v).sum::<f64>() / g.len().max(1) as f64).sqrt())
            })
            .collect::<Result<_>>()?;
        let k = prior.matrix(&xm, &xm);
        let cov = DMatrix::from_fn(n, n, |i, j| {
            hyper.amplitude * scale[i] * scale[j] * k[(i, j)]
        });
        let eig = numerics::SymmetricEigen::new(&cov, "covariance of the drawn discrepancy")
            .map_err(|e| GateAppError::Option(format!("drawn discrepancy: {e}")))?;
        let root = &eig.vectors * DMatrix::from_diagonal(&eig.values.map(|v| v.max(0.0).sqrt()));
        let l0 = model.basis.block_matrix();
        let nu = contact.gate().n_points();
        let w = contact.coverage(theta_star);
        let masked = DMatrix::from_fn(l0.nrows(), l0.ncols(), |r, c| l0[(r, c)] * w[r % nu]);
        let l = orthonormalised(&masked)?;
        let n_k = l.ncols();
        let mut rng = StdRng::seed_from_u64(seed);
        let mut alpha = DMatrix::zeros(n, n_k);
        for c in 0..n_k {
            let z = DVector::from_fn(n, |_, _| numerics::random::standard_normal(&mut rng));
            alpha.set_column(c, &(&root * z));
        }
        let at = (0..n)
            .map(|i| {
                let delta = &l * alpha.row(i).transpose();
                (key(inputs[i]), delta.iter().copied().collect())
            })
            .collect();
        Ok(Self { at })
    }

    /// `δ` at `x` (one of the inputs it was drawn at).
    pub fn delta(&self, x: [f64; 2]) -> Result<Vec<f64>> {
        self.at.get(&key(x)).cloned().ok_or_else(|| {
            GateAppError::Option(format!(
                "drawn discrepancy: levels ({}, {}) in are not among the inputs it was drawn at",
                x[0], x[1]
            ))
        })
    }
}

fn key(x: [f64; 2]) -> [u64; 2] {
    [x[0].to_bits(), x[1].to_bits()]
}
