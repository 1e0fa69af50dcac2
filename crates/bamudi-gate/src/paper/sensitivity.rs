//! The sampling-rule and prior-window sensitivity study of the reproduction.

use super::{ReproduceOptions, SensitivityRow, calibration_params, gate_model};
use crate::error::Result;
use bamudi::{
    Calibrate, Calibration, CalibrationParams, CoefficientMode, EstimatorParams, Experiments,
    SamplingRule, calibrate,
};
use mitergate::{ContactModel, GateMultiLevel};

/// Experiments used per rule in the sensitivity study.
pub const SENSITIVITY_EXPERIMENTS: usize = 150;
/// θ grid points per rule in the sensitivity study.
pub const SENSITIVITY_GRID: usize = 61;

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

/// The settings of one sensitivity run: the exact linear estimator on a coarser θ grid.
fn sensitivity_params(opts: &ReproduceOptions, rule: SamplingRule) -> CalibrationParams {
    calibration_params(opts, rule)
        .estimator(EstimatorParams::ExactLinear)
        .theta_grid_points(SENSITIVITY_GRID)
}

/// The sensitivity study: Modules 2-3 with the exact estimator under other sampling rules
/// and with the prior window shifted.
///
/// `model` is the scenario's (prior `prior`): the rules and the unshifted window calibrate it,
/// so that they read the model rows its other calibrations remembered.
pub(super) fn study(
    contact: &ContactModel,
    model: &GateMultiLevel,
    prior: (f64, f64),
    exps: &Experiments,
    opts: &ReproduceOptions,
) -> Result<Vec<SensitivityRow>> {
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
    // the default rule's calibration (listed first) is also the unshifted window's paper row
    let mut default_cal = None;
    for (name, rule) in sensitivity_rules() {
        let cfg = sensitivity_params(opts, rule.clone()).check()?;
        let cal = calibrate(model, &sub, &cfg)?;
        rows.push(sensitivity_row(
            format!("{name} (exact linear estimator)"),
            &rule,
            &cal,
        ));
        default_cal.get_or_insert(cal);
    }
    // The prior window shifted by a quarter of its width each way, with the paper's Module 3
    // and with the conditional coefficients: how much of the posterior comes from the prior.
    // The conditional row re-runs Module 3 on the paper-mode calibration of its window
    // (Module 2 does not depend on the coefficient mode: the same numbers, no refit).
    let quarter = 0.25 * (prior.1 - prior.0);
    let rule = SamplingRule::default();
    let params = |mode| {
        sensitivity_params(opts, rule.clone())
            .coefficients(mode)
            .check()
    };
    let (paper, conditional) = (
        params(CoefficientMode::PriorMarginal)?,
        params(CoefficientMode::ConditionalOnTheta)?,
    );
    for shift in [0.0, -quarter, quarter] {
        let shifted = (prior.0 + shift, prior.1 + shift);
        let shifted_model;
        let model = match shift == 0.0 {
            true => model,
            false => {
                shifted_model = gate_model(contact, shifted)?;
                &shifted_model
            }
        };
        let row = |what: &str, cal: &Calibration| {
            let rule_name = format!(
                "default rule, prior U({}, {}), {what} (exact linear estimator)",
                shifted.0, shifted.1
            );
            sensitivity_row(rule_name, &rule, cal)
        };
        let reused = if shift == 0.0 {
            default_cal.take()
        } else {
            None
        };
        let paper_cal = match reused {
            Some(cal) => cal, // the "default" row above
            None => {
                let cal = calibrate(model, &sub, &paper)?;
                rows.push(row("paper's Module 3", &cal));
                cal
            }
        };
        let cal =
            Calibrate::new(&conditional).run_with_surrogate(model, &sub, &paper_cal.surrogate())?;
        rows.push(row("conditional coefficients", &cal));
    }
    Ok(rows)
}

/// One row of the study's table: the rule's name and settings, `ρ*` and the `θ` posterior.
fn sensitivity_row(rule_name: String, rule: &SamplingRule, cal: &Calibration) -> SensitivityRow {
    SensitivityRow {
        rule: rule_name,
        rho_range: [rule.rho_range.0, rule.rho_range.1],
        alpha_scale: rule.alpha_scale,
        rho_star: cal.rho_star(),
        theta: cal.module3().posterior.summary(0),
    }
}
