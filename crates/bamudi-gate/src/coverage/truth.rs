//! The realities of the coverage study: the contact model at `θ*` scaled by `ρ`, plus a true
//! discrepancy whose shape is chosen, none of which the calibration's discrepancy basis
//! contains exactly.

pub use super::delta_file::DeltaFile;
pub use super::drawn::DrawnDelta;
use crate::error::Result;
use mitergate::ContactModel;
use mitergate::data::truth::true_discrepancy;
use rand::SeedableRng;
use rand::rngs::StdRng;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// The shape of the true discrepancy `δ(x)` along the quoin (lbf/in).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum DiscrepancyShape {
    /// The paper's Eq. 53-54: zero in the gap and a step to its full value at the gap's edge
    /// `θ*` (normal force `3 h (762 − d)³/1200³`, tangential `(h/100)² sin(d/240)`, `h` the
    /// head).
    Paper,
    /// The paper's expressions with the quoin point that straddles the gap's edge loaded by
    /// its contact coverage at `θ*` ([`ContactModel::coverage`]: the fraction of the point's
    /// lower cell above `θ*`), the convention of the contact model's own forces: the step
    /// sits at `θ*` rather than at the first point above it.
    PaperCell,
    /// The paper's normal discrepancy alone (Eq. 53; no tangential part).
    PaperNormal,
    /// The paper's tangential discrepancy alone (Eq. 54; no normal part).
    PaperTangential,
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
    /// `δ` at levels `x` (in) on the quoin points of `contact`'s gate for the gap `theta_star`
    /// (in), component blocked (normal, then tangential).
    pub fn delta(self, contact: &ContactModel, x: [f64; 2], theta_star: f64) -> Vec<f64> {
        let d_u = &contact.gate().nu_points;
        match self {
            Self::Paper => true_discrepancy(x, d_u, theta_star, 1.0),
            Self::PaperCell => {
                let mut d = true_discrepancy(x, d_u, theta_star, 1.0);
                let n = d_u.len();
                for (b, c) in contact.coverage(theta_star).into_iter().enumerate() {
                    d[b] *= c;
                    d[n + b] *= c;
                }
                d
            }
            Self::Unmasked => true_discrepancy(x, d_u, f64::NEG_INFINITY, 1.0),
            Self::None => vec![0.0; 2 * d_u.len()],
            Self::PaperNormal | Self::PaperTangential => {
                let mut d = true_discrepancy(x, d_u, theta_star, 1.0);
                let n = d_u.len();
                let zeroed = if self == Self::PaperNormal {
                    n..2 * n
                } else {
                    0..n
                };
                d[zeroed].fill(0.0);
                d
            }
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

/// The true discrepancy of one replicate.
#[derive(Debug, Clone)]
pub enum TrueDelta {
    /// A shape of the library times a factor (1: its stated magnitude).
    Shape {
        /// The shape.
        shape: DiscrepancyShape,
        /// The factor.
        scale: f64,
    },
    /// A user's discrepancy, given as a table or as coefficients ([`DeltaFile`]).
    File(Arc<DeltaFile>),
    /// Drawn from the calibration's own prior at the replicate's inputs ([`DrawnDelta`]):
    /// simulation-based calibration.
    Drawn(Arc<DrawnDelta>),
}

impl TrueDelta {
    /// `δ` at levels `x` (in) on the quoin points of `contact`'s gate for the gap `theta_star`
    /// (in), component blocked (lbf/in).
    pub fn delta(&self, contact: &ContactModel, x: [f64; 2], theta_star: f64) -> Result<Vec<f64>> {
        match self {
            Self::Shape { shape, scale } => {
                let mut d = shape.delta(contact, x, theta_star);
                d.iter_mut().for_each(|v| *v *= scale);
                Ok(d)
            }
            Self::File(f) => f.delta(contact, x, theta_star),
            Self::Drawn(d) => d.delta(x),
        }
    }

    /// A short name for reports: `paper`, `paper x2`, `file gate-delta.csv`, `drawn from the
    /// prior`.
    pub fn label(&self) -> String {
        match self {
            Self::Shape { shape, scale } => {
                let name = serde_json::to_value(shape)
                    .ok()
                    .and_then(|v| v.as_str().map(String::from))
                    .unwrap_or_default();
                match *scale == 1.0 {
                    true => name,
                    false => format!("{name} x{scale}"),
                }
            }
            Self::File(f) => format!("file {}", f.name),
            Self::Drawn(_) => "drawn from the calibration's prior".into(),
        }
    }
}

/// One replicate's reality.
#[derive(Debug, Clone)]
pub struct Truth {
    /// `θ*` (in).
    pub theta: f64,
    /// `ρ`.
    pub rho: f64,
    /// The true discrepancy.
    pub delta: TrueDelta,
}

impl Truth {
    /// A truth with a library shape at its stated magnitude.
    pub fn new(theta: f64, rho: f64, shape: DiscrepancyShape) -> Self {
        Self {
            theta,
            rho,
            delta: TrueDelta::Shape { shape, scale: 1.0 },
        }
    }

    /// The true quoin forces `ρ g(x, θ*) + δ(x)` (lbf/in, blocked).
    pub fn forces(&self, contact: &ContactModel, x: [f64; 2]) -> Result<Vec<f64>> {
        let mut f = contact.solve(x[0], x[1], self.theta)?.forces;
        let delta = self.delta.delta(contact, x, self.theta)?;
        f.iter_mut()
            .zip(&delta)
            .for_each(|(f, d)| *f = self.rho * *f + d);
        Ok(f)
    }

    /// The truth's model part `ρ g(x, θ*)` (lbf/in, blocked): the true forces without the
    /// discrepancy.
    pub fn model_part(&self, contact: &ContactModel, x: [f64; 2]) -> Result<Vec<f64>> {
        let mut f = contact.solve(x[0], x[1], self.theta)?.forces;
        f.iter_mut().for_each(|f| *f *= self.rho);
        Ok(f)
    }

    /// The truth's identified `ρ⊥` at the experiments `levels`: `Σ aᵀ A F / Σ aᵀa` with
    /// `a = A g(x_i, θ*)` and `F` the true forces, the value a calibration's
    /// [`bamudi::posterior::MarginalFit::rho_projection`] estimates (noise-free).
    pub fn projection_rho(&self, contact: &ContactModel, levels: &[[f64; 2]]) -> Result<f64> {
        let a_mat = &contact.gate().a_matrix;
        let (mut num, mut den) = (0.0, 0.0);
        for x in levels {
            let g = nalgebra::DVector::from_vec(contact.solve(x[0], x[1], self.theta)?.forces);
            let f = nalgebra::DVector::from_vec(self.forces(contact, *x)?);
            let (ag, af) = (a_mat * g, a_mat * f);
            num += ag.dot(&af);
            den += ag.dot(&ag);
        }
        Ok(num / den.max(1e-300))
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

#[cfg(test)]
mod tests {
    use super::*;
    use mitergate::contact::ContactParams;

    /// `PaperCell` is the paper's shape except at the point straddling the gap's edge, which
    /// carries the fraction of its discrepancy that its contact coverage says (points at 0,
    /// 190.5, 381, 571.5, 762 in; `θ* = 95.25` covers half of the second point's lower cell).
    #[test]
    fn the_cell_weighted_shape_differs_only_at_the_straddling_point() {
        let contact = ContactParams::default()
            .build(mitergate::testing::doc_gate())
            .unwrap();
        let x = [700.0, 50.0];
        let truth = |shape| Truth::new(95.25, 0.8, shape);
        let paper = truth(DiscrepancyShape::Paper).forces(&contact, x).unwrap();
        let cell = truth(DiscrepancyShape::PaperCell)
            .forces(&contact, x)
            .unwrap();
        let delta = DiscrepancyShape::Paper.delta(&contact, x, 95.25);
        let n = delta.len() / 2;
        for b in 0..2 * n {
            let expected = if b % n == 1 { 0.5 * delta[b] } else { 0.0 };
            // rounding of ρ g + δ at the scale of the forces (1e4 lbf/in)
            let tol = 1e-9 * paper[b].abs().max(1.0);
            assert!(
                ((paper[b] - cell[b]) - expected).abs() <= tol,
                "point {b}: paper {} cell {} delta {}",
                paper[b],
                cell[b],
                delta[b]
            );
        }
        assert!(delta[1] > 0.0, "the straddling point carries a discrepancy");
    }

    /// The normal and tangential parts of the paper's shape split it: each keeps its own
    /// component and zeroes the other, and together they are the paper's δ exactly.
    #[test]
    fn the_paper_shape_splits_into_its_components() {
        let contact = ContactParams::default()
            .build(mitergate::testing::doc_gate())
            .unwrap();
        let x = [700.0, 50.0];
        let paper = DiscrepancyShape::Paper.delta(&contact, x, 95.25);
        let normal = DiscrepancyShape::PaperNormal.delta(&contact, x, 95.25);
        let tangential = DiscrepancyShape::PaperTangential.delta(&contact, x, 95.25);
        let n = paper.len() / 2;
        assert!(normal[n..].iter().all(|&v| v == 0.0) && tangential[..n].iter().all(|&v| v == 0.0));
        assert!(normal[..n].iter().any(|&v| v != 0.0) && tangential[n..].iter().any(|&v| v != 0.0));
        for b in 0..2 * n {
            assert_eq!(normal[b] + tangential[b], paper[b], "entry {b}");
        }
    }
}
