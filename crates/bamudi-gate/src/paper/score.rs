//! Scoring a calibration against the synthetic truth (only here, never inside a calibration).

use super::{ForceRmse, StrainRmse};
use crate::baselines::{Baselines, ConditionForces, ErrorTally, SeenSubspace};
use crate::error::Result;
use bamudi::{Band, Calibration};
use mitergate::data::truth::{self, Scenario};
use mitergate::{ContactModel, GateMultiLevel};
use mlmodel::{LinearObservableModel, UnobservableModel};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub(super) fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (mut ss, mut n) = (0.0, 0usize);
    for v in values {
        ss += v * v;
        n += 1;
    }
    (ss / n.max(1) as f64).sqrt()
}

/// Prior-averaged response `Σ_j w_j g_u(x, θ_j)` (Eq. 2, Gauss quadrature of order 8 over the
/// gap prior), the "before calibration" model: contact line loads (lbf/in), blocked
/// `[F_N; F_T]`.
///
/// ```
/// let contact = mitergate::contact::ContactParams::default()
///     .build(mitergate::testing::doc_gate())
///     .unwrap();
/// let model = bamudi_gate::paper::gate_model(&contact, (60.0, 150.0)).unwrap();
/// let before = bamudi_gate::paper::prior_mean_response(&model, &[700.0, 100.0]).unwrap();
/// assert_eq!(before.len(), 10); // 5 points, normal and tangential
/// assert!(before[..5].iter().all(|&f| f >= 0.0)); // an average of no-tension forces
/// ```
pub fn prior_mean_response(model: &GateMultiLevel, x: &[f64]) -> Result<Vec<f64>> {
    let rule = model.prior.quadrature(8)?;
    weighted_response(model, x, rule.nodes.iter().map(|t| t[0]).zip(rule.weights))
}

fn weighted_response(
    model: &GateMultiLevel,
    x: &[f64],
    nodes: impl Iterator<Item = (f64, f64)>,
) -> Result<Vec<f64>> {
    let n = model.unobservable.response_len();
    let (mut acc, mut g) = (vec![0.0; n], vec![0.0; n]);
    for (theta, w) in nodes {
        model.unobservable.evaluate(x, &[theta], &mut g)?;
        acc.iter_mut().zip(&g).for_each(|(a, v)| *a += w * v);
    }
    Ok(acc)
}

/// Force and strain errors of one calibration at the new conditions.
pub(super) struct Scores {
    pub(super) force: ForceRmse,
    pub(super) strain: StrainRmse,
    pub(super) discrepancy: DiscrepancyScore,
    pub(super) baselines: Baselines,
}

/// The reconstructed discrepancy `δ̂ = L μ_α` against the true one (`f* − ρ* g(x, θ*)`, the
/// part of the true force the model's response does not carry) at the new conditions.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct DiscrepancyScore {
    /// RMS of the true normal discrepancy (lbf/in).
    pub normal_true_rms: f64,
    /// RMSE of `δ̂` against it, normal (lbf/in).
    pub normal_rmse: f64,
    /// RMS of the true tangential discrepancy (lbf/in).
    pub tangential_true_rms: f64,
    /// RMSE of `δ̂`, tangential (lbf/in).
    pub tangential_rmse: f64,
    /// Fraction of (condition, quoin point) pairs whose true normal discrepancy lies in the
    /// 95 % band of `δ̂` (pairs where both are identically zero, in the gap, left out).
    pub normal_band_coverage: f64,
    /// The same, tangential.
    pub tangential_band_coverage: f64,
}

/// Accumulates `(true, band)` pairs of one component.
#[derive(Default)]
struct DeltaTally {
    truth_sq: Vec<f64>,
    err: Vec<f64>,
    inside: usize,
    counted: usize,
}

impl DeltaTally {
    fn add(&mut self, truth: f64, band: &Band, b: usize) {
        self.truth_sq.push(truth);
        self.err.push(band.mean[b] - truth);
        if truth == 0.0 && band.sd[b] == 0.0 {
            return;
        }
        self.counted += 1;
        if (band.lower[b]..=band.upper[b]).contains(&truth) {
            self.inside += 1;
        }
    }

    /// `(true rms, rmse, band coverage)`.
    fn summary(self) -> (f64, f64, f64) {
        let cov = self.inside as f64 / self.counted.max(1) as f64;
        (
            rms(self.truth_sq.into_iter()),
            rms(self.err.into_iter()),
            cov,
        )
    }
}

/// `δ̂` against the true discrepancy at `new_x`.
fn discrepancy_score<U, O>(
    predictor: &bamudi::Predictor<'_, U, O>,
    scenario: &Scenario,
    contact: &ContactModel,
    new_x: &[[f64; 2]],
) -> Result<DiscrepancyScore>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let nu = contact.gate().n_points();
    let no_delta = scenario.clone().discrepancy_scale(0.0);
    // the conditions in parallel (contact solves), tallied in their order
    let per_x = new_x
        .par_iter()
        .map(|x| -> Result<_> {
            let with = truth::true_forces(scenario, contact, *x)?;
            let without = truth::true_forces(&no_delta, contact, *x)?;
            Ok((with, without, predictor.discrepancy(x)?))
        })
        .collect::<Vec<_>>() // every condition first: an error is then the first in their order
        .into_iter()
        .collect::<Result<Vec<_>>>()?;
    let (mut n, mut t) = (DeltaTally::default(), DeltaTally::default());
    for (with, without, band) in per_x {
        for b in 0..2 * nu {
            let tally = if b < nu { &mut n } else { &mut t };
            tally.add(with[b] - without[b], &band, b);
        }
    }
    let ((nt, ne, nc), (tt, te, tc)) = (n.summary(), t.summary());
    Ok(DiscrepancyScore {
        normal_true_rms: nt,
        normal_rmse: ne,
        tangential_true_rms: tt,
        tangential_rmse: te,
        normal_band_coverage: nc,
        tangential_band_coverage: tc,
    })
}

/// Force RMSE before/after, strain RMSE with/without the discrepancy, and every baseline
/// and oracle ([`crate::baselines`]) at `new_x`.
pub(super) fn score(
    model: &GateMultiLevel,
    cal: &Calibration,
    scenario: &Scenario,
    contact: &ContactModel,
    new_x: &[[f64; 2]],
) -> Result<Scores> {
    let nu = contact.gate().n_points();
    let predictor = cal.predictor(model)?;
    let no_delta = scenario.clone().discrepancy_scale(0.0);
    let seen = SeenSubspace::new(model, contact, scenario.theta_true)?;
    // the conditions in parallel (contact solves), the errors collected in their order
    let per_x = new_x
        .par_iter()
        .map(|x| condition(model, &predictor, scenario, &no_delta, contact, x))
        .collect::<Vec<_>>() // every condition first: an error is then the first in their order
        .into_iter()
        .collect::<Result<Vec<_>>>()?;
    let (mut dn_b, mut dn_a, mut dt_b, mut dt_a) = (vec![], vec![], vec![], vec![]);
    let (mut ds_w, mut ds_wo) = (vec![], vec![]);
    let mut tally = ErrorTally::default();
    for c in per_x {
        let (x, truth, before, after) = (c.x, &c.truth, &c.before, &c.after);
        let truth_f = truth;
        for b in 0..2 * nu {
            let (eb, ea) = (before[b] - truth_f[b], after[b] - truth_f[b]);
            if b < nu {
                dn_b.push(eb);
                dn_a.push(ea);
            } else {
                dt_b.push(eb);
                dt_a.push(ea);
            }
        }
        tally.add_condition(
            &ConditionForces {
                truth,
                model_part: &c.model_part,
                model_part_posterior: &c.posterior_part,
                prior_mean: before,
                no_discrepancy: &c.baseline,
                calibrated: after,
                delta_hat: &c.delta_hat,
            },
            &seen,
            nu,
        );
        let true_strain = contact.gate().strain(truth_f, x[0], x[1]);
        for p in 0..true_strain.len() {
            ds_w.push(c.with[p] - true_strain[p]);
            ds_wo.push(c.without[p] - true_strain[p]);
        }
    }
    Ok(Scores {
        force: ForceRmse {
            normal_before: rms(dn_b.into_iter()),
            normal_after: rms(dn_a.into_iter()),
            tangential_before: rms(dt_b.into_iter()),
            tangential_after: rms(dt_a.into_iter()),
        },
        strain: StrainRmse {
            with_discrepancy: rms(ds_w.into_iter()),
            without_discrepancy: rms(ds_wo.into_iter()),
        },
        discrepancy: discrepancy_score(&predictor, scenario, contact, new_x)?,
        baselines: tally.baselines(),
    })
}

/// What one new condition contributes to the scores.
struct Condition {
    x: [f64; 2],
    truth: Vec<f64>,
    model_part: Vec<f64>,
    before: Vec<f64>,
    after: Vec<f64>,
    with: Vec<f64>,
    without: Vec<f64>,
    baseline: Vec<f64>,
    delta_hat: Vec<f64>,
    posterior_part: Vec<f64>,
}

/// The truth, every prediction and the baselines at `x`.
fn condition(
    model: &GateMultiLevel,
    predictor: &bamudi::Predictor<'_, impl UnobservableModel, impl LinearObservableModel>,
    scenario: &Scenario,
    no_delta: &Scenario,
    contact: &ContactModel,
    x: &[f64; 2],
) -> Result<Condition> {
    Ok(Condition {
        x: *x,
        truth: truth::true_forces(scenario, contact, *x)?,
        model_part: truth::true_forces(no_delta, contact, *x)?,
        before: prior_mean_response(model, x)?,
        after: predictor.response_moments(x)?.0,
        with: predictor.outputs(x)?.mean,
        without: predictor.no_discrepancy_outputs(x)?.mean,
        baseline: predictor.no_discrepancy_response(x)?.mean,
        delta_hat: predictor.discrepancy(x)?.mean,
        posterior_part: posterior_model_part(predictor, scenario.rho, x)?,
    })
}

/// `ρ E[g(x, θ) | y]` over the predictor's `θ` support (lbf/in, blocked): the truth's model
/// part at the calibration's `θ` posterior.
pub(crate) fn posterior_model_part<U: UnobservableModel, O: LinearObservableModel>(
    predictor: &bamudi::Predictor<'_, U, O>,
    rho: f64,
    x: &[f64; 2],
) -> Result<Vec<f64>> {
    let model = predictor.model();
    let mut g = vec![0.0; model.unobservable.response_len()];
    let mut acc = vec![0.0; g.len()];
    for (theta, w) in predictor.support() {
        model.unobservable.evaluate(x, theta, &mut g)?;
        acc.iter_mut().zip(&g).for_each(|(a, v)| *a += rho * w * v);
    }
    Ok(acc)
}
