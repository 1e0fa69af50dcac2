//! The coverage study behind `cargo xtask coverage`: do the calibration's intervals hold the
//! truth as often as they claim?
//!
//! For each scenario of the paper's Table 1 and each replicate `r`:
//!
//! 1. `θ*` is drawn from the scenario's prior (simulation-based calibration), and a fresh data
//!    set is generated from the synthetic truth ([`mitergate::data::truth`]): the scenario's
//!    `ρ` and discrepancy (Eq. 53-54, a shape the calibration's basis does not contain),
//!    fresh water levels and fresh gauge noise, all from seeds derived from `(seed, scenario,
//!    r)`.
//! 2. Each requested coefficient mode calibrates it (Modules 2b-3). The coefficient estimator
//!    of Module 2 depends on the model and the sampling rule, not on the measured strains, so it
//!    is fitted once per scenario (on the first replicate's input range) and reused: the study
//!    conditions on one fitted estimator, as a user does.
//! 3. Scores against the truth: the transform `u = P(θ ≤ θ* | data)`, from which the central
//!    50/80/90/95 % intervals' hits and the SBC rank follow ([`bamudi::validation`]); the
//!    Module-4 95 % force bands at new water levels (fraction of condition × quoin-point pairs
//!    inside, normal and tangential); the force RMSE after calibration over before.
//!
//! The summaries carry exact (Clopper-Pearson) 95 % intervals of each coverage, and the 1 %
//! binomial acceptance region of its nominal level.

mod delta_file;
mod drawn;
mod markdown;
mod merge;
mod truth;

pub use drawn::{DrawnDelta, GeneratingHyper};
pub use truth::{DeltaFile, TrueDelta};

pub use markdown::mode_label;
pub use merge::{LogHeader, LoggedReplicate, ReplicateLog};
pub use truth::{DiscrepancyShape, Truth};

pub use crate::baselines::NormalTangential;
use crate::baselines::{Baselines, ConditionForces, DeltaScore, ErrorTally, SeenSubspace};
use crate::error::{GateAppError, Result};
use crate::paper::figures::location_a;
use crate::paper::{ForceRmse, build_gate, gate_model, prior_mean_response};
use bamudi::surrogate::FittedEstimator;
use bamudi::validation::{Coverage, RankHistogram, binomial_acceptance};
use bamudi::{
    Calibrate, Calibration, CalibrationParams, EstimatorParams, MarginalPrior, ModeKind,
    SamplingRule, SupportPolicy,
};
use mitergate::data::truth::{Scenario, sample_levels};
use mitergate::{ContactModel, GateMultiLevel, QuoinBlockModel, QuoinBlockParams};
use mlmodel::{LinearObservableModel, PredictionModel, UnobservableModel};
use numerics::random::derive_seed;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::time::Instant;

/// The nominal levels of the central `θ` intervals checked.
pub const LEVELS: [f64; 4] = [0.5, 0.8, 0.9, 0.95];

/// Significance of the binomial acceptance regions reported.
pub const ACCEPTANCE_ALPHA: f64 = 0.01;

/// Bins of the SBC rank histogram.
pub const RANK_BINS: usize = 10;

/// Support points standing for the `θ` posterior in the Module-4 bands (see
/// [`SupportPolicy`]: 32 merged groups keep all but about 1 % of a Gaussian posterior's
/// variance, and bound the contact solves per condition).
const BAND_SUPPORT: usize = 32;

/// Options of a coverage study.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CoverageOptions {
    /// Scenarios of Table 1 (1, 2).
    pub scenarios: Vec<u8>,
    /// Coefficient modes compared, each on every replicate.
    pub modes: Vec<ModeKind>,
    /// Replicate data sets per scenario.
    pub n_replicates: usize,
    /// Index of the first replicate: the study runs replicates `first_replicate ..
    /// first_replicate + n_replicates`, each with the data its index draws, so a long study can
    /// be split over machines or resumed and its parts merged (`0` for a whole study). With a
    /// learnt estimator it must be `0`: replicate 0 trains the estimator the others reuse.
    #[serde(default)]
    pub first_replicate: usize,
    /// Experiments per data set (paper: 500).
    pub n_experiments: usize,
    /// Module-2 training-set size (learnt estimators only).
    pub training_size: usize,
    /// The coefficient estimator of Eq. 29.
    pub estimator: EstimatorParams,
    /// `θ` grid points of Module 3.
    pub theta_grid_points: usize,
    /// New water-level pairs per replicate for the force bands.
    pub new_conditions: usize,
    /// What each replicate is scored on at the new conditions ([`Scoring`]).
    #[serde(default)]
    pub scoring: Scoring,
    /// Target element size of the gate mesh (in); `None` keeps the default gate's 12 in.
    pub mesh_element_size: Option<f64>,
    /// Gauge noise sd (microstrain) of the truth and of the Module-2 training outputs.
    pub gauge_noise_sd: f64,
    /// The shape of the true discrepancy (the paper's Eq. 53-54 by default).
    pub discrepancy: DiscrepancyShape,
    /// The factor on the shape (1: its stated magnitude).
    #[serde(default = "one")]
    pub discrepancy_scale: f64,
    /// A user's true discrepancy ([`DeltaFile`]) in place of the shape.
    #[serde(default)]
    pub discrepancy_file: Option<std::path::PathBuf>,
    /// Simulation-based calibration: `θ`, `ρ` and the discrepancy all drawn per replicate
    /// from the calibration's stated prior (`None`: `ρ` is the scenario's and the discrepancy
    /// the shape or file above).
    #[serde(default)]
    pub sbc: Option<SbcOptions>,
    /// The coefficients' prior of the marginal mode.
    pub marginal: MarginalPrior,
    /// The prior range of `ρ` (the sampling rule's `rho_range`); `None` keeps the default.
    #[serde(default)]
    pub rho_range: Option<(f64, f64)>,
    /// Worker threads for the replicates (0: all cores).
    pub threads: usize,
    /// Master seed.
    pub seed: u64,
}

impl CoverageOptions {
    /// The paper's size with the exact linear estimator: 500 experiments, the default
    /// 12-in mesh, 100 replicates per scenario, the marginal and the conditional modes and the
    /// paper's Module 3.
    pub fn paper_exact() -> Self {
        Self {
            scenarios: vec![1, 2],
            modes: vec![
                ModeKind::Marginal,
                ModeKind::ConditionalOnTheta,
                ModeKind::PriorMarginal,
            ],
            n_replicates: 100,
            first_replicate: 0,
            n_experiments: 500,
            training_size: 4_000,
            estimator: EstimatorParams::ExactLinear,
            theta_grid_points: 121,
            new_conditions: 10,
            scoring: Scoring::Full,
            mesh_element_size: None,
            gauge_noise_sd: 1.0,
            discrepancy: DiscrepancyShape::Paper,
            discrepancy_scale: 1.0,
            discrepancy_file: None,
            sbc: None,
            marginal: MarginalPrior::default(),
            rho_range: None,
            threads: 0,
            seed: 2021,
        }
    }

    /// The suite's size: 40 replicates of 120 experiments on the 24-in mesh, exact
    /// estimator, marginal mode only.
    pub fn quick() -> Self {
        Self {
            modes: vec![ModeKind::Marginal],
            n_replicates: 40,
            n_experiments: 120,
            theta_grid_points: 49,
            new_conditions: 4,
            mesh_element_size: Some(24.0),
            ..Self::paper_exact()
        }
    }

    fn check(&self) -> Result<()> {
        let bad =
            |key: &str, why: &str| Err(GateAppError::Option(format!("coverage {key}: {why}")));
        if self.n_replicates < 2 {
            return bad("replicates", "at least 2");
        }
        if self.first_replicate > 0 && self.estimator != EstimatorParams::ExactLinear {
            return bad(
                "first replicate",
                "must be 0 with a learnt estimator (replicate 0 trains the one the others reuse)",
            );
        }
        if self.modes.is_empty() || self.scenarios.is_empty() {
            return bad("modes/scenarios", "at least one of each");
        }
        if let Some(s) = self.scenarios.iter().find(|s| !matches!(s, 1 | 2)) {
            return bad("scenarios", &format!("unknown scenario {s} (1 or 2)"));
        }
        if self.sbc.is_some()
            && (self.modes != [ModeKind::Marginal]
                || self.marginal.scales != bamudi::CoefficientScales::Isotropic)
        {
            return bad(
                "sbc",
                "draws from the marginal mode's isotropic prior: modes must be `marginal` and \
                 scales `isotropic`",
            );
        }
        if !(self.discrepancy_scale.is_finite()) {
            return bad("discrepancy scale", "must be finite");
        }
        Ok(())
    }
}

fn one() -> f64 {
    1.0
}

/// What a replicate is scored on besides `θ` ([`CoverageOptions::scoring`]). `θ`'s posterior,
/// the data and the new conditions are the same either way, so a lighter study's `θ` and force
/// bands are the full one's, bit for bit.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scoring {
    /// Everything: the force bands and RMSE, the baselines, oracles and discrepancy error
    /// ([`Replicate::baselines`], [`Replicate::delta`]), the fatigue bands
    /// ([`Replicate::band_fatigue`]) and the ranks of the force and damage ([`Replicate::ranks`]).
    #[default]
    Full,
    /// The force bands and RMSE only (the rest `None`): about three quarters of a replicate's
    /// cost on the quick size, for studies that judge `θ` and the bands alone (the test suite).
    ForceBands,
}

/// Simulation-based calibration's settings ([`CoverageOptions::sbc`]).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct SbcOptions {
    /// The hyper-parameters the discrepancy and the noise are drawn with.
    pub hyper: GeneratingHyper,
    /// Hold them in the calibration (`true`: the exact-inference check) or let the calibration
    /// estimate them as the product does (`false`).
    pub hold: bool,
}

/// One replicate under one coefficient mode.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Replicate {
    /// Replicate index.
    pub index: usize,
    /// `θ*` drawn from the prior (in).
    pub theta_true: f64,
    /// `P(θ ≤ θ* | data)`.
    pub pit: f64,
    /// Posterior mean and sd of `θ` (in).
    pub theta_mean: f64,
    /// Posterior sd of `θ` (in).
    pub theta_sd: f64,
    /// `ρ*` (modular modes) or `ρ`'s posterior mean (marginal mode).
    pub rho: f64,
    /// `ρ`'s posterior sd (marginal mode; `None` in the modular modes, which plug `ρ*` in,
    /// and in reports saved before it was recorded).
    #[serde(default)]
    pub rho_sd: Option<f64>,
    /// The true `ρ` of the replicate's data (the scenario's; `None` in reports saved before
    /// it was recorded).
    #[serde(default)]
    pub rho_true: Option<f64>,
    /// Fraction of condition × point pairs inside the 95 % normal-force band.
    pub band_normal: f64,
    /// The same for the tangential force.
    pub band_tangential: f64,
    /// Fraction of condition × point pairs with fatigue damage (true or predicted) whose true
    /// quoin-block damage rate lies in the 95 % band of the prediction level
    /// ([`mitergate::QuoinBlockModel`] through `Predictor::predict_through`); `None` in
    /// reports saved before the prediction level existed.
    #[serde(default)]
    pub band_fatigue: Option<f64>,
    /// Force RMSE before/after (lbf/in).
    pub force_rmse: ForceRmse,
    /// Mean half-width of the 95 % force bands over the condition × point pairs (lbf/in);
    /// `None` in reports saved before it was measured.
    #[serde(default)]
    pub band_halfwidth: Option<NormalTangential>,
    /// Median half-width of the 95 % force bands over the condition × point pairs (lbf/in;
    /// `None` in reports saved before it was measured).
    #[serde(default)]
    pub band_halfwidth_median: Option<NormalTangential>,
    /// The force RMSE of every baseline and oracle ([`crate::baselines`]; `None` in reports
    /// saved before they were measured).
    #[serde(default)]
    pub baselines: Option<Baselines>,
    /// The reconstructed discrepancy against the true one in the truth's split.
    #[serde(default)]
    pub delta: Option<DeltaScore>,
    /// The calibration's identified `ρ⊥` (mean, sd; marginal mode).
    #[serde(default)]
    pub rho_projection: Option<[f64; 2]>,
    /// The truth's `ρ⊥` at the replicate's experiments.
    #[serde(default)]
    pub rho_projection_true: Option<f64>,
    /// The marginal mode's fitted hyper-parameters: amplitude `s`, length-scale factor and
    /// `σ_ε` (µε).
    #[serde(default)]
    pub hyper: Option<[f64; 3]>,
    /// `P(M_0 | y)`: the posterior probability of no discrepancy, when the models with and
    /// without one were weighed ([`bamudi::posterior`]).
    #[serde(default)]
    pub probability_without: Option<f64>,
    /// The truth's place in more posteriors than `θ`'s ([`Ranks`]; `None` in reports saved
    /// before they were measured).
    #[serde(default)]
    pub ranks: Option<Ranks>,
    /// Seconds for the calibration and its scores.
    pub seconds: f64,
}

/// The posterior CDF at the truth (a PIT, uniform when the calibration is exact) of the
/// quantities simulation-based calibration ranks besides `θ`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Ranks {
    /// `P(ρ ≤ ρ* | y)` (marginal mode: the mixture over the `θ` nodes of Gaussians with `ρ`'s
    /// conditional moments; `None` in the modular modes).
    pub rho: Option<f64>,
    /// The normal force at location A (a quarter of the quoin height) at the first new
    /// condition: the fraction of joint posterior draws below the truth.
    pub force: f64,
    /// The largest quoin-block damage rate along the quoin (the hot spot's, wherever each
    /// draw puts it) at the first new condition: the fraction of draws below the truth's
    /// (`None` when the truth has no damage there). A fixed function of the parameters, as
    /// SBC needs: the damage at the *truth's* hot spot would pick its point from the truth and
    /// rank the truth high by construction.
    pub damage: Option<f64>,
    /// `(mean − truth)/sd` of the force at location A over the draws.
    pub force_z: f64,
}

/// A coverage with its exact interval and the acceptance region of its nominal level.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LevelCoverage {
    /// Nominal level.
    pub level: f64,
    /// Hits.
    pub hits: usize,
    /// Empirical coverage.
    pub rate: f64,
    /// Clopper-Pearson 95 % interval of the coverage.
    pub interval: (f64, f64),
    /// Hit counts consistent with the nominal level ([`ACCEPTANCE_ALPHA`]).
    pub acceptance: (usize, usize),
}

impl LevelCoverage {
    /// A coverage count with its Clopper-Pearson 95 % interval and the acceptance region of
    /// its nominal level ([`ACCEPTANCE_ALPHA`]).
    fn of(c: &Coverage) -> Result<Self> {
        Ok(Self {
            level: c.level,
            hits: c.hits,
            rate: c.rate(),
            interval: c.clopper_pearson(0.95)?,
            acceptance: binomial_acceptance(c.n, c.level, ACCEPTANCE_ALPHA)?,
        })
    }
}

/// Summary of one scenario under one coefficient mode (the `--json` schema's entries).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ScenarioCoverage {
    /// "scenario 1" / "scenario 2".
    pub name: String,
    /// The estimator's kind (`exact_linear`, `lstm`, `ridge`).
    pub estimator: String,
    /// The coefficient mode.
    pub mode: ModeKind,
    /// Replicates.
    pub n_replicates: usize,
    /// Empirical coverage of the central intervals, keyed by level ("0.5", "0.8", ...).
    pub theta_coverage: BTreeMap<String, f64>,
    /// The same with intervals and acceptance regions.
    pub theta_levels: Vec<LevelCoverage>,
    /// The SBC rank histogram ([`RANK_BINS`] bins).
    pub sbc_histogram: Vec<usize>,
    /// p-value of its χ² uniformity test.
    pub sbc_uniformity_p: f64,
    /// Mean over replicates of the fraction of points inside the 95 % force bands.
    pub force_band_coverage_95: NormalTangential,
    /// Mean over replicates of the fraction of live points inside the 95 % band of the
    /// quoin-block damage rate (the prediction level); `None` when a replicate did not
    /// measure it (a report saved before the prediction level existed).
    #[serde(default)]
    pub fatigue_band_coverage_95: Option<f64>,
    /// `ρ` over replicates: mean, sd, min, max.
    pub rho: [f64; 4],
    /// The check of `ρ`'s reported posterior against the true `ρ` (marginal mode; `None`
    /// where no replicate reported a `ρ` sd).
    #[serde(default)]
    pub rho_check: Option<RhoCheck>,
    /// Median over replicates of force RMSE after / before.
    pub force_rmse_ratio_median: NormalTangential,
    /// Median over replicates of the mean 95 % band half-width / force RMSE before: how wide
    /// the bands are against the error they correct (`None` when a replicate did not measure
    /// it).
    #[serde(default)]
    pub force_band_halfwidth_ratio_median: Option<NormalTangential>,
    /// Root mean square of `(mean − θ*)/sd` (1 for a calibrated Gaussian posterior).
    pub z_rms: f64,
    /// Mean and standard deviation of `(mean − θ*)/sd` (0 and 1 when calibrated; `[0, 0]` in
    /// reports saved before they were kept).
    #[serde(default)]
    pub z_mean_sd: [f64; 2],
    /// The corrected force against the baselines and oracles, and the identified `ρ⊥`
    /// against the truth's (`None` when a replicate did not measure them).
    #[serde(default)]
    pub correction: Option<CorrectionSummary>,
    /// Rank uniformity and z of every ranked quantity (`θ`, `ρ`, the force at location A, the
    /// hot spot's damage; `None` when a replicate did not rank them).
    #[serde(default)]
    pub ranked: Option<Vec<RankSummary>>,
    /// Median posterior sd of `θ` (in).
    pub theta_sd_median: f64,
    /// Wall time of this scenario and mode (s, summed over replicates).
    pub seconds: f64,
    /// Every replicate.
    pub replicates: Vec<Replicate>,
}

/// The corrected force against the baselines and oracles over the replicates (medians over
/// replicates of each replicate's RMSE over conditions and points; [`crate::baselines`]).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CorrectionSummary {
    /// Median RMSE of each baseline (lbf/in).
    pub baselines: Baselines,
    /// Median of (c) / (b): the correction against the best fit without a discrepancy.
    pub vs_no_discrepancy: NormalTangential,
    /// Median of (c) / (e): the correction against the seen-subspace oracle.
    pub vs_oracle_seen: NormalTangential,
    /// Median of `δ̂` RMSE / true `δ` RMS (truth's split; `NaN` where the truth has no `δ`).
    pub delta_ratio: NormalTangential,
    /// Median RMSE of `δ̂` against the true `δ` (lbf/in).
    pub delta_rmse: NormalTangential,
    /// Median of (g)'s discrepancy error / true `δ` RMS: the floor `θ`'s spread sets for
    /// `δ̂ / δ`.
    #[serde(default)]
    pub delta_floor_ratio: NormalTangential,
    /// Median over replicates of the median (over conditions and points) 95 % band
    /// half-width / true `δ` RMS: how wide the band is against what it is meant to resolve
    /// (`NaN` without a true `δ`).
    pub halfwidth_over_delta: NormalTangential,
    /// `ρ⊥` against the truth's `ρ⊥` (modes that report it).
    pub rho_projection: Option<RhoCheck>,
}

/// The ranks of one quantity over the replicates.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RankSummary {
    /// `theta`, `rho`, `force at A`, `hot-spot damage`.
    pub quantity: String,
    /// Replicates ranked.
    pub n: usize,
    /// The rank histogram ([`RANK_BINS`] bins).
    pub histogram: Vec<usize>,
    /// p-value of its χ² uniformity test.
    pub uniformity_p: f64,
    /// Mean and sd of `(posterior mean − truth)/posterior sd` (`None` where no sd is kept).
    pub z_mean_sd: Option<[f64; 2]>,
}

/// A ranked quantity's name, its PITs and its z's mean and sd.
type RankColumn = (&'static str, Vec<f64>, Option<[f64; 2]>);

/// [`RankSummary`] of each ranked quantity, if every replicate ranked them.
fn rank_summaries(reps: &[Replicate]) -> Result<Option<Vec<RankSummary>>> {
    let ranks: Option<Vec<Ranks>> = reps.iter().map(|r| r.ranks).collect();
    let Some(ranks) = ranks.filter(|v| !v.is_empty()) else {
        return Ok(None);
    };
    let mean_sd = |z: &[f64]| -> Option<[f64; 2]> {
        if z.is_empty() {
            return None;
        }
        let n = z.len() as f64;
        let m = z.iter().sum::<f64>() / n;
        Some([
            m,
            (z.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n).sqrt(),
        ])
    };
    let theta_z: Vec<f64> = reps
        .iter()
        .map(|r| (r.theta_mean - r.theta_true) / r.theta_sd)
        .collect();
    let rho_z: Vec<f64> = reps
        .iter()
        .filter_map(|r| Some((r.rho - r.rho_true?) / r.rho_sd?))
        .collect();
    let force_z: Vec<f64> = ranks.iter().map(|r| r.force_z).collect();
    let columns: [RankColumn; 4] = [
        (
            "theta",
            reps.iter().map(|r| r.pit).collect(),
            mean_sd(&theta_z),
        ),
        (
            "rho",
            ranks.iter().filter_map(|r| r.rho).collect(),
            mean_sd(&rho_z),
        ),
        (
            "force at A",
            ranks.iter().map(|r| r.force).collect(),
            mean_sd(&force_z),
        ),
        (
            "hot-spot damage",
            ranks.iter().filter_map(|r| r.damage).collect(),
            None,
        ),
    ];
    let mut out = Vec::new();
    for (quantity, pits, z) in columns {
        if pits.len() < 2 {
            continue;
        }
        let hist = RankHistogram::new(&pits, RANK_BINS)?;
        out.push(RankSummary {
            quantity: quantity.into(),
            n: pits.len(),
            histogram: hist.counts,
            uniformity_p: hist.p_value,
            z_mean_sd: z,
        });
    }
    Ok(Some(out))
}

/// [`CorrectionSummary`] if every replicate measured the baselines.
fn correction_summary(reps: &[Replicate]) -> Result<Option<CorrectionSummary>> {
    let all: Option<Vec<(Baselines, DeltaScore, NormalTangential)>> = reps
        .iter()
        .map(|r| Some((r.baselines?, r.delta?, r.band_halfwidth_median?)))
        .collect();
    let Some(all) = all.filter(|v| !v.is_empty()) else {
        return Ok(None);
    };
    let med = |f: &dyn Fn(&(Baselines, DeltaScore, NormalTangential)) -> NormalTangential| {
        NormalTangential {
            normal: median(all.iter().map(|v| f(v).normal)),
            tangential: median(all.iter().map(|v| f(v).tangential)),
        }
    };
    let ratio = |a: NormalTangential, b: NormalTangential| NormalTangential {
        normal: a.normal / b.normal,
        tangential: a.tangential / b.tangential,
    };
    let rho: Vec<(f64, f64, f64)> = reps
        .iter()
        .filter_map(|r| match (r.rho_projection, r.rho_projection_true) {
            (Some([m, sd]), Some(t)) if sd > 0.0 => Some((m, sd, t)),
            _ => None,
        })
        .collect();
    Ok(Some(CorrectionSummary {
        baselines: Baselines {
            prior_mean: med(&|v| v.0.prior_mean),
            no_discrepancy: med(&|v| v.0.no_discrepancy),
            calibrated: med(&|v| v.0.calibrated),
            oracle_split: med(&|v| v.0.oracle_split),
            oracle_seen: med(&|v| v.0.oracle_seen),
            theta_spread: med(&|v| v.0.theta_spread),
            oracle_seen_posterior: med(&|v| v.0.oracle_seen_posterior),
        },
        vs_no_discrepancy: med(&|v| ratio(v.0.calibrated, v.0.no_discrepancy)),
        vs_oracle_seen: med(&|v| ratio(v.0.calibrated, v.0.oracle_seen)),
        delta_ratio: med(&|v| ratio(v.1.rmse, v.1.true_rms)),
        delta_rmse: med(&|v| v.1.rmse),
        delta_floor_ratio: med(&|v| ratio(v.1.floor, v.1.true_rms)),
        halfwidth_over_delta: med(&|v| ratio(v.2, v.1.true_rms)),
        rho_projection: z_check(
            rho.iter().map(|(m, sd, t)| (m - t) / sd).collect(),
            rho.iter().map(|r| r.1),
        )?,
    }))
}

/// `ρ`'s posterior against the true `ρ` over the replicates, with the Gaussian approximation
/// (posterior mean ± 1.96 sd): the posterior is a mixture over the `θ` nodes of normals
/// truncated to the prior range, nearly Gaussian when its sd is far below the range.
///
/// What it measures: the truth's `ρ` is the scale of `g` in the simulator's decomposition
/// `ρ g + δ`; with a `δ` partly along `g` (Kennedy-O'Hagan's confounding) another split of the
/// same data is equally true, so a miss here says the reported `ρ` interval is not an interval
/// for that `ρ`, not that the gap or the force is wrong.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RhoCheck {
    /// The central 95 % interval's hits, with its Clopper-Pearson interval and the binomial
    /// acceptance region.
    pub coverage_95: LevelCoverage,
    /// Mean of `(posterior mean − ρ_true)/sd`.
    pub z_mean: f64,
    /// Root mean square of the same.
    pub z_rms: f64,
    /// Median posterior sd.
    pub sd_median: f64,
}

/// [`RhoCheck`] over the replicates that report a `ρ` sd and truth (`None` if none does).
fn rho_check(reps: &[Replicate]) -> Result<Option<RhoCheck>> {
    let z: Vec<f64> = reps
        .iter()
        .filter_map(|r| match (r.rho_sd, r.rho_true) {
            (Some(sd), Some(t)) if sd > 0.0 => Some((r.rho - t) / sd),
            _ => None,
        })
        .collect();
    z_check(z, reps.iter().filter_map(|r| r.rho_sd))
}

/// [`RhoCheck`] from the z values `(mean − truth)/sd` and the posterior sds (`None` if no z).
fn z_check(z: Vec<f64>, sds: impl Iterator<Item = f64>) -> Result<Option<RhoCheck>> {
    if z.is_empty() {
        return Ok(None);
    }
    let n = z.len();
    let hits = z.iter().filter(|v| v.abs() <= RHO_Z95).count();
    let mean = |f: &dyn Fn(f64) -> f64| z.iter().map(|&v| f(v)).sum::<f64>() / n as f64;
    Ok(Some(RhoCheck {
        coverage_95: LevelCoverage::of(&Coverage {
            level: 0.95,
            hits,
            n,
        })?,
        z_mean: mean(&|v| v),
        z_rms: mean(&|v| v * v).sqrt(),
        sd_median: median(sds),
    }))
}

/// The standard normal's 97.5 % quantile: the half-width of a Gaussian central 95 % interval
/// in sd.
const RHO_Z95: f64 = 1.959_963_984_540_054;

/// The whole study.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CoverageReport {
    /// Options used.
    pub options: CoverageOptions,
    /// Degrees of freedom of the gate model.
    pub n_dofs: usize,
    /// Target element size (in).
    pub element_size: f64,
    /// Per scenario and mode.
    pub scenarios: Vec<ScenarioCoverage>,
    /// Wall time (s); for a merged report, the sum of the merged reports' (a replicate log
    /// records each replicate's seconds, not the study's wall time).
    pub total_s: f64,
    /// Parts (reports and replicate logs) this report was merged from; `0` for a study run
    /// in one go.
    #[serde(default)]
    pub merged_from: usize,
}

/// Called after each replicate, from worker threads, with the scenario number and the
/// replicate's result per mode (in `opts.modes` order): a progress bar, or a log of finished
/// replicates that a long study can be read from while it runs.
pub type OnReplicate<'a> = &'a (dyn Fn(u8, &[Replicate]) + Sync);

/// Runs the study; `on_replicate` sees every finished replicate.
pub fn run(opts: &CoverageOptions, on_replicate: OnReplicate) -> Result<CoverageReport> {
    opts.check()?;
    let t = Instant::now();
    let (contact, gate) = build_gate(opts.mesh_element_size)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads)
        .build()
        .map_err(|e| GateAppError::Option(format!("coverage threads: {e}")))?;
    let mut scenarios = Vec::new();
    for &number in &opts.scenarios {
        let runs = pool.install(|| scenario_replicates(&contact, number, opts, on_replicate))?;
        for (m, mode) in opts.modes.iter().enumerate() {
            let reps: Vec<Replicate> = runs.iter().map(|r| r[m].clone()).collect();
            scenarios.push(summarise(number, *mode, opts, reps)?);
        }
    }
    Ok(CoverageReport {
        options: opts.clone(),
        n_dofs: gate.n_dofs,
        element_size: gate.element_size,
        scenarios,
        total_s: t.elapsed().as_secs_f64(),
        merged_from: 0,
    })
}

/// One scenario's fixed parts.
struct Setup<'a> {
    contact: &'a ContactModel,
    number: u8,
    model: GateMultiLevel,
    opts: &'a CoverageOptions,
    file: Option<std::sync::Arc<DeltaFile>>,
}

/// Every replicate of one scenario (per replicate, one result per mode).
fn scenario_replicates(
    contact: &ContactModel,
    number: u8,
    opts: &CoverageOptions,
    on_replicate: OnReplicate,
) -> Result<Vec<Vec<Replicate>>> {
    let prior = Scenario::paper(number)?.prior;
    let file = match &opts.discrepancy_file {
        None => None,
        Some(path) => Some(std::sync::Arc::new(DeltaFile::read(
            path,
            contact.gate().quoin_height,
        )?)),
    };
    let setup = Setup {
        contact,
        number,
        model: gate_model(contact, prior)?,
        opts,
        file,
    };
    // the first replicate fits the estimator the others reuse
    let start = opts.first_replicate;
    let (first, estimator) = setup.replicate(start, None)?;
    on_replicate(number, &first);
    let mut all = vec![first];
    let rest = (start + 1..start + opts.n_replicates)
        .into_par_iter()
        .map(|r| {
            let reps = setup.replicate(r, Some(&estimator))?.0;
            on_replicate(number, &reps);
            Ok(reps)
        })
        .collect::<Result<Vec<_>>>()?;
    all.extend(rest);
    Ok(all)
}

impl Setup<'_> {
    /// The replicate's truth (`θ*` from the prior; with SBC `ρ` and `δ` too), its data, new
    /// conditions and the truth's `ρ⊥` at the experiments.
    fn truth(&self, r: usize) -> Result<(Truth, bamudi::Experiments, Vec<[f64; 2]>, f64)> {
        let base = derive_seed(self.opts.seed, 1000 * self.number as u64 + r as u64);
        let scenario = Scenario::paper(self.number)?;
        let (lo, hi) = scenario.prior;
        let theta = lo + (hi - lo) * unit_uniform(derive_seed(base, 1));
        let levels = sample_levels(self.opts.n_experiments, derive_seed(base, 2));
        let new_x = sample_levels(self.opts.new_conditions, derive_seed(base, 3));
        let (rho, delta, noise_sd) = match &self.opts.sbc {
            Some(sbc) => {
                let (r_lo, r_hi) = self.rho_range();
                let rho = r_lo + (r_hi - r_lo) * unit_uniform(derive_seed(base, 5));
                let inputs: Vec<[f64; 2]> = levels.iter().chain(&new_x).copied().collect();
                let drawn = DrawnDelta::draw(
                    &self.model,
                    self.contact,
                    (theta, 0.5 * (lo + hi)),
                    &levels,
                    &inputs,
                    &sbc.hyper,
                    derive_seed(base, 6),
                )?;
                let delta = TrueDelta::Drawn(std::sync::Arc::new(drawn));
                (rho, delta, sbc.hyper.noise_sd)
            }
            None => {
                let delta = match &self.file {
                    Some(f) => TrueDelta::File(f.clone()),
                    None => TrueDelta::Shape {
                        shape: self.opts.discrepancy,
                        scale: self.opts.discrepancy_scale,
                    },
                };
                (scenario.rho, delta, self.opts.gauge_noise_sd)
            }
        };
        let truth = Truth { theta, rho, delta };
        let y = truth.strains(self.contact, &levels, noise_sd, derive_seed(base, 4))?;
        let x = nalgebra::DMatrix::from_fn(levels.len(), 2, |i, j| levels[i][j]);
        let gauges = (1..=y.ncols()).map(|g| format!("g{g}")).collect();
        let exps = bamudi::Experiments::new(vec!["h_up".into(), "h_down".into()], gauges, x, y)?;
        let rho_perp = truth.projection_rho(self.contact, &levels)?;
        Ok((truth, exps, new_x, rho_perp))
    }

    /// `ρ`'s prior range (the sampling rule's).
    fn rho_range(&self) -> (f64, f64) {
        self.opts
            .rho_range
            .unwrap_or(SamplingRule::default().rho_range)
    }

    fn params(&self, mode: ModeKind, r: usize) -> CalibrationParams {
        let mut sampling = SamplingRule::default().noise_sd(self.opts.gauge_noise_sd);
        if let Some((lo, hi)) = self.opts.rho_range {
            sampling = sampling.rho_range(lo, hi);
        }
        let mut marginal = self.opts.marginal.clone();
        let mut sigma_eps = None;
        if let Some(sbc) = self.opts.sbc.filter(|s| s.hold) {
            marginal.fixed = Some(bamudi::params::FixedHyper {
                amplitude: sbc.hyper.amplitude,
                length_scale_factor: sbc.hyper.length_scale_factor,
            });
            marginal.level_variance = sbc.hyper.level_variance;
            sigma_eps = Some(sbc.hyper.noise_sd);
        }
        if self.opts.sbc.is_some() {
            // SBC's data come from the discrepancy's prior, present in every replicate: the
            // posterior it checks is the one that assumes a discrepancy (the evidence weighing
            // puts half its prior on none, another prior); the panel checks the weighing
            marginal.presence = bamudi::DiscrepancyPresence::Assumed;
        }
        CalibrationParams::default()
            .estimator(self.opts.estimator.clone())
            .training_size(self.opts.training_size)
            .theta_grid_points(self.opts.theta_grid_points)
            .sampling(sampling)
            .coefficients(match mode {
                // the marginal mode's settings; the other modes take none
                ModeKind::Marginal => bamudi::CoefficientMode::Marginal(marginal),
                other => other.into(),
            })
            .sigma_eps(sigma_eps)
            .seed(derive_seed(self.opts.seed, 7 + r as u64))
    }

    /// Every mode on replicate `r`; returns the estimator fitted (or the one given).
    fn replicate(
        &self,
        r: usize,
        estimator: Option<&(FittedEstimator, usize)>,
    ) -> Result<(Vec<Replicate>, (FittedEstimator, usize))> {
        let (truth, exps, new_x, rho_perp) = self.truth(r)?;
        let mut fitted = estimator.cloned();
        let mut out = Vec::new();
        for &mode in &self.opts.modes {
            let t = Instant::now();
            let cfg = self.params(mode, r).check()?;
            let cal = match &fitted {
                Some((est, pool)) => Calibrate::new(&cfg).run_with_estimator(
                    &self.model,
                    &exps,
                    est.clone(),
                    *pool,
                )?,
                None => Calibrate::new(&cfg).run(&self.model, &exps)?,
            };
            let m2 = cal.module2();
            fitted.get_or_insert_with(|| (m2.estimator.clone(), m2.training_pool_size));
            let seed = derive_seed(self.opts.seed, 5000 + r as u64);
            let mut rep = self.score(&cal, &truth, &new_x, seed)?;
            (rep.index, rep.seconds) = (r, t.elapsed().as_secs_f64());
            rep.rho_projection_true = Some(rho_perp);
            out.push(rep);
        }
        let fitted = fitted.ok_or_else(|| GateAppError::Option("coverage: no mode ran".into()))?;
        Ok((out, fitted))
    }

    /// The replicate's scores against its truth.
    fn score(
        &self,
        cal: &Calibration,
        truth: &Truth,
        new_x: &[[f64; 2]],
        seed: u64,
    ) -> Result<Replicate> {
        let post = &cal.module3().posterior;
        let predictor = cal
            .predictor(&self.model)?
            .support_policy(&SupportPolicy::default().max_nodes(BAND_SUPPORT))?;
        let nu = self.contact.gate().n_points();
        let block = QuoinBlockModel::new(
            QuoinBlockParams::default(),
            self.contact.gate().nu_points.clone(),
        )?;
        let mut tally = BandTally::default();
        let full = self.opts.scoring == Scoring::Full;
        let mut errors = ErrorTally::default();
        let seen = if full {
            Some(SeenSubspace::new(&self.model, self.contact, truth.theta)?)
        } else {
            None
        };
        let mut fatigue = (0usize, 0usize);
        for (k, x) in new_x.iter().enumerate() {
            let truth_f = truth.forces(self.contact, *x)?;
            let before = prior_mean_response(&self.model, x)?;
            let band = predictor.response(x)?;
            for p in 0..2 * nu {
                tally.add(p < nu, truth_f[p], before[p], &band, p);
            }
            let Some(seen) = &seen else {
                continue;
            };
            let forces = ConditionForces {
                truth: &truth_f,
                model_part: &truth.model_part(self.contact, *x)?,
                model_part_posterior: &crate::paper::score::posterior_model_part(
                    &predictor, truth.rho, x,
                )?,
                prior_mean: &before,
                no_discrepancy: &predictor.no_discrepancy_response(x)?.mean,
                calibrated: &band.mean,
                delta_hat: &predictor.discrepancy(x)?.mean,
            };
            errors.add_condition(&forces, seen, nu);
            let hits = fatigue_hits(&predictor, &block, x, &truth_f, derive_seed(seed, k as u64))?;
            fatigue = (fatigue.0 + hits.0, fatigue.1 + hits.1);
        }
        let ranks = match new_x.first() {
            Some(x0) if full => Some(self.ranks(cal, &predictor, &block, truth, *x0, seed)?),
            _ => None,
        };
        let s = post.summary(0);
        Ok(Replicate {
            index: 0,
            theta_true: truth.theta,
            pit: post.cdf(0, truth.theta),
            theta_mean: s.mean,
            theta_sd: s.sd,
            rho: cal.rho_star(),
            rho_sd: cal.module3().marginal().map(|m| m.rho_sd),
            rho_true: Some(truth.rho),
            band_normal: tally.inside[0] as f64 / tally.n[0].max(1) as f64,
            band_tangential: tally.inside[1] as f64 / tally.n[1].max(1) as f64,
            band_fatigue: full.then(|| fatigue.0 as f64 / fatigue.1.max(1) as f64),
            force_rmse: tally.rmse(),
            band_halfwidth: Some(tally.halfwidth()),
            band_halfwidth_median: Some(tally.median_halfwidth()),
            baselines: full.then(|| errors.baselines()),
            delta: full.then(|| errors.delta()),
            rho_projection: cal.module3().marginal().map(|m| m.rho_projection),
            rho_projection_true: None,
            hyper: cal
                .module3()
                .marginal()
                .map(|m| [m.amplitude, m.length_scale_factor, cal.sigma_eps()]),
            probability_without: cal.module3().probability_without(),
            ranks,
            seconds: 0.0,
        })
    }

    /// [`Ranks`] at the condition `x`.
    fn ranks<U: UnobservableModel, O: LinearObservableModel>(
        &self,
        cal: &Calibration,
        predictor: &bamudi::Predictor<'_, U, O>,
        block: &QuoinBlockModel,
        truth: &Truth,
        x: [f64; 2],
        seed: u64,
    ) -> Result<Ranks> {
        let rho = cal.module3().marginal().map(|m| {
            let w: f64 = m.nodes.iter().map(|n| n.weight).sum::<f64>().max(1e-300);
            m.nodes
                .iter()
                .map(|n| {
                    let sd = n.rho_var.sqrt().max(1e-300);
                    n.weight * normal_cdf((truth.rho - n.rho_mean) / sd)
                })
                .sum::<f64>()
                / w
        });
        let truth_f = truth.forces(self.contact, x)?;
        let gate = self.contact.gate();
        let a = location_a(gate);
        let draws = predictor.response_draws(&x, FATIGUE_DRAWS, derive_seed(seed, 99))?;
        let below = |values: &[f64], t: f64| {
            let n = values.len().max(1) as f64;
            let (lt, eq) = values.iter().fold((0usize, 0usize), |(lt, eq), v| {
                (lt + usize::from(*v < t), eq + usize::from(*v == t))
            });
            (lt as f64 + 0.5 * eq as f64) / n
        };
        let forces: Vec<f64> = draws.iter().map(|d| d.response[a]).collect();
        let mean = forces.iter().sum::<f64>() / forces.len().max(1) as f64;
        let sd = (forces.iter().map(|f| (f - mean).powi(2)).sum::<f64>()
            / forces.len().max(2).saturating_sub(1) as f64)
            .sqrt();
        let nu = gate.n_points();
        let mut damage_truth = vec![0.0; 4 * nu];
        block.evaluate(&x, &[0.0], &truth_f, &mut damage_truth)?;
        let largest = |d: &[f64]| d[3 * nu..4 * nu].iter().copied().fold(0.0, f64::max);
        let damage = match largest(&damage_truth) {
            t if t > 0.0 => {
                let mut out = vec![0.0; 4 * nu];
                let values = draws
                    .iter()
                    .map(|d| {
                        block.evaluate(&x, &d.theta, &d.response, &mut out)?;
                        Ok(largest(&out))
                    })
                    .collect::<Result<Vec<_>>>()?;
                Some(below(&values, t))
            }
            _ => None,
        };
        Ok(Ranks {
            rho,
            force: below(&forces, truth_f[a]),
            damage,
            force_z: (mean - truth_f[a]) / sd.max(1e-300),
        })
    }
}

/// The standard normal CDF.
fn normal_cdf(z: f64) -> f64 {
    0.5 * statrs::function::erf::erfc(-z / std::f64::consts::SQRT_2)
}

/// Joint force draws per condition behind the fatigue band (its 2.5 % quantile lies between
/// the 1.5 % and 3.5 % points).
const FATIGUE_DRAWS: usize = 1_000;

/// `(inside, live)`: quoin points with a non-zero true or predicted damage rate at `x`, and
/// those whose true rate lies in the prediction level's 95 % band.
fn fatigue_hits<U: UnobservableModel, O: LinearObservableModel>(
    predictor: &bamudi::Predictor<'_, U, O>,
    block: &QuoinBlockModel,
    x: &[f64; 2],
    truth_forces: &[f64],
    seed: u64,
) -> Result<(usize, usize)> {
    let nu = block.coordinates_in().len();
    let mut truth = vec![0.0; 4 * nu];
    block.evaluate(x, &[0.0], truth_forces, &mut truth)?;
    let band = predictor.predict_through(block, x, FATIGUE_DRAWS, seed)?;
    let (mut inside, mut live) = (0, 0);
    for p in 3 * nu..4 * nu {
        if truth[p] > 0.0 || band.upper[p] > 0.0 {
            live += 1;
            inside += usize::from(band.lower[p] <= truth[p] && truth[p] <= band.upper[p]);
        }
    }
    Ok((inside, live))
}

/// Band hits and squared errors, normal `[0]` and tangential `[1]`.
#[derive(Default)]
struct BandTally {
    inside: [usize; 2],
    n: [usize; 2],
    ss_before: [f64; 2],
    ss_after: [f64; 2],
    half: [f64; 2],
    halves: [Vec<f64>; 2],
}

impl BandTally {
    fn add(&mut self, normal: bool, truth: f64, before: f64, band: &bamudi::Band, p: usize) {
        let c = usize::from(!normal);
        self.n[c] += 1;
        self.inside[c] += usize::from(band.lower[p] <= truth && truth <= band.upper[p]);
        self.ss_before[c] += (before - truth).powi(2);
        self.ss_after[c] += (band.mean[p] - truth).powi(2);
        self.half[c] += 0.5 * (band.upper[p] - band.lower[p]);
        self.halves[c].push(0.5 * (band.upper[p] - band.lower[p]));
    }

    /// Median band half-width over the pairs (lbf/in): the mean is dominated by the few
    /// points at the gap's edge, where the force's uncertainty is that of `θ`.
    fn median_halfwidth(&self) -> NormalTangential {
        NormalTangential {
            normal: median(self.halves[0].iter().copied()),
            tangential: median(self.halves[1].iter().copied()),
        }
    }

    /// Mean band half-width (lbf/in).
    fn halfwidth(&self) -> NormalTangential {
        let m = |c: usize| self.half[c] / self.n[c].max(1) as f64;
        NormalTangential {
            normal: m(0),
            tangential: m(1),
        }
    }

    fn rmse(&self) -> ForceRmse {
        let r = |ss: f64, c: usize| (ss / self.n[c].max(1) as f64).sqrt();
        ForceRmse {
            normal_before: r(self.ss_before[0], 0),
            normal_after: r(self.ss_after[0], 0),
            tangential_before: r(self.ss_before[1], 1),
            tangential_after: r(self.ss_after[1], 1),
        }
    }
}

/// The summary of one scenario and mode over its replicates.
fn summarise(
    number: u8,
    mode: ModeKind,
    opts: &CoverageOptions,
    reps: Vec<Replicate>,
) -> Result<ScenarioCoverage> {
    let n = reps.len();
    let pits: Vec<f64> = reps.iter().map(|r| r.pit).collect();
    let levels = LEVELS
        .iter()
        .map(|&level| LevelCoverage::of(&Coverage::from_pits(&pits, level)))
        .collect::<Result<Vec<_>>>()?;
    let hist = RankHistogram::new(&pits, RANK_BINS)?;
    let mean = |f: &dyn Fn(&Replicate) -> f64| reps.iter().map(f).sum::<f64>() / n as f64;
    let rhos: Vec<f64> = reps.iter().map(|r| r.rho).collect();
    let rho_mean = mean(&|r| r.rho);
    let rho_sd = (mean(&|r| (r.rho - rho_mean).powi(2))).sqrt();
    let fold = |f: fn(f64, f64) -> f64, init| rhos.iter().copied().fold(init, f);
    Ok(ScenarioCoverage {
        name: format!("scenario {number}"),
        estimator: estimator_kind(&opts.estimator),
        mode,
        n_replicates: n,
        theta_coverage: levels
            .iter()
            .map(|l| (l.level.to_string(), l.rate))
            .collect(),
        theta_levels: levels,
        sbc_histogram: hist.counts,
        sbc_uniformity_p: hist.p_value,
        force_band_coverage_95: NormalTangential {
            normal: mean(&|r| r.band_normal),
            tangential: mean(&|r| r.band_tangential),
        },
        fatigue_band_coverage_95: reps
            .iter()
            .map(|r| r.band_fatigue)
            .sum::<Option<f64>>()
            .map(|total| total / n as f64),
        rho: [
            rho_mean,
            rho_sd,
            fold(f64::min, f64::INFINITY),
            fold(f64::max, f64::NEG_INFINITY),
        ],
        rho_check: rho_check(&reps)?,
        force_rmse_ratio_median: NormalTangential {
            normal: median(
                reps.iter()
                    .map(|r| r.force_rmse.normal_after / r.force_rmse.normal_before),
            ),
            tangential: median(
                reps.iter()
                    .map(|r| r.force_rmse.tangential_after / r.force_rmse.tangential_before),
            ),
        },
        force_band_halfwidth_ratio_median: halfwidth_ratio(&reps),
        z_rms: mean(&|r| ((r.theta_mean - r.theta_true) / r.theta_sd).powi(2)).sqrt(),
        z_mean_sd: {
            let z = |r: &Replicate| (r.theta_mean - r.theta_true) / r.theta_sd;
            let m = mean(&z);
            [m, mean(&|r| (z(r) - m).powi(2)).sqrt()]
        },
        correction: correction_summary(&reps)?,
        ranked: rank_summaries(&reps)?,
        theta_sd_median: median(reps.iter().map(|r| r.theta_sd)),
        seconds: reps.iter().map(|r| r.seconds).sum(),
        replicates: reps,
    })
}

/// Median band half-width / RMSE before, per component, if every replicate measured it.
fn halfwidth_ratio(reps: &[Replicate]) -> Option<NormalTangential> {
    let ratios: Option<Vec<(f64, f64)>> = reps
        .iter()
        .map(|r| {
            r.band_halfwidth.map(|h| {
                (
                    h.normal / r.force_rmse.normal_before,
                    h.tangential / r.force_rmse.tangential_before,
                )
            })
        })
        .collect();
    let ratios = ratios.filter(|v| !v.is_empty())?;
    Some(NormalTangential {
        normal: median(ratios.iter().map(|r| r.0)),
        tangential: median(ratios.iter().map(|r| r.1)),
    })
}

fn median(values: impl Iterator<Item = f64>) -> f64 {
    numerics::robust::median(&mut values.collect::<Vec<_>>())
}

/// A uniform number in `[0, 1)` from the top 53 bits of a derived seed.
fn unit_uniform(bits: u64) -> f64 {
    (bits >> 11) as f64 / (1u64 << 53) as f64
}

/// `exact_linear`, `lstm` or `ridge`.
pub fn estimator_kind(e: &EstimatorParams) -> String {
    match e {
        EstimatorParams::Lstm(_) => "lstm",
        EstimatorParams::Ridge(_) => "ridge",
        EstimatorParams::ExactLinear => "exact_linear",
    }
    .into()
}

impl CoverageReport {
    /// The report as pretty JSON.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self).map_err(|e| GateAppError::Serde {
            context: "coverage report".into(),
            reason: e.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn replicate(rho: f64, rho_sd: Option<f64>) -> Replicate {
        Replicate {
            index: 0,
            theta_true: 90.0,
            pit: 0.5,
            theta_mean: 90.0,
            theta_sd: 0.1,
            rho,
            rho_sd,
            rho_true: Some(0.8),
            band_normal: 1.0,
            band_tangential: 1.0,
            band_fatigue: None,
            force_rmse: ForceRmse {
                normal_before: 1.0,
                normal_after: 1.0,
                tangential_before: 1.0,
                tangential_after: 1.0,
            },
            band_halfwidth: None,
            band_halfwidth_median: None,
            baselines: None,
            delta: None,
            rho_projection: None,
            rho_projection_true: None,
            hyper: None,
            probability_without: None,
            ranks: None,
            seconds: 0.0,
        }
    }

    /// A study may start at any replicate with the exact estimator, whose fit does not depend
    /// on the replicate, but not with a learnt one, which replicate 0 trains for the others.
    /// The force-band scoring leaves out the baselines, the fatigue bands and the ranks and
    /// changes nothing else: `θ` and the force bands are the full scoring's bit for bit, and
    /// the full scoring fills every score with values in range (the suite's coverage tests use
    /// the lighter one, so this is where the full one runs in CI).
    #[test]
    fn force_band_scoring_is_the_full_scoring_without_the_extras() {
        let small = |scoring| CoverageOptions {
            scenarios: vec![1],
            n_replicates: 2,
            n_experiments: 20,
            theta_grid_points: 25,
            new_conditions: 2,
            scoring,
            threads: 1,
            seed: 99,
            ..CoverageOptions::quick()
        };
        let full = run(&small(Scoring::Full), &|_, _| {}).unwrap();
        let light = run(&small(Scoring::ForceBands), &|_, _| {}).unwrap();
        let (f, l) = (&full.scenarios[0], &light.scenarios[0]);
        for (a, b) in f.replicates.iter().zip(&l.replicates) {
            let bits = |r: &Replicate| {
                [
                    r.pit,
                    r.theta_mean,
                    r.theta_sd,
                    r.band_normal,
                    r.band_tangential,
                    r.force_rmse.normal_after,
                    r.force_rmse.tangential_after,
                ]
                .map(f64::to_bits)
            };
            assert_eq!(bits(a), bits(b));
            assert!(b.baselines.is_none() && b.delta.is_none());
            assert!(b.ranks.is_none() && b.band_fatigue.is_none());
            assert!((0.0..=1.0).contains(&a.band_fatigue.unwrap()));
            let ranks = a.ranks.unwrap();
            assert!((0.0..=1.0).contains(&ranks.force) && ranks.force_z.is_finite());
            let baselines = a.baselines.unwrap();
            assert!(serde_json::to_string(&baselines).is_ok() && a.delta.is_some());
        }
        assert!(f.correction.is_some() && f.ranked.is_some());
        assert!(l.correction.is_none() && l.ranked.is_none());
    }

    #[test]
    fn a_later_first_replicate_needs_the_exact_estimator() {
        let later = CoverageOptions {
            first_replicate: 22,
            ..CoverageOptions::quick()
        };
        assert!(later.check().is_ok());
        let learnt = CoverageOptions {
            estimator: EstimatorParams::Ridge(bamudi::RidgeParams { lambda: 1e-3 }),
            ..later
        };
        let msg = learnt.check().unwrap_err().to_string();
        assert!(msg.contains("first replicate"), "{msg}");
    }

    /// Twenty replicates whose `(ρ − 0.8)/sd` are known: the check counts those within
    /// 1.96 sd (z = ±1.95 in, ±1.97 out, so the Gaussian half-width is the one used), 15 of
    /// 20, which its acceptance region rejects, and averages z; modular replicates (no sd) are not counted.
    #[test]
    fn rho_check_counts_the_gaussian_interval_hits() {
        let sd = 0.002;
        let z = [
            0.0, 0.5, -0.5, 1.0, -1.0, 1.5, -1.5, 1.95, -1.95, 0.2, -0.2, 0.8, -0.8, 1.2, -1.2,
            2.1, 1.97, -1.97, 3.0, 2.5,
        ];
        let mut reps: Vec<Replicate> = z
            .iter()
            .map(|v| replicate(0.8 + v * sd, Some(sd)))
            .collect();
        reps.push(replicate(0.9, None));
        let c = rho_check(&reps).unwrap().unwrap();
        assert_eq!((c.coverage_95.hits, c.coverage_95.rate), (15, 0.75));
        // 20 replicates: the 1 % acceptance region of p = 0.95 starts at 16 hits
        // (P(K ≤ 15) = 0.0026 ≤ 0.005 < P(K ≤ 16) = 0.016)
        assert_eq!(c.coverage_95.acceptance, (16, 20));
        let mean = z.iter().sum::<f64>() / 20.0;
        // z is recomputed from ρ, so it carries the rounding of 0.8 + z sd: 1e-9 is far
        // above it and far below any z that matters
        assert!((c.z_mean - mean).abs() < 1e-9, "{} vs {mean}", c.z_mean);
        assert!(rho_check(&[replicate(0.9, None)]).unwrap().is_none());
    }
}
