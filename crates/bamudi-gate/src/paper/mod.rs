//! Reproduction of the paper's miter-gate case study (Sec. 4.3, Table 1, Fig. 13-22): the job
//! behind `cargo xtask reproduce-paper`.
//!
//! For each scenario of Table 1 (θ* = 90 in with prior U(81, 105); θ* = 150 in with prior
//! U(135, 165)):
//!
//! 1. **Module 1**: the default gate ([`mitergate::GateConfig::default`]) is built and condensed
//!    once ([`mitergate::build_contact`], `N_u` = 509), with its quoin contact model; the
//!    multi-level model of each scenario comes from [`mitergate::multilevel`].
//! 2. **Synthetic truth** ([`mitergate::truth`]): `N_e` = 500 experiments with
//!    ρ = 0.8, the discrepancy of Eq. 53-54 and σ = 1 microstrain noise.
//! 3. **Modules 2-4** ([`bamudi::calibrate()`]), blind to ρ, θ* and δ.
//! 4. **Scoring against the truth** (only here, never inside the calibration): force RMSE over
//!    50 new water-level pairs and all 509 quoin points before calibration (the prior-averaged
//!    model, Eq. 2) and after (Module 4, Eq. 52), and the strain RMSE at the same 50 conditions
//!    with and without the discrepancy model.
//!
//! The sampling rule of Module 2 is [`SamplingRule::default`], fixed from the model alone; the
//! optional sensitivity study re-runs Modules 2-3 with the exact linear estimator for a few
//! other rules and reports how ρ* and the θ posterior move.

pub mod fatigue;
pub mod figures;
mod markdown;
pub(crate) mod score;
pub use score::DiscrepancyScore;
pub use score::prior_mean_response;
mod sensitivity;

pub use sensitivity::{SENSITIVITY_EXPERIMENTS, SENSITIVITY_GRID, sensitivity_rules};

use crate::baselines::Baselines;
use crate::error::Result;
use crate::gate::ROW_MEMO_CAPACITY;
use bamudi::ThetaSummary;
use bamudi::surrogate::{EstimatorAccuracy, estimator_accuracy};
use bamudi::{
    Calibrate, Calibration, CalibrationConfig, CalibrationParams, CoefficientMode, EstimatorParams,
    Experiments, SamplingRule,
};
use mitergate::data::truth::{self, Scenario};
use mitergate::{ContactModel, GateConfig, GateMultiLevel, MultiLevelSpec};
use nalgebra::{DMatrix, DVector};
use score::{Scores, rms, score};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Options of the reproduction. [`ReproduceOptions::paper`] is the paper's size,
/// [`ReproduceOptions::quick`] a CI-sized run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReproduceOptions {
    /// Number of experiments per scenario (paper: 500).
    pub n_experiments: usize,
    /// Module 2 training-set size (paper: 50,000).
    pub training_size: usize,
    /// The coefficient estimator of Eq. 29 (paper: LSTM).
    pub estimator: EstimatorParams,
    /// θ grid points for Module 3.
    pub theta_grid_points: usize,
    /// New water-level pairs for the prediction scores (paper: 50).
    pub new_conditions: usize,
    /// Target element size of the gate mesh (in); `None` keeps the default gate's.
    pub mesh_element_size: Option<f64>,
    /// Run the sampling-rule sensitivity study.
    pub sensitivity: bool,
    /// Gauge noise standard deviation (microstrain) from the sensor specification, added to the
    /// Module-2 training outputs so the estimator learns `E[α | ρ, x, y]` for noisy `y`. It is a
    /// property of the gauges (the paper states σ = 1 µε), not of the unknown truth; without it
    /// 12 coefficients reproduce any 7 noise-free strains exactly and Eq. 30 is flat in ρ.
    pub gauge_noise_sd: f64,
    /// Also run the conditional-coefficient variant ([`CoefficientMode::ConditionalOnTheta`]).
    #[serde(default)]
    pub conditional: bool,
    /// Also run the marginal-coefficient variant ([`CoefficientMode::Marginal`]).
    #[serde(default)]
    pub marginal: bool,
    /// The marginal mode's prior of the discrepancy coefficients (default: the library's).
    #[serde(default)]
    pub marginal_prior: bamudi::MarginalPrior,
    /// Master seed.
    pub seed: u64,
    /// Progress bars.
    pub progress: bool,
}

impl ReproduceOptions {
    /// The paper's sizes: 500 experiments, 50,000 training samples, the LSTM estimator.
    ///
    /// ```
    /// let o = bamudi_gate::paper::ReproduceOptions::paper();
    /// assert_eq!((o.n_experiments, o.training_size), (500, 50_000));
    /// ```
    pub fn paper() -> Self {
        Self {
            n_experiments: 500,
            training_size: 50_000,
            // The paper's LSTM (hidden 64, one layer, 10 scalar steps) with a budget of 60 epochs
            // and early stopping (patience 10) on a 10% validation split.
            estimator: EstimatorParams::Lstm(bamudi_lstm_paper()),
            theta_grid_points: 121,
            new_conditions: 50,
            mesh_element_size: None,
            sensitivity: true,
            gauge_noise_sd: 1.0,
            conditional: true,
            marginal: true,
            marginal_prior: bamudi::MarginalPrior::default(),
            seed: 2021,
            progress: true,
        }
    }

    /// A CI-sized run: a coarser mesh, 120 experiments and the exact linear estimator (no
    /// training set), so the whole chain runs in the test profile in well under a minute.
    ///
    /// ```
    /// let o = bamudi_gate::paper::ReproduceOptions::quick();
    /// assert!(o.n_experiments < 500);
    /// ```
    pub fn quick() -> Self {
        Self {
            n_experiments: 120,
            training_size: 4_000,
            estimator: EstimatorParams::ExactLinear,
            theta_grid_points: 49,
            new_conditions: 20,
            mesh_element_size: Some(24.0),
            sensitivity: false,
            gauge_noise_sd: 1.0,
            conditional: true,
            marginal: true,
            marginal_prior: bamudi::MarginalPrior::default(),
            seed: 2021,
            progress: false,
        }
    }
}

/// Force RMSE (lbf/in) over the new conditions and all quoin points.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ForceRmse {
    /// Normal force, prior-averaged model (ρ = 1, no discrepancy, Eq. 2).
    pub normal_before: f64,
    /// Normal force, Module 4 posterior mean (Eq. 52).
    pub normal_after: f64,
    /// Tangential force before.
    pub tangential_before: f64,
    /// Tangential force after.
    pub tangential_after: f64,
}

/// Strain prediction RMSE (microstrain) at the new conditions, against noise-free truth.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StrainRmse {
    /// BA-MUDI prediction (Module 4 with the discrepancy model).
    pub with_discrepancy: f64,
    /// Prediction of the calibration without discrepancy (ρ = 1, δ = 0, its own θ posterior).
    pub without_discrepancy: f64,
}

/// Wall-clock seconds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ScenarioTimings {
    /// Module 2: training set, estimator, ρ*, GPs.
    pub module2: f64,
    /// Module 3: covariance factorisation and θ posteriors.
    pub module3: f64,
    /// Whole scenario including truth generation and Module 4 scoring (not Module 1).
    pub total: f64,
    /// The scenario's stages in the order they ran, each with its wall time; they add up to
    /// `total` (empty in reports written before it existed).
    #[serde(default)]
    pub stages: Vec<StageSeconds>,
}

/// Wall time of one stage of a scenario.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StageSeconds {
    /// What ran, e.g. "calibration (paper's Module 3)".
    pub stage: String,
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// Splits a scenario's wall time into stages: each [`StageClock::lap`] closes the stage that
/// ran since the previous one.
struct StageClock {
    start: Instant,
    last: Instant,
    stages: Vec<StageSeconds>,
}

impl StageClock {
    fn start() -> Self {
        let now = Instant::now();
        Self {
            start: now,
            last: now,
            stages: Vec::new(),
        }
    }

    fn lap(&mut self, stage: &str) {
        let now = Instant::now();
        self.stages.push(StageSeconds {
            stage: stage.into(),
            seconds: (now - self.last).as_secs_f64(),
        });
        self.last = now;
    }
}

/// One row of the sampling-rule sensitivity study.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SensitivityRow {
    /// Human-readable description of the rule.
    pub rule: String,
    /// ρ range of the training distribution.
    pub rho_range: [f64; 2],
    /// α range multiplier `c`.
    pub alpha_scale: f64,
    /// ρ*.
    pub rho_star: f64,
    /// θ posterior with discrepancy.
    pub theta: ThetaSummary,
}

/// The same scenario re-run with [`CoefficientMode::ConditionalOnTheta`] (not in the paper),
/// reusing the fitted estimator of the main run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ConditionalResult {
    /// ρ* of the profile search.
    pub rho_star: f64,
    /// θ posterior with the discrepancy model.
    pub theta_posterior: ThetaSummary,
    /// Force RMSE before/after.
    pub force_rmse: ForceRmse,
    /// Strain RMSE (the without-discrepancy column repeats the main run's).
    pub strain_rmse: StrainRmse,
    /// σ_ε used in Module 3 (estimated).
    pub sigma_eps: f64,
    /// Seconds for the re-run of Modules 2b-3 (profile search, GP refit, posterior).
    pub seconds: f64,
    /// Posterior sd of ρ (the marginal mode; `None` where ρ* is a plug-in).
    #[serde(default)]
    pub rho_sd: Option<f64>,
    /// The reconstructed discrepancy against the true one.
    #[serde(default)]
    pub discrepancy: DiscrepancyScore,
    /// The corrected force beside every baseline and oracle ([`crate::baselines`]; absent in
    /// reports written before they were measured).
    #[serde(default)]
    pub baselines: Option<Baselines>,
    /// The identified `ρ⊥` (mean, sd; marginal mode).
    #[serde(default)]
    pub rho_projection: Option<[f64; 2]>,
}

/// Everything reported for one scenario (the `--json` schema of docs/getting-started.md).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ScenarioResult {
    /// "scenario 1" / "scenario 2".
    pub name: String,
    /// θ* (in).
    pub theta_true: f64,
    /// The paper's ρ* for this scenario.
    pub rho_star_paper: f64,
    /// Our ρ*.
    pub rho_star: f64,
    /// θ posterior of the answer: with the discrepancy model, or the evidence-weighed mixture
    /// of the models with and without it when they were weighed ([`bamudi::posterior`]).
    pub theta_posterior: ThetaSummary,
    /// θ posterior without it.
    pub theta_posterior_no_discrepancy: ThetaSummary,
    /// `P(M_0 | y)`: the posterior probability of no discrepancy, when the models were weighed.
    #[serde(default)]
    pub probability_without: Option<f64>,
    /// Force RMSE before/after.
    pub force_rmse: ForceRmse,
    /// Strain RMSE with/without discrepancy.
    pub strain_rmse: StrainRmse,
    /// RMS over experiments and gauges of the discrepancy's strain `A δ` (microstrain), to set
    /// against σ = 1.
    pub discrepancy_strain_rms: f64,
    /// σ_ε used in Module 3 (estimated).
    pub sigma_eps: f64,
    /// The reconstructed discrepancy against the true one (the paper's Module 3).
    #[serde(default)]
    pub discrepancy: DiscrepancyScore,
    /// The paper's Module 3 beside every baseline and oracle ([`crate::baselines`]).
    #[serde(default)]
    pub baselines: Option<Baselines>,
    /// The truth's `ρ⊥` at the experiments (the value the calibrations' `ρ⊥` estimates).
    #[serde(default)]
    pub rho_projection_true: Option<f64>,
    /// The estimator of Eq. 29 on held-out samples of its training distribution (Fig. 12).
    #[serde(default)]
    pub estimator_accuracy: EstimatorAccuracy,
    /// Timings.
    pub timings_s: ScenarioTimings,
    /// Sampling-rule sensitivity (empty when not run).
    pub sensitivity: Vec<SensitivityRow>,
    /// The conditional-coefficient variant (absent when not run).
    #[serde(default)]
    pub conditional: Option<ConditionalResult>,
    /// The marginal-coefficient variant (absent when not run).
    #[serde(default)]
    pub marginal: Option<ConditionalResult>,
    /// The prediction level: quoin-block fatigue before and after calibration against the
    /// truth, from the headline calibration (absent in reports written before it existed).
    #[serde(default)]
    pub fatigue: Option<fatigue::FatigueSummary>,
    /// Fig. 15 and Fig. 22 as numbers, from the headline calibration (absent in reports
    /// written before they were measured).
    #[serde(default)]
    pub figures: Option<FigureScores>,
}

/// The paper's Fig. 15 and Fig. 22 as numbers ([`figures`]).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct FigureScores {
    /// `δ̂` with its band against the true `δ` along the quoin at the paper's condition.
    pub fig15: figures::Fig15,
    /// The force at location A over a week: truth, before, without a discrepancy, after.
    pub fig22: figures::Fig22,
}

/// Module-1 facts about the gate.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GateSummary {
    /// Degrees of freedom of the FE model.
    pub n_dofs: usize,
    /// FE quoin nodes.
    pub n_quoin_nodes: usize,
    /// Build + factor + condense (s).
    pub module1_s: f64,
    /// Target element size (in).
    pub element_size: f64,
}

/// The whole reproduction.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReproduceReport {
    /// Options used.
    pub options: ReproduceOptions,
    /// The gate.
    pub gate: GateSummary,
    /// Both scenarios.
    pub scenarios: Vec<ScenarioResult>,
    /// Total wall time (s).
    pub total_s: f64,
    /// The coefficient mode of the headline (`marginal`: the engine's default, the one the
    /// coverage study checks); the scenarios' top-level fields stay the paper's Module 3.
    #[serde(default)]
    pub headline_mode: String,
}

/// The paper's LSTM (hidden 64, one layer, 10 scalar steps) with a budget of 60 epochs and
/// early stopping (patience 10) on a 10 % validation split. Each mini-batch's gradient is
/// computed in two shards on two threads (the reproduction took 226.7 s with one and
/// 215.2 s with two, on 2 cores); the count is fixed, so the trained network does not depend
/// on the machine's core count or the thread schedule. It differs from the one-shard network by the summation order only, which the
/// training amplifies: the LSTM-based numbers moved by up to 1.1 % (the conditional mode's
/// tangential RMSE, scenario 1) and θ by 0.01 in.
fn bamudi_lstm_paper() -> bamudi::surrogate::LstmSettings {
    bamudi::surrogate::LstmSettings {
        hidden: 64,
        layers: 1,
        steps: 10,
        epochs: 60,
        batch_size: 256,
        learning_rate: 1e-3,
        validation_fraction: 0.1,
        patience: 10,
        threads: 2,
        ..Default::default()
    }
}

/// Builds the default gate (Module 1, timed) with the given element size.
pub fn build_gate(element_size: Option<f64>) -> Result<(ContactModel, GateSummary)> {
    let mut cfg = GateConfig::default();
    if let Some(h) = element_size {
        cfg.mesh.element_size = h;
    }
    let (contact, s, seconds) = crate::gate::build(&cfg)?;
    let summary = GateSummary {
        n_dofs: s.n_dofs,
        n_quoin_nodes: s.n_quoin_nodes,
        module1_s: seconds,
        element_size: s.element_size,
    };
    Ok((contact, summary))
}

/// The gate as a multi-level model with prior `U(lo, hi)` and 6 + 6 Legendre terms. Its
/// model rows are remembered ([`ROW_MEMO_CAPACITY`]): the coefficient modes of a scenario, its
/// scores and the sensitivity study's rules meet the same experiments at the same `θ` nodes.
/// Its contact solves are not (a memo of 8-kB solves took the run's peak memory from 0.93 to
/// 2.72 GB; docs/benchmarks.md).
pub fn gate_model(contact: &ContactModel, prior: (f64, f64)) -> Result<GateMultiLevel> {
    let spec = MultiLevelSpec {
        gap_prior_in: prior,
        discrepancy_terms: [6, 6],
        memo_capacity: 0,
        row_memo_capacity: ROW_MEMO_CAPACITY,
    };
    Ok(mitergate::multilevel(contact.clone(), &spec)?)
}

pub(crate) fn to_experiments(exps: &truth::Experiments, n_gauges: usize) -> Result<Experiments> {
    let n = exps.x.len();
    let x = DMatrix::from_fn(n, 2, |i, j| exps.x[i][j]);
    let y = DMatrix::from_fn(n, n_gauges, |i, j| exps.strains[i][j]);
    Ok(Experiments::new(
        vec!["h_up".into(), "h_down".into()],
        (1..=n_gauges).map(|g| format!("g{g}")).collect(),
        x,
        y,
    )?)
}

/// The reproduction's calibration settings with the given sampling rule.
/// The main run is the paper's Module 3 ("as published"); the default mode runs as a variant.
fn calibration_params(opts: &ReproduceOptions, sampling: SamplingRule) -> CalibrationParams {
    CalibrationParams::default()
        .coefficients(CoefficientMode::PriorMarginal)
        .estimator(opts.estimator.clone())
        .training_size(opts.training_size)
        .theta_grid_points(opts.theta_grid_points)
        .sampling(sampling.noise_sd(opts.gauge_noise_sd))
        .seed(opts.seed)
}

/// Re-runs Module 3 of a finished calibration with another coefficient mode (same estimator,
/// `ρ*`, `α̂` and coefficient GPs, same data: [`Calibrate::run_with_surrogate`] its surrogate) and scores it
/// like the main run; returns the scores and the variant's calibration. `mode` carries its
/// settings (the marginal mode its prior).
fn run_variant(
    s: &ScenarioRun<'_>,
    cal: &Calibration,
    main_scores: &Scores,
    mode: CoefficientMode,
    observer: &dyn bamudi::observe::Observer,
) -> Result<(ConditionalResult, Calibration)> {
    let t = Instant::now();
    let cfg: CalibrationConfig = cal
        .config()
        .clone()
        .into_params()
        .coefficients(mode)
        .check()?;
    let cond = Calibrate::new(&cfg).observer(observer).run_with_surrogate(
        &s.model,
        &s.exps,
        &cal.surrogate(),
    )?;
    let seconds = t.elapsed().as_secs_f64();
    let scores = score(&s.model, &cond, &s.scenario, s.contact, &s.new_x)?;
    let result = ConditionalResult {
        rho_star: cond.rho_star(),
        theta_posterior: cond.module3().posterior.summary(0),
        force_rmse: scores.force,
        strain_rmse: StrainRmse {
            with_discrepancy: scores.strain.with_discrepancy,
            without_discrepancy: main_scores.strain.without_discrepancy,
        },
        sigma_eps: cond.sigma_eps(),
        seconds,
        rho_sd: cond.module3().marginal().map(|m| m.rho_sd),
        discrepancy: scores.discrepancy,
        baselines: Some(scores.baselines),
        rho_projection: cond.module3().marginal().map(|m| m.rho_projection),
    };
    Ok((result, cond))
}

/// One scenario's fixed inputs: the gate, the synthetic truth, the model and the new
/// conditions of the scores.
struct ScenarioRun<'a> {
    contact: &'a ContactModel,
    scenario: Scenario,
    truth: truth::Experiments,
    exps: Experiments,
    model: GateMultiLevel,
    new_x: Vec<[f64; 2]>,
}

impl<'a> ScenarioRun<'a> {
    fn new(contact: &'a ContactModel, number: u8, opts: &ReproduceOptions) -> Result<Self> {
        let scenario = Scenario::paper(number)?
            .n_experiments(opts.n_experiments)
            .seed(opts.seed.wrapping_add(number as u64));
        let truth = truth::generate(&scenario, contact)?;
        let exps = to_experiments(&truth, contact.gate().n_gauges())?;
        let model = gate_model(contact, scenario.prior)?;
        let new_x = truth::sample_levels(
            opts.new_conditions,
            opts.seed.wrapping_add(100 + number as u64),
        );
        Ok(Self {
            contact,
            scenario,
            truth,
            exps,
            model,
            new_x,
        })
    }

    /// The truth's `ρ⊥` at the experiments: `Σ aᵀ A F / Σ aᵀa`, `a = A g(x_i, θ*)`.
    fn projection_rho(&self) -> Result<f64> {
        let no_delta = self.scenario.clone().discrepancy_scale(0.0);
        let gate = self.contact.gate();
        let (mut num, mut den) = (0.0, 0.0);
        for (x, f) in self.truth.x.iter().zip(&self.truth.true_forces) {
            let g = truth::true_forces(&no_delta, self.contact, *x)?;
            let ag = &gate.a_matrix * DVector::from_column_slice(&g);
            let af = &gate.a_matrix * DVector::from_column_slice(f);
            num += ag.dot(&af);
            den += ag.dot(&ag);
        }
        // `g` here carries the truth's ρ: divide it out
        Ok(self.scenario.rho * num / den.max(1e-300))
    }

    /// RMS over experiments and gauges of the true discrepancy's strain `A δ`.
    fn discrepancy_strain_rms(&self) -> f64 {
        let no_delta = self.scenario.clone().discrepancy_scale(0.0);
        let gate = self.contact.gate();
        rms(self
            .truth
            .x
            .iter()
            .zip(&self.truth.noise_free_strains)
            .flat_map(|(x, s)| {
                let without = truth::true_forces(&no_delta, self.contact, *x)
                    .map(|f| gate.strain(&f, x[0], x[1]))
                    .unwrap_or_else(|_| DVector::from_element(s.len(), f64::NAN));
                s.iter()
                    .zip(without.iter())
                    .map(|(a, b)| a - b)
                    .collect::<Vec<_>>()
            }))
    }
}

/// Held-out samples scoring the estimator (Fig. 12): the relative RMSE of a coefficient is
/// then known to about 1.6 % (`1/√(2n)`).
const ACCURACY_SAMPLES: usize = 2_000;

/// Runs one scenario (1 or 2) on a built gate, reporting progress to `observer`; returns the
/// scored result, the headline calibration (the default marginal mode when it ran, else the
/// paper's "as published" Module 3) and the model.
pub fn run_scenario(
    contact: &ContactModel,
    number: u8,
    opts: &ReproduceOptions,
    observer: &dyn bamudi::observe::Observer,
) -> Result<(ScenarioResult, Calibration, GateMultiLevel)> {
    let mut clock = StageClock::start();
    let s = ScenarioRun::new(contact, number, opts)?;
    clock.lap("synthetic truth");
    let cfg = calibration_params(opts, SamplingRule::default()).check()?;
    let cal = Calibrate::new(&cfg)
        .observer(observer)
        .run(&s.model, &s.exps)?;
    clock.lap("calibration: Modules 2-3 (paper's Module 3)");
    let scores = score(&s.model, &cal, &s.scenario, contact, &s.new_x)?;
    clock.lap("scores of the paper's Module 3");
    let variant = |on: bool, mode| match on {
        true => run_variant(&s, &cal, &scores, mode, observer).map(Some),
        false => Ok(None),
    };
    let conditional = variant(opts.conditional, CoefficientMode::ConditionalOnTheta)?.map(|v| v.0);
    clock.lap("conditional mode: Module 3 re-run and scores");
    let marginal_mode = CoefficientMode::Marginal(opts.marginal_prior.clone());
    let (marginal, headline) = match variant(opts.marginal, marginal_mode)? {
        Some((result, cal)) => (Some(result), Some(cal)),
        None => (None, None),
    };
    clock.lap("marginal mode: Module 3 re-run and scores");
    let sens = match opts.sensitivity {
        true => sensitivity::study(contact, &s.model, s.scenario.prior, &s.exps, opts)?,
        false => Vec::new(),
    };
    clock.lap("sampling-rule sensitivity study");
    let seed = opts.seed.wrapping_add(500 + number as u64);
    let (m2, parts) = (cal.module2(), cal.parts());
    let accuracy = estimator_accuracy(&s.model, parts, m2, cal.config(), ACCURACY_SAMPLES, seed)?;
    clock.lap("estimator accuracy (Fig. 12)");
    let x_fatigue = fatigue::condition(number);
    let profile = fatigue::damage_along_quoin(
        &s.model,
        headline.as_ref().unwrap_or(&cal),
        &s.scenario,
        contact,
        x_fatigue,
        opts.seed.wrapping_add(700 + number as u64),
    )?;
    clock.lap("quoin-block fatigue");
    let discrepancy_strain_rms = s.discrepancy_strain_rms();
    let rho_projection_true = s.projection_rho()?;
    clock.lap("true discrepancy's strain and ρ⊥");
    let figure_scores = figure_scores(&s, headline.as_ref().unwrap_or(&cal), number)?;
    clock.lap("Fig. 15 and Fig. 22");
    let (m3, tm) = (cal.module3(), cal.timings());
    let result = ScenarioResult {
        name: format!("scenario {number}"),
        theta_true: s.scenario.theta_true,
        rho_star_paper: if number == 1 { 0.74 } else { 0.83 },
        rho_star: cal.rho_star(),
        theta_posterior: m3.posterior.summary(0),
        theta_posterior_no_discrepancy: m3.posterior_no_discrepancy.summary(0),
        probability_without: m3.probability_without(),
        force_rmse: scores.force,
        strain_rmse: scores.strain,
        discrepancy_strain_rms,
        sigma_eps: cal.sigma_eps(),
        discrepancy: scores.discrepancy.clone(),
        baselines: Some(scores.baselines),
        rho_projection_true: Some(rho_projection_true),
        estimator_accuracy: accuracy,
        timings_s: ScenarioTimings {
            module2: tm.module2_s(),
            module3: tm.coefficients_s + tm.module3_s,
            total: clock.start.elapsed().as_secs_f64(),
            stages: clock.stages,
        },
        sensitivity: sens,
        conditional,
        marginal,
        fatigue: Some(fatigue::FatigueSummary::of(&profile, x_fatigue)),
        figures: Some(figure_scores),
    };
    Ok((result, headline.unwrap_or(cal), s.model))
}

/// Fig. 15 and Fig. 22 as numbers for the calibration `shown`.
fn figure_scores(s: &ScenarioRun<'_>, shown: &Calibration, number: u8) -> Result<FigureScores> {
    let curve = figures::discrepancy_curve(&s.model, shown, &s.scenario, s.contact, number)?;
    let history = figures::force_history(&s.model, shown, &s.scenario, s.contact)?;
    Ok(FigureScores {
        fig15: curve.score(figures::condition(number)),
        fig22: history.score(),
    })
}

/// Runs both scenarios, reporting progress to `observer`. `on_scenario` is called after each
/// one (e.g. to write plots).
pub fn reproduce(
    opts: &ReproduceOptions,
    observer: &dyn bamudi::observe::Observer,
    mut on_scenario: impl FnMut(&ScenarioResult, &Calibration, &GateMultiLevel) -> Result<()>,
) -> Result<ReproduceReport> {
    let t = Instant::now();
    let (contact, gate) = build_gate(opts.mesh_element_size)?;
    let mut scenarios = Vec::new();
    for number in [1u8, 2] {
        let (res, cal, model) = run_scenario(&contact, number, opts, observer)?;
        on_scenario(&res, &cal, &model)?;
        scenarios.push(res);
    }
    Ok(ReproduceReport {
        options: opts.clone(),
        gate,
        scenarios,
        total_s: t.elapsed().as_secs_f64(),
        headline_mode: match opts.marginal {
            true => "marginal".into(),
            false => "prior_marginal".into(),
        },
    })
}
