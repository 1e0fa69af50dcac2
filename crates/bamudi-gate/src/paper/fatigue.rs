//! The reproduction's prediction level (paper Eq. 8, Fig. 2): quoin-block fatigue from the
//! quoin force, before calibration, after it (with the band of
//! [`bamudi::Predictor::predict_through`]) and from the truth, at one lockage condition per
//! scenario. The damage rate is the Miner damage of 1,000 lockages to that condition
//! ([`mitergate::QuoinBlockModel`], default blocks and S-N curve).

use super::score::prior_mean_response;
use crate::error::Result;
use bamudi::{Band, Calibration};
use mitergate::data::truth::{self, Scenario};
use mitergate::quoin_block::QUOIN_BLOCK_OUTPUTS;
use mitergate::{ContactModel, GateMultiLevel, QuoinBlockModel, QuoinBlockParams};
use mlmodel::{PredictionModel, UnobservableModel};
use serde::{Deserialize, Serialize};

/// Joint draws of the calibrated force behind each prediction band: the 2.5 % quantile of
/// 2,000 draws lies between the 1.8 % and 3.2 % points.
pub const FATIGUE_DRAWS: usize = 2_000;

/// The damage rate along the quoin at one condition: truth, before, after (with band).
#[derive(Debug, Clone)]
pub struct DamageAlongQuoin {
    /// Quoin points (in above the sill).
    pub z_in: Vec<f64>,
    /// From the true force.
    pub truth: Vec<f64>,
    /// From the nominal model (prior-mean force, ρ = 1, no discrepancy).
    pub before: Vec<f64>,
    /// From the calibrated force, with its 95 % band.
    pub after: Band,
}

/// The damage rate (per 1,000 lockages) of `x` along the quoin.
pub fn damage_along_quoin(
    model: &GateMultiLevel,
    cal: &Calibration,
    scenario: &Scenario,
    contact: &ContactModel,
    x: [f64; 2],
    seed: u64,
) -> Result<DamageAlongQuoin> {
    let z = model.unobservable.coordinates().to_vec();
    let block = QuoinBlockModel::new(QuoinBlockParams::default(), z.clone())?;
    let n = z.len();
    let damage_block = |forces: &[f64]| -> Result<Vec<f64>> {
        let mut out = vec![0.0; QUOIN_BLOCK_OUTPUTS.len() * n];
        block.evaluate(&x, &[scenario.theta_true], forces, &mut out)?;
        Ok(out[3 * n..].to_vec())
    };
    let truth = damage_block(&truth::true_forces(scenario, contact, x)?)?;
    let before = damage_block(&prior_mean_response(model, &x)?)?;
    let all = cal
        .predictor(model)?
        .predict_through(&block, &x, FATIGUE_DRAWS, seed)?;
    let pick = |v: &[f64]| v[3 * n..].to_vec();
    let after = Band {
        mean: pick(&all.mean),
        sd: pick(&all.sd),
        lower: pick(&all.lower),
        upper: pick(&all.upper),
    };
    Ok(DamageAlongQuoin {
        z_in: z,
        truth,
        before,
        after,
    })
}

/// The prediction section of one scenario (`--json` key `fatigue`).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct FatigueSummary {
    /// The lockage condition (in).
    pub h_up_in: f64,
    /// The lockage condition (in).
    pub h_down_in: f64,
    /// The truth's hot spot: the quoin point of the largest damage rate (in).
    pub hot_spot_z_in: f64,
    /// The truth's damage per 1,000 lockages there.
    pub truth: f64,
    /// The nominal model's (before calibration) at the same point.
    pub before: f64,
    /// The calibrated prediction there: mean and 95 % band.
    pub after_mean: f64,
    /// Lower end of the band.
    pub after_lower: f64,
    /// Upper end of the band.
    pub after_upper: f64,
    /// The calibrated prediction's own hot spot (largest mean damage rate, in).
    pub after_hot_spot_z_in: f64,
    /// Fraction of the quoin points with a non-zero true or predicted damage rate whose true
    /// rate lies in the band.
    pub band_coverage: f64,
}

impl FatigueSummary {
    /// The summary of a damage profile at the condition `x`.
    pub fn of(d: &DamageAlongQuoin, x: [f64; 2]) -> Self {
        let argmax = |v: &[f64]| {
            (0..v.len())
                .max_by(|a, b| v[*a].total_cmp(&v[*b]))
                .unwrap_or(0)
        };
        let hot = argmax(&d.truth);
        let live: Vec<usize> = (0..d.z_in.len())
            .filter(|&b| d.truth[b] > 0.0 || d.after.upper[b] > 0.0)
            .collect();
        let covered = live
            .iter()
            .filter(|&&b| d.after.lower[b] <= d.truth[b] && d.truth[b] <= d.after.upper[b])
            .count();
        Self {
            h_up_in: x[0],
            h_down_in: x[1],
            hot_spot_z_in: d.z_in[hot],
            truth: d.truth[hot],
            before: d.before[hot],
            after_mean: d.after.mean[hot],
            after_lower: d.after.lower[hot],
            after_upper: d.after.upper[hot],
            after_hot_spot_z_in: d.z_in[argmax(&d.after.mean)],
            band_coverage: covered as f64 / live.len().max(1) as f64,
        }
    }
}

/// The scenario's lockage condition for the prediction section: the paper's plotting
/// condition of Fig. 15 and 17 (full upper pool for scenario 1, a low one for scenario 2).
pub fn condition(scenario_number: u8) -> [f64; 2] {
    if scenario_number == 1 {
        [738.0, 360.0]
    } else {
        [426.0, 120.0]
    }
}
