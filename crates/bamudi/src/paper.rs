//! Reproduction of the paper's miter-gate case study (Sec. 4.3, Table 1, Fig. 13-22): the job
//! behind `cargo xtask reproduce-paper`.
//!
//! For each scenario of Table 1 (θ* = 90 in with prior U(81, 105); θ* = 150 in with prior
//! U(135, 165)):
//!
//! 1. **Module 1**: the default gate ([`mitergate::GateConfig::default`]) is built and condensed
//!    once ([`mitergate::GateModel::condense`], `N_u` = 509), and wrapped in the quoin contact
//!    model.
//! 2. **Synthetic truth** ([`mitergate::truth`]): `N_e` = 500 experiments with
//!    ρ = 0.8, the discrepancy of Eq. 53-54 and σ = 1 microstrain noise.
//! 3. **Modules 2-4** ([`crate::calibrate()`]), blind to ρ, θ* and δ.
//! 4. **Scoring against the truth** (only here, never inside the calibration): force RMSE over
//!    50 new water-level pairs and all 509 quoin points before calibration (the prior-averaged
//!    model, Eq. 2) and after (Module 4, Eq. 52), and the strain RMSE at the same 50 conditions
//!    with and without the discrepancy model.
//!
//! The sampling rule of Module 2 is [`SamplingRule::default`], fixed from the model alone; the
//! optional sensitivity study re-runs Modules 2-3 with the exact linear estimator for a few
//! other rules and reports how ρ* and the θ posterior move.

use crate::calibrate::{Calibration, ThetaPosterior, calibrate, finish_calibration};
use crate::config::{CalibrationConfig, CoefficientMode, EstimatorConfig, SamplingRule};
use crate::error::{BamudiError, Result};
use crate::experiments::Experiments;
use mitergate::contact::{ContactModel, ContactParams};
use mitergate::gate_model::{ContactForceModel, StrainModel};
use mitergate::truth::{self, Scenario};
use mitergate::{GateConfig, GateModel};
use mlmodel::{
    DiscrepancyBasis, LinearObservableModel, MultiLevelModel, ObservableModel, UniformPrior,
    UnobservableModel,
};
use nalgebra::{DMatrix, DVector};
use orthopoly::Family;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// The miter-gate multi-level model as the calibration consumes it.
pub type GateMultiLevel = MultiLevelModel<ContactForceModel, StrainModel>;

/// Options of the reproduction. [`ReproduceOptions::paper`] is the paper's size,
/// [`ReproduceOptions::quick`] a CI-sized run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReproduceOptions {
    /// Number of experiments per scenario (paper: 500).
    pub n_experiments: usize,
    /// Module 2 training-set size (paper: 50,000).
    pub training_size: usize,
    /// The coefficient estimator of Eq. 29 (paper: LSTM).
    pub estimator: EstimatorConfig,
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
    /// Master seed.
    pub seed: u64,
    /// Progress bars.
    pub progress: bool,
}

impl ReproduceOptions {
    /// The paper's sizes: 500 experiments, 50,000 training samples, the LSTM estimator.
    ///
    /// ```
    /// let o = bamudi::paper::ReproduceOptions::paper();
    /// assert_eq!((o.n_experiments, o.training_size), (500, 50_000));
    /// ```
    pub fn paper() -> Self {
        Self {
            n_experiments: 500,
            training_size: 50_000,
            // The paper's LSTM (hidden 64, one layer, 10 scalar steps) with a budget of 60 epochs
            // and early stopping (patience 10) on a 10% validation split.
            estimator: EstimatorConfig::Lstm {
                hidden: 64,
                layers: 1,
                steps: 10,
                epochs: 60,
                batch_size: 256,
                learning_rate: 1e-3,
                validation_fraction: 0.1,
                patience: 10,
            },
            theta_grid_points: 121,
            new_conditions: 50,
            mesh_element_size: None,
            sensitivity: true,
            gauge_noise_sd: 1.0,
            conditional: true,
            seed: 2021,
            progress: true,
        }
    }

    /// A CI-sized run: a coarser mesh, 120 experiments and the exact linear estimator (no
    /// training set), so the whole chain runs in the test profile in well under a minute.
    ///
    /// ```
    /// let o = bamudi::paper::ReproduceOptions::quick();
    /// assert!(o.n_experiments < 500);
    /// ```
    pub fn quick() -> Self {
        Self {
            n_experiments: 120,
            training_size: 4_000,
            estimator: EstimatorConfig::ExactLinear,
            theta_grid_points: 49,
            new_conditions: 20,
            mesh_element_size: Some(24.0),
            sensitivity: false,
            gauge_noise_sd: 1.0,
            conditional: true,
            seed: 2021,
            progress: false,
        }
    }
}

/// Posterior summary of θ (inches).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ThetaSummary {
    /// Posterior mean.
    pub mean: f64,
    /// Posterior standard deviation.
    pub sd: f64,
    /// Equal-tailed 95% credible interval.
    pub ci95: [f64; 2],
}

impl ThetaSummary {
    fn of(p: &ThetaPosterior) -> Self {
        let ci = p.ci95()[0];
        Self {
            mean: p.mean()[0],
            sd: p.sd()[0],
            ci95: [ci.0, ci.1],
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
}

/// Everything reported for one scenario (the `--json` schema of the README).
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
    /// θ posterior with the discrepancy model.
    pub theta_posterior: ThetaSummary,
    /// θ posterior without it.
    pub theta_posterior_no_discrepancy: ThetaSummary,
    /// Force RMSE before/after.
    pub force_rmse: ForceRmse,
    /// Strain RMSE with/without discrepancy.
    pub strain_rmse: StrainRmse,
    /// RMS over experiments and gauges of the discrepancy's strain `A δ` (microstrain), to set
    /// against σ = 1.
    pub discrepancy_strain_rms: f64,
    /// σ_ε used in Module 3 (estimated).
    pub sigma_eps: f64,
    /// Timings.
    pub timings_s: ScenarioTimings,
    /// Sampling-rule sensitivity (empty when not run).
    pub sensitivity: Vec<SensitivityRow>,
    /// The conditional-coefficient variant (absent when not run).
    #[serde(default)]
    pub conditional: Option<ConditionalResult>,
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
}

/// Builds the default gate (Module 1) and its contact model.
pub fn build_gate(element_size: Option<f64>) -> Result<(ContactModel, GateSummary)> {
    let t = Instant::now();
    let mut cfg = GateConfig::default();
    if let Some(h) = element_size {
        cfg.mesh.element_size = h;
    }
    let gate_err = |e: mitergate::GateError| BamudiError::Application(e.to_string());
    let model = GateModel::build(&cfg).map_err(gate_err)?;
    let condensed = model.condense(mitergate::DEFAULT_NU).map_err(gate_err)?;
    let summary = GateSummary {
        n_dofs: model.n_dofs(),
        n_quoin_nodes: condensed.n_quoin_nodes(),
        module1_s: 0.0,
        element_size: cfg.mesh.element_size,
    };
    let contact = ContactParams::default()
        .build(condensed)
        .map_err(gate_err)?;
    Ok((
        contact,
        GateSummary {
            module1_s: t.elapsed().as_secs_f64(),
            ..summary
        },
    ))
}

/// The gate as an `mlmodel` multi-level model with prior `U(lo, hi)` and 6 + 6 Legendre terms.
pub fn gate_model(contact: &ContactModel, prior: (f64, f64)) -> Result<GateMultiLevel> {
    let gate = contact.gate();
    let basis = DiscrepancyBasis::new(
        Family::Legendre,
        (0.0, gate.quoin_height),
        &gate.nu_points,
        &[6, 6],
    )?;
    let prior = UniformPrior::new(vec![prior])?;
    Ok(MultiLevelModel::new(
        ContactForceModel::new(contact.clone()),
        StrainModel::new(gate),
        Box::new(prior),
        basis,
    )?)
}

fn to_experiments(exps: &truth::Experiments, n_gauges: usize) -> Result<Experiments> {
    let n = exps.x.len();
    let x = DMatrix::from_fn(n, 2, |i, j| exps.x[i][j]);
    let y = DMatrix::from_fn(n, n_gauges, |i, j| exps.strains[i][j]);
    Experiments::new(
        vec!["h_up".into(), "h_down".into()],
        (1..=n_gauges).map(|g| format!("g{g}")).collect(),
        x,
        y,
    )
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (mut ss, mut n) = (0.0, 0usize);
    for v in values {
        ss += v * v;
        n += 1;
    }
    (ss / n.max(1) as f64).sqrt()
}

/// Prior-averaged response `Σ_j w_j g_u(x, θ_j)` (Eq. 2), the "before calibration" model.
fn prior_mean_response(model: &GateMultiLevel, x: &[f64]) -> Result<Vec<f64>> {
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

/// Strains `A g + s_w` of the no-discrepancy calibration, averaged over its θ posterior.
fn no_discrepancy_strain(model: &GateMultiLevel, cal: &Calibration, x: &[f64]) -> Result<Vec<f64>> {
    let support = cal.posterior_no_discrepancy.support(200);
    let g = weighted_response(model, x, support.iter().map(|(t, w)| (t[0], *w)))?;
    let mut b = vec![0.0; model.observable.output_dim()];
    model.observable.offset(x, &[0.0], &mut b)?;
    let s = model.observable.matrix() * DVector::from_vec(g) + DVector::from_vec(b);
    Ok(s.iter().copied().collect())
}

struct Scores {
    force: ForceRmse,
    strain: StrainRmse,
}

fn score(
    model: &GateMultiLevel,
    cal: &Calibration,
    scenario: &Scenario,
    contact: &ContactModel,
    new_x: &[[f64; 2]],
) -> Result<Scores> {
    let nu = contact.gate().n_points();
    let gate_err = |e: mitergate::GateError| BamudiError::Application(e.to_string());
    let (mut dn_b, mut dn_a, mut dt_b, mut dt_a) = (vec![], vec![], vec![], vec![]);
    let (mut ds_w, mut ds_wo) = (vec![], vec![]);
    for x in new_x {
        let truth_f = truth::true_forces(scenario, contact, *x).map_err(gate_err)?;
        let before = prior_mean_response(model, x)?;
        let after = cal.predict_response(model, x)?.mean;
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
        let true_strain = contact.gate().strain(&truth_f, x[0], x[1]);
        let with = cal.predict_outputs(model, x)?.mean;
        let without = no_discrepancy_strain(model, cal, x)?;
        for p in 0..true_strain.len() {
            ds_w.push(with[p] - true_strain[p]);
            ds_wo.push(without[p] - true_strain[p]);
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
    })
}

fn calibration_config(opts: &ReproduceOptions, sampling: SamplingRule) -> CalibrationConfig {
    CalibrationConfig::default()
        .estimator(opts.estimator.clone())
        .training_size(opts.training_size)
        .theta_grid_points(opts.theta_grid_points)
        .sampling(sampling.noise_sd(opts.gauge_noise_sd))
        .seed(opts.seed)
        .progress(opts.progress)
}

/// Experiments used per rule in the sensitivity study.
pub const SENSITIVITY_EXPERIMENTS: usize = 150;
/// θ grid points per rule in the sensitivity study.
pub const SENSITIVITY_GRID: usize = 61;

/// Printed above the conditional-mode table.
const CONDITIONAL_NOTE: &str = "\n## Module 3 with the coefficients conditioned on θ (not in the paper)\n\n\
The paper's Module 3 (Eq. 50) uses coefficients estimated with θ marginalised over its prior \
(Eq. 25/27), the same at every θ; they absorb the difference between the prior-averaged response \
and the response at the true θ, so the posterior is pulled towards the θ whose response equals the \
prior average and moves with the prior window. The conditional mode (`CoefficientMode::ConditionalOnTheta`) \
re-applies the same fitted estimator at each θ to the observations shifted to the prior-averaged model, \
re-conditions the coefficient GPs on them with their hyper-parameters held, and sets ρ* by Eq. 30 \
with θ profiled instead of marginalised (see docs/equations.md). Same data, same estimator:\n\n";

/// Printed under each sensitivity table.
const SENSITIVITY_NOTE: &str = "\nThe ρ range shapes only the training set of learnt estimators; the exact linear \
estimator needs no training set, so its ρ-range rows equal the default row (kept to show that). \
The α range enters the exact estimator through the prior moments of α.\n";

/// The sampling rules of the sensitivity study (the default first).
pub fn sensitivity_rules() -> Vec<(String, SamplingRule)> {
    let base = SamplingRule::default();
    let (lo, hi) = base.rho_range;
    vec![
        ("default".into(), base.clone()),
        (
            "alpha range x0.5".into(),
            base.clone().alpha_scale(base.alpha_scale * 0.5),
        ),
        (
            "alpha range x2".into(),
            base.clone().alpha_scale(base.alpha_scale * 2.0),
        ),
        (
            "rho range [0.5, 1.5]".into(),
            base.clone().rho_range(0.5, 1.5),
        ),
        (
            format!("rho range [{lo}, {}]", hi * 0.5 + 0.5),
            base.rho_range(lo, hi * 0.5 + 0.5),
        ),
    ]
}

/// The configuration of one sensitivity run: the exact linear estimator on a coarser θ grid.
fn sensitivity_config(opts: &ReproduceOptions, rule: SamplingRule) -> CalibrationConfig {
    calibration_config(opts, rule)
        .estimator(EstimatorConfig::ExactLinear)
        .theta_grid_points(SENSITIVITY_GRID)
        .progress(false)
}

fn sensitivity(
    contact: &ContactModel,
    prior: (f64, f64),
    exps: &Experiments,
    opts: &ReproduceOptions,
) -> Result<Vec<SensitivityRow>> {
    let model = &gate_model(contact, prior)?;
    // Each rule re-runs Modules 2-3; to keep the study affordable it uses the first
    // `SENSITIVITY_EXPERIMENTS` experiments and a coarser θ grid (stated in the report).
    let n = exps.len().min(SENSITIVITY_EXPERIMENTS);
    let sub = Experiments::new(
        exps.input_names.clone(),
        exps.output_names.clone(),
        exps.x.rows(0, n).into_owned(),
        exps.y.rows(0, n).into_owned(),
    )?;
    let mut rows = Vec::new();
    for (name, rule) in sensitivity_rules() {
        let cfg = sensitivity_config(opts, rule.clone());
        let cal = calibrate(model, &sub, &cfg)?;
        rows.push(SensitivityRow {
            rule: format!("{name} (exact linear estimator)"),
            rho_range: [rule.rho_range.0, rule.rho_range.1],
            alpha_scale: rule.alpha_scale,
            rho_star: cal.rho.rho_star,
            theta: ThetaSummary::of(&cal.posterior),
        });
    }
    // The prior window shifted by a quarter of its width each way, with the paper's Module 3
    // and with the conditional coefficients: how much of the posterior comes from the prior.
    let quarter = 0.25 * (prior.1 - prior.0);
    for shift in [0.0, -quarter, quarter] {
        let shifted = (prior.0 + shift, prior.1 + shift);
        let model = gate_model(contact, shifted)?;
        for mode in [
            CoefficientMode::PriorMarginal,
            CoefficientMode::ConditionalOnTheta,
        ] {
            if shift == 0.0 && mode == CoefficientMode::PriorMarginal {
                continue; // the "default" row above
            }
            let rule = SamplingRule::default();
            let cfg = sensitivity_config(opts, rule.clone()).coefficients(mode);
            let cal = calibrate(&model, &sub, &cfg)?;
            let what = match mode {
                CoefficientMode::PriorMarginal => "paper's Module 3",
                CoefficientMode::ConditionalOnTheta => "conditional coefficients",
            };
            rows.push(SensitivityRow {
                rule: format!(
                    "default rule, prior U({}, {}), {what} (exact linear estimator)",
                    shifted.0, shifted.1
                ),
                rho_range: [rule.rho_range.0, rule.rho_range.1],
                alpha_scale: rule.alpha_scale,
                rho_star: cal.rho.rho_star,
                theta: ThetaSummary::of(&cal.posterior),
            });
        }
    }
    Ok(rows)
}

/// Re-runs Modules 2b-3 of a finished calibration with the conditional coefficient mode
/// (same fitted estimator, same data) and scores it like the main run.
fn run_conditional(
    model: &GateMultiLevel,
    exps: &Experiments,
    cal: &Calibration,
    scenario: &Scenario,
    contact: &ContactModel,
    new_x: &[[f64; 2]],
    main_scores: &Scores,
) -> Result<ConditionalResult> {
    let t = Instant::now();
    let cfg = cal
        .config
        .clone()
        .coefficients(CoefficientMode::ConditionalOnTheta);
    let cond = finish_calibration(
        model,
        exps,
        &cfg,
        cal.x_bounds.clone(),
        cal.theta_rule.clone(),
        cal.parts.clone(),
        cal.training_pool_size,
        cal.estimator.clone(),
        crate::Timings::default(),
    )?;
    let seconds = t.elapsed().as_secs_f64();
    let scores = score(model, &cond, scenario, contact, new_x)?;
    Ok(ConditionalResult {
        rho_star: cond.rho.rho_star,
        theta_posterior: ThetaSummary::of(&cond.posterior),
        force_rmse: scores.force,
        strain_rmse: StrainRmse {
            with_discrepancy: scores.strain.with_discrepancy,
            without_discrepancy: main_scores.strain.without_discrepancy,
        },
        sigma_eps: cond.sigma_eps,
        seconds,
    })
}

/// Runs one scenario (1 or 2) on a built gate; returns the scored result and the calibration.
pub fn run_scenario(
    contact: &ContactModel,
    number: u8,
    opts: &ReproduceOptions,
) -> Result<(ScenarioResult, Calibration, GateMultiLevel)> {
    let t_total = Instant::now();
    let gate_err = |e: mitergate::GateError| BamudiError::Application(e.to_string());
    let scenario = Scenario::paper(number)
        .map_err(gate_err)?
        .n_experiments(opts.n_experiments)
        .seed(opts.seed.wrapping_add(number as u64));
    let truth_exps = truth::generate(&scenario, contact).map_err(gate_err)?;
    let n_gauges = contact.gate().n_gauges();
    let exps = to_experiments(&truth_exps, n_gauges)?;
    let model = gate_model(contact, scenario.prior)?;
    let cal = calibrate(
        &model,
        &exps,
        &calibration_config(opts, SamplingRule::default()),
    )?;
    let new_x = truth::sample_levels(
        opts.new_conditions,
        opts.seed.wrapping_add(100 + number as u64),
    );
    let scores = score(&model, &cal, &scenario, contact, &new_x)?;
    let discrepancy_strain_rms = rms(truth_exps
        .x
        .iter()
        .zip(&truth_exps.noise_free_strains)
        .flat_map(|(x, s)| {
            let without = truth::true_forces(&scenario.clone().discrepancy_scale(0.0), contact, *x)
                .map(|f| contact.gate().strain(&f, x[0], x[1]))
                .unwrap_or_else(|_| DVector::from_element(s.len(), f64::NAN));
            s.iter()
                .zip(without.iter())
                .map(|(a, b)| a - b)
                .collect::<Vec<_>>()
        }));
    let conditional = if opts.conditional {
        Some(run_conditional(
            &model, &exps, &cal, &scenario, contact, &new_x, &scores,
        )?)
    } else {
        None
    };
    let sens = if opts.sensitivity {
        sensitivity(contact, scenario.prior, &exps, opts)?
    } else {
        Vec::new()
    };
    let tm = &cal.timings;
    let result = ScenarioResult {
        name: format!("scenario {number}"),
        theta_true: scenario.theta_true,
        rho_star_paper: if number == 1 { 0.74 } else { 0.83 },
        rho_star: cal.rho.rho_star,
        theta_posterior: ThetaSummary::of(&cal.posterior),
        theta_posterior_no_discrepancy: ThetaSummary::of(&cal.posterior_no_discrepancy),
        force_rmse: scores.force,
        strain_rmse: scores.strain,
        discrepancy_strain_rms,
        sigma_eps: cal.sigma_eps,
        timings_s: ScenarioTimings {
            module2: tm.training_set_s + tm.estimator_s + tm.rho_s + tm.gp_s,
            module3: tm.module3_s,
            total: t_total.elapsed().as_secs_f64(),
        },
        sensitivity: sens,
        conditional,
    };
    Ok((result, cal, model))
}

/// Runs both scenarios. `on_scenario` is called after each one (e.g. to write plots).
pub fn reproduce(
    opts: &ReproduceOptions,
    mut on_scenario: impl FnMut(&ScenarioResult, &Calibration, &GateMultiLevel) -> Result<()>,
) -> Result<ReproduceReport> {
    let t = Instant::now();
    let (contact, gate) = build_gate(opts.mesh_element_size)?;
    let mut scenarios = Vec::new();
    for number in [1u8, 2] {
        let (res, cal, model) = run_scenario(&contact, number, opts)?;
        on_scenario(&res, &cal, &model)?;
        scenarios.push(res);
    }
    Ok(ReproduceReport {
        options: opts.clone(),
        gate,
        scenarios,
        total_s: t.elapsed().as_secs_f64(),
    })
}

impl ReproduceReport {
    /// The `--json` document: `{"scenarios": [...], "gate": ..., "options": ..., "total_s"}`.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self).map_err(|e| BamudiError::Serde {
            context: "reproduce-paper report".into(),
            reason: e.to_string(),
        })
    }

    /// The markdown table, paper value beside ours.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        s.push_str("# Reproduction of the paper's case study (Sec. 4.3)\n\n");
        s.push_str(&format!(
            "Gate: {} DOF ({} in elements), {} quoin nodes, Module 1 (build + condense) {:.1} s. \
             Experiments per scenario: {}, training samples: {}, estimator: {}. Total wall time {:.1} s.\n\n",
            self.gate.n_dofs,
            self.gate.element_size,
            self.gate.n_quoin_nodes,
            self.gate.module1_s,
            self.options.n_experiments,
            self.options.training_size,
            estimator_name(&self.options.estimator),
            self.total_s
        ));
        s.push_str(
            "| quantity | paper S1 | ours S1 | paper S2 | ours S2 |\n|---|---|---|---|---|\n",
        );
        let sc = &self.scenarios;
        let row = |s: &mut String,
                   name: &str,
                   p1: &str,
                   f: &dyn Fn(&ScenarioResult) -> String,
                   p2: &str| {
            s.push_str(&format!(
                "| {name} | {p1} | {} | {p2} | {} |\n",
                f(&sc[0]),
                sc.get(1).map(f).unwrap_or_default()
            ));
        };
        let th = |t: &ThetaSummary| {
            format!(
                "{:.2} ± {:.2} [{:.2}, {:.2}]",
                t.mean, t.sd, t.ci95[0], t.ci95[1]
            )
        };
        row(
            &mut s,
            "θ* (in)",
            "90",
            &|r| format!("{}", r.theta_true),
            "150",
        );
        row(
            &mut s,
            "ρ* (truth 0.8)",
            "0.74",
            &|r| format!("{:.3}", r.rho_star),
            "0.83",
        );
        row(
            &mut s,
            "θ posterior, with discrepancy: mean ± sd [95%]",
            "close to 90 (Fig. 16)",
            &|r| th(&r.theta_posterior),
            "close to 150 (Fig. 16)",
        );
        row(
            &mut s,
            "θ posterior, without discrepancy",
            "biased (Fig. 16)",
            &|r| th(&r.theta_posterior_no_discrepancy),
            "biased (Fig. 16)",
        );
        row(
            &mut s,
            "normal force RMSE before → after (lbf/in)",
            "reduced (Fig. 18)",
            &|r| {
                format!(
                    "{:.1} → {:.1}",
                    r.force_rmse.normal_before, r.force_rmse.normal_after
                )
            },
            "reduced (Fig. 18)",
        );
        row(
            &mut s,
            "tangential force RMSE before → after (lbf/in)",
            "reduced (Fig. 22)",
            &|r| {
                format!(
                    "{:.1} → {:.1}",
                    r.force_rmse.tangential_before, r.force_rmse.tangential_after
                )
            },
            "reduced (Fig. 22)",
        );
        row(
            &mut s,
            "strain RMSE at new conditions, with / without discrepancy (µε)",
            "smaller with (Fig. 19)",
            &|r| {
                format!(
                    "{:.2} / {:.2}",
                    r.strain_rmse.with_discrepancy, r.strain_rmse.without_discrepancy
                )
            },
            "smaller with (Fig. 20)",
        );
        row(
            &mut s,
            "RMS strain of the true discrepancy A δ (µε; noise σ = 1)",
            "–",
            &|r| format!("{:.2}", r.discrepancy_strain_rms),
            "–",
        );
        row(
            &mut s,
            "σ_ε estimated for Module 3 (µε)",
            "1 (given)",
            &|r| format!("{:.3}", r.sigma_eps),
            "1 (given)",
        );
        row(
            &mut s,
            "Module 2 wall time (s)",
            "11,400 (190 min)",
            &|r| format!("{:.1}", r.timings_s.module2),
            "–",
        );
        row(
            &mut s,
            "Module 3 wall time (s)",
            "3,360 (56 min)",
            &|r| format!("{:.1}", r.timings_s.module3),
            "–",
        );
        row(
            &mut s,
            "scenario total (s)",
            "14,820 (247 min)",
            &|r| format!("{:.1}", r.timings_s.total),
            "–",
        );
        if sc.iter().any(|r| r.conditional.is_some()) {
            s.push_str(CONDITIONAL_NOTE);
            s.push_str("| quantity | paper's Module 3 S1 | conditional S1 | paper's Module 3 S2 | conditional S2 |\n|---|---|---|---|---|\n");
            let crow = |s: &mut String,
                        name: &str,
                        f: &dyn Fn(&ScenarioResult) -> String,
                        g: &dyn Fn(&ConditionalResult) -> String| {
                let cell = |r: &ScenarioResult| r.conditional.as_ref().map(g).unwrap_or_default();
                s.push_str(&format!(
                    "| {name} | {} | {} | {} | {} |\n",
                    f(&sc[0]),
                    cell(&sc[0]),
                    sc.get(1).map(f).unwrap_or_default(),
                    sc.get(1).map(cell).unwrap_or_default()
                ));
            };
            crow(
                &mut s,
                "ρ* (truth 0.8)",
                &|r| format!("{:.3}", r.rho_star),
                &|c| format!("{:.3}", c.rho_star),
            );
            crow(
                &mut s,
                "θ posterior: mean ± sd [95%] (truth 90 / 150)",
                &|r| th(&r.theta_posterior),
                &|c| th(&c.theta_posterior),
            );
            crow(
                &mut s,
                "normal force RMSE before → after (lbf/in)",
                &|r| {
                    format!(
                        "{:.1} → {:.1}",
                        r.force_rmse.normal_before, r.force_rmse.normal_after
                    )
                },
                &|c| {
                    format!(
                        "{:.1} → {:.1}",
                        c.force_rmse.normal_before, c.force_rmse.normal_after
                    )
                },
            );
            crow(
                &mut s,
                "tangential force RMSE before → after (lbf/in)",
                &|r| {
                    format!(
                        "{:.1} → {:.1}",
                        r.force_rmse.tangential_before, r.force_rmse.tangential_after
                    )
                },
                &|c| {
                    format!(
                        "{:.1} → {:.1}",
                        c.force_rmse.tangential_before, c.force_rmse.tangential_after
                    )
                },
            );
            crow(
                &mut s,
                "strain RMSE at new conditions (µε)",
                &|r| format!("{:.2}", r.strain_rmse.with_discrepancy),
                &|c| format!("{:.2}", c.strain_rmse.with_discrepancy),
            );
            crow(
                &mut s,
                "σ_ε estimated for Module 3 (µε)",
                &|r| format!("{:.3}", r.sigma_eps),
                &|c| format!("{:.3}", c.sigma_eps),
            );
            crow(&mut s, "extra wall time (s)", &|_| "–".into(), &|c| {
                format!("{:.1}", c.seconds)
            });
        }
        for r in sc.iter().filter(|r| !r.sensitivity.is_empty()) {
            s.push_str(&format!(
                "\n## Sampling-rule sensitivity, {} (θ* = {}; first {} experiments, {} θ nodes)\n\n| rule | ρ range | α scale c | ρ* | θ mean ± sd [95%] |\n|---|---|---|---|---|\n",
                r.name, r.theta_true, SENSITIVITY_EXPERIMENTS, SENSITIVITY_GRID
            ));
            for row in &r.sensitivity {
                s.push_str(&format!(
                    "| {} | [{}, {}] | {} | {:.3} | {} |\n",
                    row.rule,
                    row.rho_range[0],
                    row.rho_range[1],
                    row.alpha_scale,
                    row.rho_star,
                    th(&row.theta)
                ));
            }
            s.push_str(SENSITIVITY_NOTE);
        }
        s
    }
}

fn estimator_name(e: &EstimatorConfig) -> &'static str {
    match e {
        EstimatorConfig::Lstm { .. } => "LSTM (seqnet)",
        EstimatorConfig::Ridge { .. } => "ridge (smartcore)",
        EstimatorConfig::ExactLinear => "exact linear-Gaussian",
    }
}
