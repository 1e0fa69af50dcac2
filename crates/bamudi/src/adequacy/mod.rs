//! Is the calibrated model adequate for the data? An adequacy verdict on every calibration
//! (marginal mode), computed from the calibration's own covariance so that what the
//! discrepancy could absorb is counted, not hidden.
//!
//! The checks (`checks`, over the linear-Gaussian residual model of `residual`):
//! * `logo`: each gauge predicted from all the others (leave one gauge out), with `ρ` and `θ`
//!   re-estimated and the discrepancy conditioned on the other gauges: chi-square over the
//!   experiments; `ppc_autocorrelation`: Ljung-Box on the same residuals whitened in row order;
//! * `ppc_condition`: each experiment's gauges predicted from the other experiments; the worst
//!   one with Šidák's correction;
//! * `sensor_offset`, `sensor_gain`, `sensor_drift`, `sensor_step`: a fault's signature on one
//!   gauge fitted jointly with `ρ`, `θ` and the integrated discrepancy (generalised least
//!   squares); a z-test each, the step's position searched (Bonferroni);
//! * `build_tolerance`: each declared tolerance of the observable model's build, integrated
//!   out by the calibration: is the deviation the data imply plausible under its prior?
//!
//! All p-values form one family with Holm's correction at
//! [`AdequacyParams::family_alpha`]; the verdict is inadequate when any is rejected. Each
//! failure is attributed ([`Attribution`]); an application adds its own physical checks with
//! [`crate::Calibration::add_adequacy_checks`]. The identifiability report ([`Identifiability`]) is
//! descriptive. The hyper-parameters (`s`, `σ`, length scales) are plug-ins: a fault inflates
//! them, which makes the tests conservative rather than alarming.
//!
//! Architecture Invariant: an inadequate calibration still returns its results; the verdict
//! never changes a number of Modules 2-4.

mod checks;
mod residual;
mod verdict;

pub use crate::params::AdequacyParams;
pub use verdict::holm;

use crate::error::{BamudiError, Result};
use crate::posterior::marginal::MarginalState;
use crate::posterior::{Module3, model_rows};
use crate::surrogate::Problem;
use mlmodel::{LinearObservableModel, UnobservableModel};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// The verdict.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Every check passes.
    Adequate,
    /// At least one check fails: the results are of a model that does not explain the data.
    Inadequate,
    /// The checks could not run (see [`AdequacyReport::reason`]).
    NotAssessed,
}

/// What a failed check is attributed to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Attribution {
    /// A sensor fault on one or two gauges explains every failure.
    Sensor,
    /// A deviation of the model's form (common to many gauges, or physical).
    ModelForm,
    /// Neither.
    Unexplained,
}

/// A sensor-fault signature.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultKind {
    /// A constant added to every reading (output units).
    Offset,
    /// A relative error of the gauge factor (estimate: scale − 1).
    Gain,
    /// A linear change over the record (estimate: the change from start to end).
    Drift,
    /// A jump at a position in the record (estimate: its size).
    Step,
}

impl FaultKind {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Offset => "offset",
            Self::Gain => "gain",
            Self::Drift => "drift",
            Self::Step => "step",
        }
    }

    /// The name of its check.
    pub(crate) fn check_name(self) -> String {
        format!("sensor_{}", self.name())
    }
}

/// One test of the family.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Check {
    /// Check id (`logo`, `ppc_autocorrelation`, `ppc_condition`, `sensor_*`, or an
    /// application's).
    pub check: String,
    /// The gauge it concerns.
    pub gauge: Option<String>,
    /// Its statistic.
    pub statistic: f64,
    /// Its p-value alone (`None`: a threshold check, outside the p-value family).
    pub p_value: Option<f64>,
    /// Holm-adjusted over the family.
    pub p_adjusted: Option<f64>,
    /// Not rejected.
    pub passed: bool,
    /// What was found, in words.
    pub detail: String,
}

/// A failed check with its attribution.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FailedCheck {
    /// Check id.
    pub check: String,
    /// Gauges it names.
    pub gauges: Vec<String>,
    /// Sensor, model form, or unexplained.
    pub attribution: Attribution,
    /// What was found.
    pub detail: String,
}

/// The sensor faults that explain a verdict's failures, fitted jointly with the calibration
/// (generalised least squares under the calibrated covariance), and what removing them does
/// to the data. Present when the failures are attributed to sensors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorCorrection {
    /// The suspected faults with their joint estimates (`sd`, `z` and `p_value` are those of
    /// the joint fit; the p-value is not multiplied by the step positions searched).
    pub faults: Vec<SensorFault>,
    /// The fitted faults at each experiment (rows) and output (columns), output units. Not
    /// serialised: it is a function of the data and the faults.
    #[serde(skip)]
    pub shift: DMatrix<f64>,
}

impl SensorCorrection {
    /// The observations with the fitted faults removed (`y − shift`), for a re-calibration
    /// or a re-check on corrected data. `y` must be the calibration's own observations.
    ///
    /// ```
    /// use bamudi::adequacy::SensorCorrection;
    /// use nalgebra::DMatrix;
    /// // a +2 microstrain offset fitted on the second of two gauges, three experiments
    /// let c = SensorCorrection { faults: vec![], shift: DMatrix::from_fn(3, 2, |_, g| 2.0 * g as f64) };
    /// let y = DMatrix::from_element(3, 2, 10.0);
    /// assert_eq!(c.corrected(&y).unwrap()[(0, 1)], 8.0);
    /// assert!(c.corrected(&DMatrix::zeros(4, 2)).is_err()); // not this calibration's data
    /// ```
    pub fn corrected(&self, y: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        if y.shape() != self.shift.shape() {
            return Err(BamudiError::dim(
                "observations vs the sensor correction (experiments x outputs)",
                self.shift.nrows() * self.shift.ncols(),
                y.nrows() * y.ncols(),
            ));
        }
        Ok(y - &self.shift)
    }

    /// `"SG2 offset +9.8 (z 26.9)"`, comma separated.
    pub fn describe(&self) -> String {
        let items: Vec<String> = self
            .faults
            .iter()
            .map(|f| {
                format!(
                    "{} {} {:+.3} (z {:.1})",
                    f.gauge,
                    f.kind.check_name().trim_start_matches("sensor_"),
                    f.estimate,
                    f.z
                )
            })
            .collect();
        items.join(", ")
    }
}

/// One gauge predicted from the others.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GaugeCheck {
    /// Gauge.
    pub gauge: String,
    /// Chi-square statistic.
    pub chi2: f64,
    /// Its degrees of freedom (experiments).
    pub dof: usize,
    /// Its p-value.
    pub p_value: f64,
    /// Mean of observed minus predicted (output units).
    pub mean_shift: f64,
    /// Share of experiments outside the 95 % predictive band.
    pub outside_band_fraction: f64,
    /// Ljung-Box p-value of the whitened residuals in row order.
    pub ljung_box_p: f64,
}

/// The worst experiment predicted from the others.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConditionCheck {
    /// Its row (1-based).
    pub experiment: usize,
    /// Its inputs.
    pub inputs: Vec<f64>,
    /// Its chi-square statistic.
    pub max_chi2: f64,
    /// Degrees of freedom (gauges).
    pub dof: usize,
    /// p-value of the maximum over the experiments (Šidák).
    pub p_value: f64,
}

/// A fault signature fitted on one gauge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorFault {
    /// Gauge.
    pub gauge: String,
    /// Kind.
    pub kind: FaultKind,
    /// Estimate (see [`FaultKind`]).
    pub estimate: f64,
    /// Its standard deviation.
    pub sd: f64,
    /// `estimate / sd`.
    pub z: f64,
    /// The step's position (fraction of the record).
    pub at_fraction: Option<f64>,
    /// Two-sided p-value (the step's multiplied by the positions searched).
    pub p_value: f64,
}

/// Which coefficient directions the gauges see, at a reference experiment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Identifiability {
    /// The reference experiment (1-based; the median of those with the discrepancy active).
    pub experiment: usize,
    /// Singular values of `B D_a` (output units per prior sd), largest first.
    pub singular_values: Vec<f64>,
    /// Posterior-to-prior variance along each seen direction (same order).
    pub posterior_to_prior_variance: Vec<f64>,
    /// Coefficient directions the gauges cannot see (prior = posterior there).
    pub unseen_directions: usize,
    /// Posterior correlation of `ρ` and `θ` (scalar `θ`).
    pub rho_theta_correlation: Option<f64>,
}

/// The adequacy of one calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AdequacyReport {
    /// The verdict.
    pub verdict: Verdict,
    /// Why the checks did not run, when they did not.
    pub reason: Option<String>,
    /// Family-wise error rate.
    pub family_alpha: f64,
    /// The failed checks, attributed.
    pub failed: Vec<FailedCheck>,
    /// Every test.
    pub checks: Vec<Check>,
    /// Each gauge from the others.
    pub gauges: Vec<GaugeCheck>,
    /// The worst experiment.
    pub condition: Option<ConditionCheck>,
    /// Every fault signature (the best step position per gauge).
    pub sensor_faults: Vec<SensorFault>,
    /// Identifiability.
    pub identifiability: Option<Identifiability>,
    /// The fitted discrepancy amplitude `s` (1: the prior scale the sampling rule implies).
    pub discrepancy_amplitude: Option<f64>,
    /// The jointly fitted sensor faults, when the failures are attributed to sensors.
    #[serde(default)]
    pub sensor_correction: Option<SensorCorrection>,
}

impl AdequacyReport {
    /// A report whose checks did not run.
    pub fn not_assessed(reason: impl Into<String>, family_alpha: f64) -> Self {
        Self {
            verdict: Verdict::NotAssessed,
            reason: Some(reason.into()),
            family_alpha,
            failed: Vec::new(),
            checks: Vec::new(),
            gauges: Vec::new(),
            condition: None,
            sensor_faults: Vec::new(),
            identifiability: None,
            discrepancy_amplitude: None,
            sensor_correction: None,
        }
    }

    /// Number of checks in the p-value family.
    pub fn family_size(&self) -> usize {
        self.checks.iter().filter(|c| c.p_value.is_some()).count()
    }

    /// Adds threshold checks: checks with a pass threshold rather than a p-value (see
    /// [`crate::Calibration::add_adequacy_checks`]).
    pub(crate) fn add_threshold_checks(&mut self, checks: Vec<(Check, Attribution)>) {
        for (c, attribution) in checks {
            if !c.passed {
                self.failed.push(FailedCheck {
                    check: c.check.clone(),
                    gauges: c.gauge.iter().cloned().collect(),
                    attribution,
                    detail: c.detail.clone(),
                });
                if self.verdict == Verdict::Adequate {
                    self.verdict = Verdict::Inadequate;
                }
            }
            self.checks.push(c);
        }
    }

    /// One line: the verdict and what failed.
    pub fn summary(&self) -> String {
        match self.verdict {
            Verdict::Adequate => format!(
                "adequate ({} tests at family-wise error {}, {} threshold check(s))",
                self.family_size(),
                self.family_alpha,
                self.checks.len() - self.family_size()
            ),
            Verdict::NotAssessed => format!(
                "not assessed ({})",
                self.reason.as_deref().unwrap_or("no reason given")
            ),
            Verdict::Inadequate => {
                let items: Vec<String> = self
                    .failed
                    .iter()
                    .map(|f| {
                        let att = serde_json::to_value(f.attribution)
                            .ok()
                            .and_then(|v| v.as_str().map(str::to_string))
                            .unwrap_or_default();
                        format!("{} [{}] ({att})", f.check, f.gauges.join(", "))
                    })
                    .collect();
                format!("INADEQUATE: {}", items.join("; "))
            }
        }
    }
}

/// What the checks read of a calibration ([`crate::Calibration`] makes it).
pub(crate) struct Subject<'a> {
    /// Module 3's result.
    pub module3: &'a Module3,
    /// The experiments' inputs.
    pub x: &'a DMatrix<f64>,
    /// The marginal mode's covariance state, made when first needed.
    pub state: &'a dyn Fn() -> Result<std::sync::Arc<MarginalState>>,
}

/// Runs the checks of a marginal-mode calibration on its own data.
pub(crate) fn assess<U, O>(
    p: &Problem<'_, U, O>,
    cal: &Subject<'_>,
    params: &AdequacyParams,
) -> Result<AdequacyReport>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let Some(fit) = cal.module3.marginal() else {
        return Ok(AdequacyReport::not_assessed(
            "the checks use the marginal mode's covariance; this calibration's coefficient \
             mode has none",
            params.family_alpha,
        ));
    };
    let (rm, lay) = residual_model(p, cal)?;
    let gauges = checks::leave_one_gauge_out(&rm, &lay)?;
    let condition = checks::worst_condition(&rm, &lay, &p.exps.x)?;
    let faults = checks::sensor_faults(&rm, &lay)?;
    let mut all = family(&gauges, &condition, &faults);
    all.extend(build_tolerance_checks(&fit.tolerances));
    verdict::correct(&mut all, params.family_alpha);
    let (failed, sensor_correction) =
        verdict::attribute(&all, &faults, &rm, &lay, params.family_alpha)?;
    let identifiability = identifiability(cal, fit)?;
    Ok(AdequacyReport {
        verdict: verdict_of(&failed),
        reason: None,
        family_alpha: params.family_alpha,
        failed,
        checks: all,
        gauges,
        condition: Some(condition),
        sensor_faults: faults,
        identifiability: Some(identifiability),
        discrepancy_amplitude: Some(fit.amplitude),
        sensor_correction,
    })
}

fn verdict_of(failed: &[FailedCheck]) -> Verdict {
    match failed.is_empty() {
        true => Verdict::Adequate,
        false => Verdict::Inadequate,
    }
}

/// The residual model at the posterior mode and the observations' layout.
fn residual_model<U, O>(
    p: &Problem<'_, U, O>,
    cal: &Subject<'_>,
) -> Result<(residual::ResidualModel, checks::Layout)>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    let fit = cal
        .module3
        .marginal()
        .ok_or_else(|| BamudiError::Calibration("adequacy checks need the marginal fit".into()))?;
    let (n_e, n_o) = (p.exps.len(), p.exps.y.ncols());
    let flat = |m: &DMatrix<f64>| DVector::from_iterator(n_e * n_o, m.transpose().iter().copied());
    let theta = fit.support_theta.clone();
    let rows = model_rows(p, &theta)?;
    let (a, b) = (flat(&rows.ag), flat(&rows.b));
    let mut cols = vec![a.clone()];
    let sd = cal.module3.posterior.sd();
    for (j, &(lo, hi)) in p.model.prior.bounds().iter().enumerate() {
        let h = sd.get(j).copied().unwrap_or(0.0).max(1e-3 * (hi - lo));
        let (mut up, mut down) = (theta.clone(), theta.clone());
        up[j] = (theta[j] + h).min(hi);
        down[j] = (theta[j] - h).max(lo);
        let (ru, rd) = (model_rows(p, &up)?, model_rows(p, &down)?);
        let step = up[j] - down[j];
        let d = (flat(&ru.ag) - flat(&rd.ag)) * fit.rho_mean + flat(&ru.b) - flat(&rd.b);
        cols.push(d / step.max(f64::MIN_POSITIVE));
    }
    let x = DMatrix::from_columns(&cols);
    let y = flat(&p.exps.y);
    let state = (cal.state)()?;
    let cov = state.covariance();
    let rm =
        residual::ResidualModel::new(cov.whitened_factor()?, cov.t(), cov.sigma2(), &x, &y - &b)?;
    let lay = checks::Layout {
        n_e,
        n_o,
        names: p.exps.output_names.clone(),
        mean: a * fit.rho_mean + b,
    };
    Ok((rm, lay))
}

/// One test per declared tolerance of the build ([`crate::posterior::marginal::nuisance`]):
/// is the deviation the data imply plausible under its prior `N(0, 1)`? Under the model the
/// posterior mean `m` of a deviation has variance `1 − sd²` (the prior's variance less the
/// expected posterior variance), so `z = m / √(1 − sd²)` is standard normal; a gate built
/// outside its declared tolerance fails it (attributed to the model's form).
fn build_tolerance_checks(tols: &[crate::posterior::marginal::ToleranceEstimate]) -> Vec<Check> {
    use statrs::function::erf::erfc;
    tols.iter()
        .map(|t| {
            let spread = (1.0 - t.sd * t.sd).max(0.0).sqrt();
            let z = if spread > 1e-6 { t.mean / spread } else { 0.0 };
            let p = erfc(z.abs() / std::f64::consts::SQRT_2);
            Check {
                check: "build_tolerance".into(),
                gauge: None,
                statistic: z,
                p_value: Some(p),
                p_adjusted: Some(p),
                passed: true,
                detail: format!(
                    "`{}`: the data put the build at {:+.2} ± {:.2} of its declared standard \
                     deviations (z = {z:+.2} against its prior)",
                    t.name, t.mean, t.sd
                ),
            }
        })
        .collect()
}

/// Every p-value of the family, in a fixed order.
fn family(gauges: &[GaugeCheck], cond: &ConditionCheck, faults: &[SensorFault]) -> Vec<Check> {
    let mut out = Vec::new();
    let check = |name: &str, gauge: Option<&str>, stat: f64, p: f64, detail: String| Check {
        check: name.to_string(),
        gauge: gauge.map(str::to_string),
        statistic: stat,
        p_value: Some(p),
        p_adjusted: Some(p),
        passed: true,
        detail,
    };
    for g in gauges {
        out.push(check(
            "logo",
            Some(&g.gauge),
            g.chi2,
            g.p_value,
            format!(
                "{} predicted from the other gauges: chi-square {:.0} on {} dof, mean shift \
                 {:+.2}, {:.0} % outside the 95 % band",
                g.gauge,
                g.chi2,
                g.dof,
                g.mean_shift,
                100.0 * g.outside_band_fraction
            ),
        ));
        out.push(check(
            "ppc_autocorrelation",
            Some(&g.gauge),
            g.ljung_box_p,
            g.ljung_box_p,
            format!(
                "{}: residuals correlated in row order (Ljung-Box p {:.2e})",
                g.gauge, g.ljung_box_p
            ),
        ));
    }
    out.push(check(
        "ppc_condition",
        None,
        cond.max_chi2,
        cond.p_value,
        format!(
            "experiment {} (inputs {:?}) predicted from the others: chi-square {:.1} on {} dof",
            cond.experiment, cond.inputs, cond.max_chi2, cond.dof
        ),
    ));
    for f in faults {
        let at = f
            .at_fraction
            .map_or(String::new(), |a| format!(" at {a:.2} of the record"));
        out.push(check(
            &f.kind.check_name(),
            Some(&f.gauge),
            f.z,
            f.p_value,
            format!(
                "{} {} {:+.3} ± {:.3}{at} (z {:.1})",
                f.gauge,
                f.kind.name(),
                f.estimate,
                f.sd,
                f.z
            ),
        ));
    }
    out
}

/// Singular values of `B D_a` at the reference experiment, the posterior-to-prior variance
/// along each seen direction, and the `ρ`-`θ` correlation.
fn identifiability(
    cal: &Subject<'_>,
    fit: &crate::posterior::marginal::MarginalFit,
) -> Result<Identifiability> {
    let amps = &fit.amplitudes;
    let active: Vec<usize> = (0..amps.nrows())
        .filter(|&i| amps.row(i).iter().all(|a| *a > 0.0))
        .collect();
    let i_ref = active.get(active.len() / 2).copied().unwrap_or(0);
    let ax: Vec<f64> = amps.row(i_ref).iter().copied().collect();
    let state = (cal.state)()?;
    let (_, b) = state.basis();
    let bd = DMatrix::from_fn(b.nrows(), b.ncols(), |q, k| b[(q, k)] * ax[k]);
    let svd = bd.clone().svd(false, true);
    let v_t = svd.v_t.ok_or_else(|| BamudiError::Numerical {
        context: "identifiability: SVD of B D_a".into(),
        reason: "no right singular vectors".into(),
    })?;
    let x: Vec<f64> = cal.x.row(i_ref).iter().copied().collect();
    let cross = state.cross_cov(fit, &x, &ax, cal.x);
    let post = state.coefficient_cov(fit, &x, &ax, &cross);
    let scale = DMatrix::from_fn(ax.len(), ax.len(), |i, j| match (i == j, ax[i] > 0.0) {
        (true, true) => 1.0 / ax[i],
        _ => 0.0,
    });
    let whitened = &scale * post * &scale / fit.amplitude;
    let tol = svd.singular_values.max() * 1e-9;
    let seen: Vec<usize> = (0..svd.singular_values.len())
        .filter(|&j| svd.singular_values[j] > tol)
        .collect();
    let ratio = seen
        .iter()
        .map(|&j| {
            let v = v_t.row(j).transpose();
            (v.transpose() * &whitened * &v)[(0, 0)]
        })
        .collect();
    Ok(Identifiability {
        experiment: i_ref + 1,
        singular_values: seen.iter().map(|&j| svd.singular_values[j]).collect(),
        posterior_to_prior_variance: ratio,
        unseen_directions: ax.len() - seen.len(),
        rho_theta_correlation: rho_theta_correlation(fit),
    })
}

/// `corr(ρ, θ)` over the stored support points (scalar `θ`).
fn rho_theta_correlation(fit: &crate::posterior::marginal::MarginalFit) -> Option<f64> {
    let nodes = &fit.nodes;
    if nodes.iter().any(|n| n.theta.len() != 1) {
        return None;
    }
    let w: f64 = nodes.iter().map(|n| n.weight).sum();
    let mt = nodes.iter().map(|n| n.weight * n.theta[0]).sum::<f64>() / w;
    let mr = nodes.iter().map(|n| n.weight * n.rho_mean).sum::<f64>() / w;
    let vt = nodes
        .iter()
        .map(|n| n.weight * (n.theta[0] - mt).powi(2))
        .sum::<f64>()
        / w;
    let vr = nodes
        .iter()
        .map(|n| n.weight * (n.rho_var + (n.rho_mean - mr).powi(2)))
        .sum::<f64>()
        / w;
    let c = nodes
        .iter()
        .map(|n| n.weight * (n.theta[0] - mt) * (n.rho_mean - mr))
        .sum::<f64>()
        / w;
    (vt > 0.0 && vr > 0.0).then(|| c / (vt * vr).sqrt())
}
