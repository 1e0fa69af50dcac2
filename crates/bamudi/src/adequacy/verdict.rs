//! One family of p-values with Holm's step-down correction, the verdict, and the attribution
//! of each failure to a sensor, to the model's form, or to nothing known.

use super::residual::ResidualModel;
use super::{Attribution, Check, FailedCheck, FaultKind, SensorCorrection, SensorFault, checks};
use crate::error::Result;
use nalgebra::DMatrix;

/// Holm-adjusted p-values (in the input's order): the `j`-th smallest times `n − j + 1`,
/// made non-decreasing. Rejecting where the adjusted value is below `α` controls the
/// family-wise error rate at `α` under any dependence.
pub fn holm(p: &[f64]) -> Vec<f64> {
    let n = p.len();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| p[a].total_cmp(&p[b]));
    let mut adjusted = vec![0.0; n];
    let mut running = 0.0f64;
    for (j, &i) in order.iter().enumerate() {
        running = running.max(((n - j) as f64 * p[i]).min(1.0));
        adjusted[i] = running;
    }
    adjusted
}

/// Applies Holm over `checks` and marks each one passed or not.
pub(crate) fn correct(checks: &mut [Check], alpha: f64) {
    let p: Vec<f64> = checks.iter().map(|c| c.p_value.unwrap_or(1.0)).collect();
    for (c, a) in checks.iter_mut().zip(holm(&p)) {
        c.p_adjusted = Some(a);
        c.passed = a >= alpha;
    }
}

/// The failed checks, each attributed. Sensor: the fault tests reject on one or two gauges,
/// and once those faults — every rejected kind on those gauges, since a real gauge can drift
/// from an offset start (a linear drift from zero is an offset plus a centred drift) — are
/// fitted and removed (jointly, with the calibration) the other checks pass. Model form: one
/// fault kind with one sign on three or more gauges, gauges failing their leave-one-out
/// prediction on three or more gauges, or a build outside a declared tolerance. Otherwise
/// unexplained.
/// With a sensor attribution comes the joint fit of the suspected faults.
pub(crate) fn attribute(
    checks: &[Check],
    faults: &[SensorFault],
    rm: &ResidualModel,
    lay: &checks::Layout,
    alpha: f64,
) -> Result<(Vec<FailedCheck>, Option<SensorCorrection>)> {
    let failed: Vec<&Check> = checks.iter().filter(|c| !c.passed).collect();
    if failed.is_empty() {
        return Ok((Vec::new(), None));
    }
    let suspects = significant_faults(checks, faults);
    let gauges = distinct(suspects.iter().map(|f| f.gauge.clone()));
    let common = common_kind(&suspects);
    let logo_gauges = distinct(
        failed
            .iter()
            .filter(|c| c.check == "logo")
            .filter_map(|c| c.gauge.clone()),
    );
    let correction = if (1..=2).contains(&gauges.len()) && common.is_none() {
        let every = rejected_faults(checks, faults);
        let (correction, remaining) = joint_correction(&every, rm, lay, checks.len(), alpha)
            .or_else(|e| {
                // several kinds on one gauge can be collinear (an offset and a gain where the
                // fitted mean barely varies): then the most significant kind per gauge
                log::debug!("joint fit of every rejected fault failed ({e}); best per gauge");
                joint_correction(&suspects, rm, lay, checks.len(), alpha)
            })?;
        (remaining == 0).then_some(correction)
    } else {
        None
    };
    let accused = |g: &String| {
        correction
            .as_ref()
            .is_none_or(|c| c.faults.iter().any(|f| &f.gauge == g))
    };
    let attribution = if correction.is_some() {
        Attribution::Sensor
    } else if common.is_some()
        || logo_gauges.len() >= 3
        || failed.iter().any(|c| c.check == "build_tolerance")
    {
        Attribution::ModelForm
    } else {
        Attribution::Unexplained
    };
    let failed = failed
        .into_iter()
        .map(|c| FailedCheck {
            check: c.check.clone(),
            gauges: c.gauge.iter().cloned().collect(),
            // a build outside its declared tolerance is the model's, whatever else failed: no
            // sensor correction re-tests it
            attribution: match c.check.as_str() {
                "build_tolerance" => Attribution::ModelForm,
                _ => attribution,
            },
            detail: match (&c.gauge, &correction) {
                (Some(g), Some(corr)) if !accused(g) => format!(
                    "{}; not significant once {} is fitted jointly: a spill-over of that \
                     fault through the discrepancy, not this gauge's",
                    c.detail,
                    corr.describe()
                ),
                _ => c.detail.clone(),
            },
        })
        .collect();
    Ok((failed, correction))
}

fn distinct(it: impl Iterator<Item = String>) -> Vec<String> {
    let mut v: Vec<String> = it.collect();
    v.sort();
    v.dedup();
    v
}

/// Every fault whose test rejected.
fn rejected_faults<'a>(checks: &[Check], faults: &'a [SensorFault]) -> Vec<&'a SensorFault> {
    let rejected = |f: &SensorFault| {
        checks.iter().any(|c| {
            !c.passed && c.check == f.kind.check_name() && c.gauge.as_deref() == Some(&f.gauge)
        })
    };
    faults.iter().filter(|f| rejected(f)).collect()
}

/// The most significant rejected fault of each gauge.
fn significant_faults<'a>(checks: &[Check], faults: &'a [SensorFault]) -> Vec<&'a SensorFault> {
    let mut best: Vec<&SensorFault> = Vec::new();
    for f in rejected_faults(checks, faults) {
        match best.iter_mut().find(|b| b.gauge == f.gauge) {
            Some(b) if f.z.abs() > b.z.abs() => *b = f,
            Some(_) => {}
            None => best.push(f),
        }
    }
    best
}

/// A fault kind rejected with the same sign on three or more gauges (a common gain points to
/// the gate's stiffness, not to three sensors).
fn common_kind(suspects: &[&SensorFault]) -> Option<FaultKind> {
    [
        FaultKind::Offset,
        FaultKind::Gain,
        FaultKind::Drift,
        FaultKind::Step,
    ]
    .into_iter()
    .find(|&k| {
        let signs: Vec<bool> = suspects
            .iter()
            .filter(|f| f.kind == k)
            .map(|f| f.estimate > 0.0)
            .collect();
        signs.iter().filter(|&&s| s).count() >= 3 || signs.iter().filter(|&&s| !s).count() >= 3
    })
}

/// The suspected faults fitted jointly; a suspect not significant in the joint fit (at the
/// family's Bonferroni level) is exonerated — its own test rejected only because the
/// discrepancy spread another gauge's fault to it — and the rest are fitted again without
/// it. Returns the correction and how many prediction checks still reject after it.
fn joint_correction(
    suspects: &[&SensorFault],
    rm: &ResidualModel,
    lay: &checks::Layout,
    family_size: usize,
    alpha: f64,
) -> Result<(SensorCorrection, usize)> {
    let (all, remaining) = remaining_after_removal(suspects, rm, lay, family_size, alpha)?;
    let level = alpha / family_size as f64;
    let kept: Vec<&SensorFault> = suspects
        .iter()
        .zip(&all.faults)
        .filter(|(_, joint)| joint.p_value < level)
        .map(|(s, _)| *s)
        .collect();
    if kept.is_empty() || kept.len() == suspects.len() {
        return Ok((all, remaining));
    }
    remaining_after_removal(&kept, rm, lay, family_size, alpha)
}

/// The suspected faults fitted jointly, and how many of the prediction checks (each gauge,
/// the worst condition) still reject, at the family's Bonferroni level, once they are removed.
fn remaining_after_removal(
    suspects: &[&SensorFault],
    rm: &ResidualModel,
    lay: &checks::Layout,
    family_size: usize,
    alpha: f64,
) -> Result<(SensorCorrection, usize)> {
    let cols: Vec<DMatrix<f64>> = suspects
        .iter()
        .map(|f| {
            let g = lay.names.iter().position(|n| *n == f.gauge).unwrap_or(0);
            lay.signature(g, f.kind, f.at_fraction)
        })
        .collect();
    let h = DMatrix::from_columns(
        &cols
            .iter()
            .map(|c| c.column(0).into_owned())
            .collect::<Vec<_>>(),
    );
    let (beta, cov) = rm.gls(&h, "the suspected sensor faults fitted jointly")?;
    let cleaned = rm.with_removed(&h, &beta);
    let correction = correction(suspects, lay, &h, &beta, &cov);
    let level = alpha / family_size as f64;
    let logo = checks::leave_one_gauge_out(&cleaned, lay)?;
    let mut n = logo
        .iter()
        .filter(|g| g.p_value < level || g.ljung_box_p < level)
        .count();
    let x = DMatrix::zeros(lay.n_e, 0);
    if checks::worst_condition(&cleaned, lay, &x)?.p_value < level {
        n += 1;
    }
    Ok((correction, n))
}

/// The joint estimates as faults, and their signatures times the estimates as an
/// experiments x outputs matrix (the stacking is experiment-major).
fn correction(
    suspects: &[&SensorFault],
    lay: &checks::Layout,
    h: &DMatrix<f64>,
    beta: &nalgebra::DVector<f64>,
    cov: &DMatrix<f64>,
) -> SensorCorrection {
    let stacked = h * beta;
    let faults = suspects
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let sd = cov[(k, k)].max(0.0).sqrt();
            let z = beta[k] / sd;
            SensorFault {
                estimate: beta[k],
                sd,
                z,
                p_value: checks::normal_two_sided(z),
                ..(*f).clone()
            }
        })
        .collect();
    SensorCorrection {
        faults,
        shift: DMatrix::from_fn(lay.n_e, lay.n_o, |i, g| stacked[i * lay.n_o + g]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holm_matches_a_hand_computation() {
        // sorted 0.01, 0.02, 0.03, 0.5 times 4, 3, 2, 1 = 0.04, 0.06, 0.06, 0.5
        let a = holm(&[0.03, 0.5, 0.01, 0.02]);
        let want = [0.06, 0.5, 0.04, 0.06];
        for (x, w) in a.iter().zip(want) {
            assert!((x - w).abs() < 1e-12, "{a:?}");
        }
        // 0.8 x 2 caps at 1, and the next adjusted value cannot be smaller
        assert_eq!(holm(&[0.9, 0.8]), vec![1.0, 1.0]);
    }
}
