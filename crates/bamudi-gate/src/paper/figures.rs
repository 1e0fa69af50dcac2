//! The paper's Fig. 15 and Fig. 22 as numbers (the plots of `cargo xtask reproduce-paper` draw
//! the same series):
//!
//! * **Fig. 15**: the reconstructed discrepancy `δ̂` with its 95 % band against the true `δ`
//!   along the quoin, at the paper's condition of each scenario (738 / 360 in for scenario 1,
//!   426 / 120 in for scenario 2), normal and tangential: RMSE, band coverage, band half-width.
//! * **Fig. 22**: the force at location A over a week of lockages (an 8-h filling and emptying
//!   cycle on a daily tailwater swing, Fig. 21's shape): truth, before (the prior-mean model),
//!   the best fit without a discrepancy, and after with its band: RMSEs and band coverage.
//!   Location A is the first quoin point at or above a quarter of the quoin height
//!   ([`location_a`]): the paper's Fig. 10 marks A low on the quoin, above the
//!   gap, where the bearing force is large; a quarter of the height (190.5 in) lies above every
//!   gap of the prior (≤ 165 in), so A is always in contact and its force is never the gap's
//!   edge, whose error is θ's.

use super::prior_mean_response;
use crate::error::Result;
use bamudi::{Band, Calibration};
use mitergate::data::truth::{self, Scenario};
use mitergate::{ContactModel, GateMultiLevel};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The paper's plotting condition of Fig. 15 and 17 for scenario `number` (`[h_up, h_down]`).
pub fn condition(number: u8) -> [f64; 2] {
    if number == 1 {
        [738.0, 360.0]
    } else {
        [426.0, 120.0]
    }
}

/// A curve with a band against the truth.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct CurveScore {
    /// RMS of the truth (lbf/in).
    pub true_rms: f64,
    /// RMSE of the band's mean against the truth (lbf/in).
    pub rmse: f64,
    /// Fraction of points whose truth lies in the 95 % band (points where truth and band are
    /// identically zero, in the gap, left out).
    pub band_coverage: f64,
    /// Median half-width of the 95 % band over those points (lbf/in).
    pub median_halfwidth: f64,
}

/// Fig. 15's numbers.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Fig15 {
    /// The condition `[h_up, h_down]` (in).
    pub condition: [f64; 2],
    /// `δ̂` against `δ`, normal force.
    pub normal: CurveScore,
    /// The same, tangential.
    pub tangential: CurveScore,
}

/// The series of Fig. 15 at one condition.
pub struct DiscrepancyCurve {
    /// Quoin heights (in).
    pub d_in: Vec<f64>,
    /// True `δ` (blocked, lbf/in).
    pub truth: Vec<f64>,
    /// `δ̂` with its band (blocked).
    pub band: Band,
}

/// `δ̂` and the true `δ` along the quoin at the paper's condition of `scenario` (number 1 or 2).
pub fn discrepancy_curve(
    model: &GateMultiLevel,
    cal: &Calibration,
    scenario: &Scenario,
    contact: &ContactModel,
    number: u8,
) -> Result<DiscrepancyCurve> {
    let x = condition(number);
    let d_in = contact.gate().nu_points.clone();
    let truth = truth::true_discrepancy(x, &d_in, scenario.theta_true, scenario.discrepancy_scale);
    let band = cal.predictor(model)?.discrepancy(&x)?;
    Ok(DiscrepancyCurve { d_in, truth, band })
}

impl DiscrepancyCurve {
    /// The curve's scores.
    pub fn score(&self, condition: [f64; 2]) -> Fig15 {
        let n = self.d_in.len();
        Fig15 {
            condition,
            normal: curve_score(&self.truth[..n], &self.band, 0),
            tangential: curve_score(&self.truth[n..], &self.band, n),
        }
    }
}

/// [`CurveScore`] of `truth` against the band's entries from `offset`.
fn curve_score(truth: &[f64], band: &Band, offset: usize) -> CurveScore {
    let (mut ss_t, mut ss_e, mut inside, mut live) = (0.0, 0.0, 0usize, 0usize);
    let mut halves = Vec::new();
    for (i, &t) in truth.iter().enumerate() {
        let p = offset + i;
        ss_t += t * t;
        ss_e += (band.mean[p] - t).powi(2);
        if t == 0.0 && band.sd[p] == 0.0 {
            continue;
        }
        live += 1;
        inside += usize::from(band.lower[p] <= t && t <= band.upper[p]);
        halves.push(0.5 * (band.upper[p] - band.lower[p]));
    }
    let n = truth.len().max(1) as f64;
    CurveScore {
        true_rms: (ss_t / n).sqrt(),
        rmse: (ss_e / n).sqrt(),
        band_coverage: inside as f64 / live.max(1) as f64,
        median_halfwidth: numerics::robust::median(&mut halves),
    }
}

/// One force component at location A over the week against the truth.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct HistoryScore {
    /// RMS of the true force over the week (lbf/in).
    pub true_rms: f64,
    /// RMSE of the prior-mean model, `ρ = 1`, no discrepancy (lbf/in).
    pub rmse_before: f64,
    /// RMSE of the best fit without a discrepancy (lbf/in).
    pub rmse_no_discrepancy: f64,
    /// RMSE of the corrected force's posterior mean (lbf/in).
    pub rmse_after: f64,
    /// Fraction of times whose truth lies in the 95 % band.
    pub band_coverage: f64,
    /// Median half-width of the 95 % band (lbf/in).
    pub median_halfwidth: f64,
}

/// Fig. 22's numbers.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Fig22 {
    /// Height of location A on the quoin (in).
    pub location_in: f64,
    /// Normal force at A.
    pub normal: HistoryScore,
    /// Tangential force at A.
    pub tangential: HistoryScore,
}

/// The series of Fig. 22: per time, `[normal, tangential]` at location A.
pub struct ForceHistory {
    /// Hours from the start of the week.
    pub hours: Vec<f64>,
    /// Location A's index on the quoin and its height (in).
    pub location: (usize, f64),
    /// Truth, before, no-discrepancy fit, after (mean, lower, upper), per time, each
    /// `[normal, tangential]`.
    pub rows: Vec<[[f64; 2]; 6]>,
}

/// A quarter-hour step: the lockage cycle is 8 h, an hourly step draws it as a zig-zag.
const QUARTERS_PER_DAY: usize = 4 * 24;

/// The levels at hour `h` of the schedule: an 8-h filling and emptying cycle upstream and a
/// daily swing downstream (Fig. 21's shape).
pub fn levels_at(h: f64) -> [f64; 2] {
    let phase = (h / 8.0 * std::f64::consts::TAU).sin();
    [
        560.0 + 150.0 * phase.max(-0.9),
        60.0 + 20.0 * (h / 24.0 * std::f64::consts::TAU).cos(),
    ]
}

/// The forces at location A over a week. The schedule repeats every day, so one day is
/// computed and the week repeats it (day `k`'s levels differ from day 0's by the rounding of
/// `sin` and `cos` at larger arguments, 2.7e-12 in at most).
pub fn force_history(
    model: &GateMultiLevel,
    cal: &Calibration,
    scenario: &Scenario,
    contact: &ContactModel,
) -> Result<ForceHistory> {
    let gate = contact.gate();
    let nu = gate.n_points();
    let a = location_a(gate);
    let hours: Vec<f64> = (0..=7 * QUARTERS_PER_DAY).map(|q| q as f64 / 4.0).collect();
    let predictor = cal.predictor(model)?;
    let day: Vec<[[f64; 2]; 6]> = hours[..QUARTERS_PER_DAY]
        .par_iter()
        .map(|&h| -> Result<[[f64; 2]; 6]> {
            let x = levels_at(h);
            let t = truth::true_forces(scenario, contact, x)?;
            let b = prior_mean_response(model, &x)?;
            let nd = predictor.no_discrepancy_response(&x)?.mean;
            let r = predictor.response(&x)?;
            let pick = |v: &[f64]| [v[a], v[nu + a]];
            Ok([
                pick(&t),
                pick(&b),
                pick(&nd),
                pick(&r.mean),
                pick(&r.lower),
                pick(&r.upper),
            ])
        })
        .collect::<Vec<_>>() // every row first: an error is then the first in their order
        .into_iter()
        .collect::<Result<_>>()?;
    let rows = (0..hours.len())
        .map(|q| day[q % QUARTERS_PER_DAY])
        .collect();
    Ok(ForceHistory {
        hours,
        location: (a, gate.nu_points[a]),
        rows,
    })
}

impl ForceHistory {
    /// The history's scores.
    pub fn score(&self) -> Fig22 {
        let comp = |c: usize| {
            let n = self.rows.len().max(1) as f64;
            let rms = |k: usize| {
                (self
                    .rows
                    .iter()
                    .map(|r| (r[k][c] - r[0][c]).powi(2))
                    .sum::<f64>()
                    / n)
                    .sqrt()
            };
            let inside = self
                .rows
                .iter()
                .filter(|r| r[4][c] <= r[0][c] && r[0][c] <= r[5][c])
                .count();
            let mut halves: Vec<f64> = self
                .rows
                .iter()
                .map(|r| 0.5 * (r[5][c] - r[4][c]))
                .collect();
            HistoryScore {
                true_rms: (self.rows.iter().map(|r| r[0][c] * r[0][c]).sum::<f64>() / n).sqrt(),
                rmse_before: rms(1),
                rmse_no_discrepancy: rms(2),
                rmse_after: rms(3),
                band_coverage: inside as f64 / n,
                median_halfwidth: numerics::robust::median(&mut halves),
            }
        };
        Fig22 {
            location_in: self.location.1,
            normal: comp(0),
            tangential: comp(1),
        }
    }
}

/// The quoin point of location A: the first at or above a quarter of the quoin height (the
/// paper's Fig. 10 marks A low on the quoin, above the gap, where the bearing force is
/// largest).
pub fn location_a(gate: &mitergate::CondensedGate) -> usize {
    gate.nu_points
        .partition_point(|&z| z < 0.25 * gate.quoin_height)
}
