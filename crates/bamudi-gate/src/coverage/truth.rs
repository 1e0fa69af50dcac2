//! The realities of the coverage study: the contact model at `θ*` scaled by `ρ`, plus a true
//! discrepancy whose shape is chosen, none of which the calibration's discrepancy basis
//! contains exactly.

use crate::error::Result;
use mitergate::ContactModel;
use mitergate::data::truth::true_discrepancy;
use rand::SeedableRng;
use rand::rngs::StdRng;
use serde::{Deserialize, Serialize};

/// The shape of the true discrepancy `δ(x)` along the quoin (lbf/in).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum DiscrepancyShape {
    /// The paper's Eq. 53-54: zero in the gap and a step to its full value at the gap's edge
    /// `θ*` (normal force `3 h (762 − d)³/1200³`, tangential `(h/100)² sin(d/240)`, `h` the
    /// head).
    Paper,
    /// The same expressions without the gap: every point, also below `θ*`.
    Unmasked,
    /// The paper's expressions rising smoothly from zero at the gap's edge
    /// (`1 − exp(−(d − θ*)/60 in)`): zero in the gap, no step.
    Tapered,
    /// No discrepancy: the model class holds the truth.
    None,
}

/// Length over which the tapered shape rises (in).
const TAPER_IN: f64 = 60.0;

impl DiscrepancyShape {
    /// `δ` at levels `x` (in) on the quoin points `d_u` (in) for the gap `theta_star` (in),
    /// component blocked (normal, then tangential).
    pub fn delta(self, x: [f64; 2], d_u: &[f64], theta_star: f64) -> Vec<f64> {
        match self {
            Self::Paper => true_discrepancy(x, d_u, theta_star, 1.0),
            Self::Unmasked => true_discrepancy(x, d_u, f64::NEG_INFINITY, 1.0),
            Self::None => vec![0.0; 2 * d_u.len()],
            Self::Tapered => {
                let mut d = true_discrepancy(x, d_u, theta_star, 1.0);
                let n = d_u.len();
                for (b, &z) in d_u.iter().enumerate() {
                    let ramp = 1.0 - (-(z - theta_star).max(0.0) / TAPER_IN).exp();
                    d[b] *= ramp;
                    d[n + b] *= ramp;
                }
                d
            }
        }
    }
}

/// One replicate's reality.
#[derive(Debug, Clone, Copy)]
pub struct Truth {
    /// `θ*` (in).
    pub theta: f64,
    /// `ρ`.
    pub rho: f64,
    /// The discrepancy's shape.
    pub shape: DiscrepancyShape,
}

impl Truth {
    /// The true quoin forces `ρ g(x, θ*) + δ(x)` (lbf/in, blocked).
    pub fn forces(&self, contact: &ContactModel, x: [f64; 2]) -> Result<Vec<f64>> {
        let mut f = contact.solve(x[0], x[1], self.theta)?.forces;
        let delta = self.shape.delta(x, &contact.gate().nu_points, self.theta);
        f.iter_mut()
            .zip(&delta)
            .for_each(|(f, d)| *f = self.rho * *f + d);
        Ok(f)
    }

    /// Measured strains (microstrain, `levels.len() x N_o`) with gauge noise of sd
    /// `noise_sd`, reproducible from `seed`.
    pub fn strains(
        &self,
        contact: &ContactModel,
        levels: &[[f64; 2]],
        noise_sd: f64,
        seed: u64,
    ) -> Result<nalgebra::DMatrix<f64>> {
        let gate = contact.gate();
        let mut rng = StdRng::seed_from_u64(seed);
        let mut y = nalgebra::DMatrix::zeros(levels.len(), gate.n_gauges());
        for (i, x) in levels.iter().enumerate() {
            let clean = gate.strain(&self.forces(contact, *x)?, x[0], x[1]);
            for (q, c) in clean.iter().enumerate() {
                y[(i, q)] = c + noise_sd * numerics::random::standard_normal(&mut rng);
            }
        }
        Ok(y)
    }
}
