//! Scoring a calibration of the gate against a known truth: the corrected quoin force beside
//! every baseline and oracle a user should compare it with (only where the truth is known:
//! the reproduction, the coverage study and the validation panel; never inside a calibration).
//!
//! Per response component (normal, tangential), the RMSE over conditions and quoin points of:
//!
//! * **(a) prior mean**: the model averaged over the gap prior with `ρ = 1` and no
//!   discrepancy (Eq. 2): where a user starts, and the weakest baseline;
//! * **(b) no discrepancy**: the strongest calibration without a discrepancy, `ρ` and `θ`
//!   fitted ([`bamudi::posterior`],
//!   [`bamudi::Predictor::no_discrepancy_response`]): what the discrepancy must beat;
//! * **(c) calibrated**: the calibration's corrected force (Module 4's posterior mean);
//! * **(d) oracle split**: `ρ* g(θ*)`, the truth's own model part, whose error is the true
//!   discrepancy itself;
//! * **(e) seen-subspace oracle**: (d) plus the part of the true discrepancy the gauges can see
//!   at all: the correction of least force (root mean square over the points, on the
//!   discrepancy basis supported above `θ*`) whose strains equal the true discrepancy's
//!   ([`SeenSubspace`]). No method can recover from these gauges what this leaves out
//!   without knowing the discrepancy's shape in advance: the floor for a method that knew
//!   `θ*`;
//! * **(f) θ spread**: the truth with `θ*` replaced by the calibration's `θ` posterior: what
//!   `θ`'s posterior spread alone costs (near the gap's edge the force changes by thousands of
//!   lbf/in per inch of gap, so this dominates every force RMSE over the quoin);
//! * **(g) seen oracle at the posterior**: the model at the calibration's `θ` posterior
//!   (`ρ*` known) corrected by exactly what the gauges see of the remaining force error: what
//!   the posterior mean of a calibration with this `θ` posterior would be if its correction
//!   were perfect, the floor for such a method;
//!
//! and the reconstructed discrepancy `δ̂` against the true one in the truth's split
//! ([`DeltaScore`]).

use crate::error::{GateAppError, Result};
use mitergate::{ContactModel, GateMultiLevel};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Normal and tangential values. A ratio over a zero truth (no true discrepancy) is not a
/// number; JSON writes it as `null` and reads `null` back as NaN.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct NormalTangential {
    /// Normal force.
    #[serde(deserialize_with = "nan_if_null")]
    pub normal: f64,
    /// Tangential force.
    #[serde(deserialize_with = "nan_if_null")]
    pub tangential: f64,
}

/// `null` (how JSON writes a NaN or an infinity) as NaN.
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Force RMSE (lbf/in) of every baseline and oracle (see the module docs).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Baselines {
    /// (a) the prior-mean model with `ρ = 1`, no discrepancy.
    pub prior_mean: NormalTangential,
    /// (b) the best calibration without a discrepancy (`ρ`, `θ` fitted).
    pub no_discrepancy: NormalTangential,
    /// (c) the calibration's corrected force.
    pub calibrated: NormalTangential,
    /// (d) the truth's own split `ρ* g(θ*)` (its error is the true discrepancy's RMS).
    pub oracle_split: NormalTangential,
    /// (e) (d) plus the part of the true discrepancy the gauges see.
    pub oracle_seen: NormalTangential,
    /// (f) the truth with `θ*` replaced by the calibration's `θ` posterior,
    /// `ρ* E[g(θ) | y] + δ`: the error `θ`'s posterior spread alone leaves (the force near the
    /// gap's edge changes by thousands of lbf/in per inch of gap), which no discrepancy can
    /// remove (zero in reports saved before it was measured).
    #[serde(default)]
    pub theta_spread: NormalTangential,
    /// (g) the seen-subspace correction at the calibration's `θ` posterior:
    /// `m + seen(F* − m)` with `m = ρ* E[g(θ) | y]`, what a calibration that knew `ρ*` and
    /// corrected exactly what the gauges see would give with this `θ` posterior (the floor for
    /// a method with this `θ` posterior).
    #[serde(default)]
    pub oracle_seen_posterior: NormalTangential,
}

/// The reconstructed discrepancy against the true one (truth's split), lbf/in.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct DeltaScore {
    /// RMS of the true discrepancy.
    pub true_rms: NormalTangential,
    /// RMSE of `δ̂` against it.
    pub rmse: NormalTangential,
    /// RMSE against it of the discrepancy (g) reconstructs, `seen(F* − m)`: what `θ`'s
    /// posterior spread leaves of `δ̂`'s error for a method that corrects exactly what the
    /// gauges see (the part of `F* − m` that is not `δ` is the model's change across the
    /// posterior, which the correction absorbs).
    #[serde(default)]
    pub floor: NormalTangential,
}

/// The part of a discrepancy the gauges see, on the calibration's basis supported above a
/// gap `θ*`: `δ_seen = L G⁻¹ Bᵀ (B G⁻¹ Bᵀ)⁺ A δ` with `L` the supported basis, `G = Lᵀ L`,
/// `B = A L`: of all corrections on the basis whose strains match `A δ` as closely as any
/// can, the one of least force.
pub struct SeenSubspace {
    /// `L G⁻¹ Bᵀ (B G⁻¹ Bᵀ)⁺ A` (`C N_u x C N_u`), applied to a force vector.
    map: DMatrix<f64>,
}

/// Singular values of `B G⁻¹ Bᵀ` below this fraction of the largest count as unseen (a
/// pseudo-inverse without a floor would amplify rounding in directions no gauge resolves).
const SEEN_TOL: f64 = 1e-10;

impl SeenSubspace {
    /// The map for the gate's `model` (its basis and `A`) with the support of `contact` at
    /// `theta_star`.
    pub fn new(model: &GateMultiLevel, contact: &ContactModel, theta_star: f64) -> Result<Self> {
        let a = contact.gate().a_matrix.clone();
        let l0 = model.basis.block_matrix();
        let nu = contact.gate().n_points();
        let w = contact.coverage(theta_star);
        let l = DMatrix::from_fn(l0.nrows(), l0.ncols(), |r, k| l0[(r, k)] * w[r % nu]);
        let b = &a * &l;
        let g_inv = l.tr_mul(&l).pseudo_inverse(1e-12).map_err(oracle_error)?;
        let bgb = &b * &g_inv * b.transpose();
        let top = bgb.norm().max(1e-300);
        let pinv = bgb.pseudo_inverse(SEEN_TOL * top).map_err(oracle_error)?;
        Ok(Self {
            map: l * g_inv * b.transpose() * pinv * a,
        })
    }

    /// The seen part of `delta` (force, blocked like the model's response).
    pub fn seen(&self, delta: &[f64]) -> Vec<f64> {
        (&self.map * DVector::from_column_slice(delta))
            .iter()
            .copied()
            .collect()
    }
}

fn oracle_error(e: &str) -> GateAppError {
    GateAppError::Option(format!("seen-subspace oracle: {e}"))
}

/// Sums of squares per component for named series, turned into RMSEs.
#[derive(Debug, Clone, Default)]
pub struct ErrorTally {
    ss: [[f64; 2]; 9],
    n: [usize; 2],
}

/// The series an [`ErrorTally`] accumulates.
#[derive(Debug, Clone, Copy)]
pub enum Series {
    /// (a).
    PriorMean = 0,
    /// (b).
    NoDiscrepancy = 1,
    /// (c).
    Calibrated = 2,
    /// (d), the true discrepancy itself.
    OracleSplit = 3,
    /// (e).
    OracleSeen = 4,
    /// `δ̂ − δ`.
    DeltaError = 5,
    /// (f).
    ThetaSpread = 6,
    /// (g).
    OracleSeenPosterior = 7,
    /// (g)'s discrepancy against the true one.
    DeltaFloor = 8,
}

impl ErrorTally {
    /// Adds one point: `normal` component or not, and each series' error there.
    pub fn add(&mut self, normal: bool, errors: &[(Series, f64)]) {
        let c = usize::from(!normal);
        self.n[c] += 1;
        for (s, e) in errors {
            self.ss[*s as usize][c] += e * e;
        }
    }

    fn rmse(&self, s: Series) -> NormalTangential {
        let r = |c: usize| (self.ss[s as usize][c] / self.n[c].max(1) as f64).sqrt();
        NormalTangential {
            normal: r(0),
            tangential: r(1),
        }
    }

    /// The baselines' RMSEs.
    pub fn baselines(&self) -> Baselines {
        Baselines {
            prior_mean: self.rmse(Series::PriorMean),
            no_discrepancy: self.rmse(Series::NoDiscrepancy),
            calibrated: self.rmse(Series::Calibrated),
            oracle_split: self.rmse(Series::OracleSplit),
            oracle_seen: self.rmse(Series::OracleSeen),
            theta_spread: self.rmse(Series::ThetaSpread),
            oracle_seen_posterior: self.rmse(Series::OracleSeenPosterior),
        }
    }

    /// `δ̂` against the true discrepancy.
    pub fn delta(&self) -> DeltaScore {
        DeltaScore {
            true_rms: self.rmse(Series::OracleSplit),
            rmse: self.rmse(Series::DeltaError),
            floor: self.rmse(Series::DeltaFloor),
        }
    }
}

/// Everything one condition contributes: the truth, its model part, and the predictions.
pub struct ConditionForces<'a> {
    /// True forces `F* = ρ* g(θ*) + δ`.
    pub truth: &'a [f64],
    /// The truth's model part `ρ* g(θ*)`.
    pub model_part: &'a [f64],
    /// The truth's model part at the calibration's `θ` posterior, `ρ* E[g(θ) | y]`.
    pub model_part_posterior: &'a [f64],
    /// (a).
    pub prior_mean: &'a [f64],
    /// (b).
    pub no_discrepancy: &'a [f64],
    /// (c).
    pub calibrated: &'a [f64],
    /// `δ̂`.
    pub delta_hat: &'a [f64],
}

impl ErrorTally {
    /// Adds every point of one condition (`n_u` points per component, blocked), with the
    /// seen-subspace oracle `seen`.
    pub fn add_condition(&mut self, f: &ConditionForces<'_>, seen: &SeenSubspace, n_u: usize) {
        let minus = |m: &[f64]| -> Vec<f64> { f.truth.iter().zip(m).map(|(t, m)| t - m).collect() };
        let delta = minus(f.model_part);
        let delta_seen = seen.seen(&delta);
        let correction = seen.seen(&minus(f.model_part_posterior));
        for p in 0..f.truth.len() {
            let t = f.truth[p];
            self.add(
                p < n_u,
                &[
                    (Series::PriorMean, f.prior_mean[p] - t),
                    (Series::NoDiscrepancy, f.no_discrepancy[p] - t),
                    (Series::Calibrated, f.calibrated[p] - t),
                    (Series::OracleSplit, delta[p]),
                    (Series::OracleSeen, f.model_part[p] + delta_seen[p] - t),
                    (Series::DeltaError, f.delta_hat[p] - delta[p]),
                    (
                        Series::ThetaSpread,
                        f.model_part_posterior[p] + delta[p] - t,
                    ),
                    (
                        Series::OracleSeenPosterior,
                        f.model_part_posterior[p] + correction[p] - t,
                    ),
                    (Series::DeltaFloor, correction[p] - delta[p]),
                ],
            );
        }
    }
}
