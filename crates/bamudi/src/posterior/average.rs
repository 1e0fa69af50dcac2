//! Is there a discrepancy at all? The two models of Module 3 weighed by their evidence.
//!
//! The marginal mode fits `y = ρ A g(x, θ) + b(x, θ) + B α(x) + ε` (model 1, the discrepancy
//! integrated out) and, beside it, the strongest calibration without one (model 0, `α = 0`:
//! [`super::no_discrepancy`]). When the truth has no discrepancy the gauges cannot tell the two
//! apart, but model 1's `θ` posterior is wider: a discrepancy could mimic part of any change in
//! `θ`. Near the gap's edge the contact force changes by thousands of lbf/in per inch of `θ`,
//! so that width alone made the corrected force 2.6-9.6x worse than model 0's on truths
//! without a discrepancy (`docs/results/validation.md`): spurious force.
//!
//! [`DiscrepancyPresence::Weighed`](crate::params::DiscrepancyPresence::Weighed) lets the data
//! say which model holds. Each posterior on the `θ` grid carries its log evidence
//! `ln Z_k = ln ∫ p(y | θ, M_k) p(θ) dθ` ([`GridPosterior::log_evidence`]; `ρ` integrated over
//! its prior in both, the noise and the discrepancy's hyper-parameters at their maximum
//! likelihood). Model 1 has two hyper-parameters model 0 lacks (the amplitude `s` and the
//! length-scale factor); Schwarz's approximation of integrating them over a prior charges it
//! `½ ln N_s` nats each ([`ModelAverage::penalty`]; none when they are held,
//! [`MarginalPrior::fixed`](crate::MarginalPrior::fixed)). With even prior odds,
//!
//! `P(M_0 | y) = 1 / (1 + exp(ln Z_1 − penalty − ln Z_0))`,
//!
//! and Module 4 predicts with the mixture: the force, the strains, their joint draws and the
//! reconstructed discrepancy are `P(M_1|y)` times the discrepancy model's plus `P(M_0|y)`
//! times the fit without one ([`crate::Predictor::response`]). The second component keeps the
//! spread of the correction model 1 cannot exclude (its coefficients' covariance at `x`, mostly
//! the directions the gauges do not see): the evidence says the data need no correction, not
//! that the model is exact. A discrepancy the gauges see costs model 0 `N_s ln(σ_0/σ_1)` nats
//! (hundreds on the paper's data), so there the weighing changes nothing.
//!
//! **The gap's interval is not weighed**: it stays the discrepancy model's
//! ([`super::Module3::posterior`]). A discrepancy just below what the evidence detects still
//! moves `θ`, and the mixture's narrow `θ` then misses: on the quick study (seed 5151, 30
//! replicates, the paper's discrepancy at 0.3 times its size) the mixture's 95 % interval held
//! `θ*` in 0.70 of scenario 1's replicates (mean z +1.10), the discrepancy model's in 1.00. The
//! force bands of the mixture held the truth there (0.99), because they keep the spread above.
//! The mixture of the two `θ` posteriors is kept in [`ModelAverage::posterior`] for what it
//! is: the `θ`s the predictions average over.

use super::theta::{GridPosterior, ThetaPosterior};
use crate::error::Result;
use serde::{Deserialize, Serialize};

/// The two models weighed by their evidence (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelAverage {
    /// `ln Z_1`: the log evidence with the discrepancy (nats).
    pub log_evidence_with: f64,
    /// `ln Z_0`: the log evidence without it (nats).
    pub log_evidence_without: f64,
    /// Nats charged to model 1 for its fitted hyper-parameters: `½ ln N_s` each (Schwarz),
    /// `0` when they are held.
    pub penalty: f64,
    /// `P(M_0 | y)`: the posterior probability that the data hold no discrepancy the model
    /// class lacks.
    pub probability_without: f64,
    /// The mixture of the two `θ` posteriors with these weights: the `θ`s Module 4's
    /// predictions average over. Not the gap's interval (see the module docs).
    pub posterior: ThetaPosterior,
}

impl ModelAverage {
    /// The weighing of the grid posteriors `with` and `without` (the same nodes) for `n_s`
    /// observations and `hyper` hyper-parameters model 1 fits beyond model 0. `None` when a
    /// posterior is not a grid one (MCMC draws carry no evidence), or the two grids differ (a
    /// node where one density is not finite).
    ///
    /// ```
    /// use bamudi::posterior::ModelAverage;
    /// use bamudi::posterior::{GridPosterior, ThetaPosterior};
    /// let theta: Vec<f64> = (0..401).map(|i| -8.0 + 16.0 * i as f64 / 400.0).collect();
    /// let normal = |m: f64, c: f64| -> ThetaPosterior {
    ///     let l = theta.iter().map(|t| c - 0.5 * (t - m) * (t - m)).collect();
    ///     ThetaPosterior::Grid(GridPosterior::new(theta.clone(), l).unwrap())
    /// };
    /// // model 1 fits 2 more hyper-parameters on 100 observations: ln 100 = 4.6 nats; its
    /// // evidence is 4.6 nats higher, so the two are even
    /// let avg = ModelAverage::weigh(&normal(-1.0, 100f64.ln()), &normal(1.0, 0.0), 100, 2)
    ///     .unwrap()
    ///     .unwrap();
    /// assert!((avg.probability_without - 0.5).abs() < 1e-9);
    /// assert!(avg.posterior.mean()[0].abs() < 1e-6); // the even mixture of N(-1, 1), N(1, 1)
    /// assert!((avg.posterior.sd()[0] - 2f64.sqrt()).abs() < 1e-3);
    /// ```
    pub fn weigh(
        with: &ThetaPosterior,
        without: &ThetaPosterior,
        n_s: usize,
        hyper: usize,
    ) -> Result<Option<Self>> {
        let (ThetaPosterior::Grid(w1), ThetaPosterior::Grid(w0)) = (with, without) else {
            return Ok(None);
        };
        if w1.theta != w0.theta {
            // the interpolation subdivides only between finite nodes, so a node outside one
            // model's support gives the two different grids: no common mixture
            log::warn!("model weighing skipped: the two θ posteriors are not on one grid");
            return Ok(None);
        }
        let (z1, z0) = (w1.log_evidence(), w0.log_evidence());
        let penalty = 0.5 * hyper as f64 * (n_s.max(1) as f64).ln();
        let probability_without = 1.0 / (1.0 + (z1 - penalty - z0).exp());
        let posterior = mixture(w1, w0, probability_without)?;
        Ok(Some(Self {
            log_evidence_with: z1,
            log_evidence_without: z0,
            penalty,
            probability_without,
            posterior,
        }))
    }

    /// `P(M_1 | y)`.
    pub fn probability_with(&self) -> f64 {
        1.0 - self.probability_without
    }
}

/// `(1 − p0) with + p0 without` on their shared nodes.
fn mixture(with: &GridPosterior, without: &GridPosterior, p0: f64) -> Result<ThetaPosterior> {
    if with.theta != without.theta {
        return Err(crate::error::BamudiError::Calibration(
            "model averaging: the two θ posteriors are not on the same grid".into(),
        ));
    }
    let (l1, l0) = ((1.0 - p0).ln(), p0.ln());
    let log_density = with
        .density
        .iter()
        .zip(&without.density)
        .map(|(d1, d0)| {
            let (a, b) = (l1 + d1.ln(), l0 + d0.ln());
            let m = a.max(b);
            match m.is_finite() {
                true => m + ((a - m).exp() + (b - m).exp()).ln(),
                // both densities underflow here: the lowest finite value, which weighs nothing
                // and survives a JSON round trip (JSON has no infinity: serde writes null)
                false => f64::MIN,
            }
        })
        .collect();
    let mut post = GridPosterior::new(with.theta.clone(), log_density)?;
    post.evaluated = with.evaluated.clone();
    Ok(ThetaPosterior::Grid(post))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two narrow, distant posteriors: their mixture has nodes where both densities underflow,
    /// and the weighing survives a JSON round trip (a saved calibration is read back).
    #[test]
    fn a_mixture_with_underflowing_nodes_round_trips_through_json() {
        let theta: Vec<f64> = (0..201).map(|i| i as f64 / 10.0).collect();
        let narrow = |m: f64, c: f64| {
            let l = theta
                .iter()
                .map(|t| c - 0.5 * ((t - m) / 0.05).powi(2))
                .collect();
            ThetaPosterior::Grid(GridPosterior::new(theta.clone(), l).unwrap())
        };
        let avg = ModelAverage::weigh(&narrow(2.0, 0.0), &narrow(18.0, 1.0), 50, 2)
            .unwrap()
            .unwrap();
        let ThetaPosterior::Grid(g) = &avg.posterior else {
            panic!("a grid mixture")
        };
        assert!(g.density[100] == 0.0 && g.log_density.iter().all(|l| l.is_finite()));
        let text = serde_json::to_string(&avg).unwrap();
        let back: ModelAverage = serde_json::from_str(&text).unwrap();
        assert_eq!(back, avg);
        // 1 nat more evidence without, ½ ln 50 x 2 = 3.9 charged with: P(M0) = 1/(1 + e^-4.9)
        let want = 1.0 / (1.0 + (-1.0 - 50f64.ln()).exp());
        assert!(
            (avg.probability_without - want).abs() < 1e-6,
            "{}",
            avg.probability_without
        );
    }
}
