//! Declared tolerances of the gate's build (`[[tolerances]]`): a numeric field of the gate
//! configuration known to a relative standard deviation, checked without and against the
//! drawing, and the gate's models rebuilt one standard deviation either side of it (the
//! marginal mode integrates them out).

use crate::error::{GateAppError, Result};
use mitergate::reality::Reality;
use mitergate::{ContactForceModel, GateConfig, StrainModel};
use mlmodel::{BuildTolerance, Memo};
use serde::{Deserialize, Serialize};

/// One declared tolerance of the gate's build: a numeric gate-configuration field (dotted
/// key, e.g. `skin_plate.thickness`) known to a relative standard deviation.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ToleranceSpec {
    /// The field's dotted key in the gate configuration.
    pub key: String,
    /// Its standard deviation relative to the drawing's value (in `(0, 0.5]`).
    pub relative_sd: f64,
}

/// Checks declared tolerances without a gate: every relative sd in `(0, 0.5]`, no key declared
/// twice, and the marginal coefficient `mode` (the only one that integrates them). Errors name
/// `label` and `tolerances[i]`.
pub fn check_tolerance_specs(
    specs: &[ToleranceSpec],
    mode: bamudi::ModeKind,
    label: &str,
) -> Result<()> {
    for (i, t) in specs.iter().enumerate() {
        if !(t.relative_sd.is_finite() && t.relative_sd > 0.0 && t.relative_sd <= 0.5) {
            return Err(GateAppError::Invalid(format!(
                "{label}: tolerances[{i}].relative_sd must lie in (0, 0.5], got {}",
                t.relative_sd
            )));
        }
    }
    if let Some((i, t)) = specs
        .iter()
        .enumerate()
        .find(|(i, t)| specs[..*i].iter().any(|o| o.key == t.key))
    {
        return Err(GateAppError::Invalid(format!(
            "{label}: tolerances[{i}].key {:?} is declared twice (its variance would count twice)",
            t.key
        )));
    }
    if !specs.is_empty() && mode != bamudi::ModeKind::Marginal {
        return Err(GateAppError::Invalid(format!(
            "{label}: `tolerances` are integrated only by the marginal mode; remove them or set \
             coefficients = \"marginal\" in [calibration]"
        )));
    }
    Ok(())
}

/// Checks every declared tolerance against the drawing `gate`: the key names a numeric field,
/// and the gate stays valid one standard deviation either side. Errors name `label` and
/// `tolerances[i].key` or `.relative_sd`.
pub fn check_tolerance_keys(specs: &[ToleranceSpec], gate: &GateConfig, label: &str) -> Result<()> {
    for (i, t) in specs.iter().enumerate() {
        // the drawing itself is valid: a failure at x 1 is the key's
        Reality::scaled_field(gate, &t.key, 1.0)
            .map_err(|e| GateAppError::Invalid(format!("{label}: tolerances[{i}].key: {e}")))?;
        for factor in [1.0 - t.relative_sd, 1.0 + t.relative_sd] {
            Reality::scaled_field(gate, &t.key, factor).map_err(|e| {
                GateAppError::Invalid(format!("{label}: tolerances[{i}].relative_sd: {e}"))
            })?;
        }
    }
    Ok(())
}

/// The gate's models (strains and contact forces) rebuilt at one standard deviation either
/// side of each declared tolerance of `drawing`; errors name `label`, the tolerance's index
/// and key.
pub fn build_tolerances(
    specs: &[ToleranceSpec],
    drawing: Option<&GateConfig>,
    label: &str,
) -> Result<Vec<BuildTolerance<Memo<ContactForceModel>, StrainModel>>> {
    let mut out = Vec::with_capacity(specs.len());
    for (i, t) in specs.iter().enumerate() {
        let Some(drawing) = drawing else {
            return Err(GateAppError::Invalid(format!(
                "{label}: tolerances[{i}] ({}): tolerances need a gate configuration, not an \
                 imported deck",
                t.key
            )));
        };
        let side = |factor: f64| -> Result<(Memo<ContactForceModel>, StrainModel)> {
            let cfg = Reality::scaled_field(drawing, &t.key, factor)
                .map_err(|e| GateAppError::Invalid(format!("{label}: tolerances[{i}].key: {e}")))?;
            let (contact, _) = mitergate::build_contact(&cfg).map_err(|e| {
                GateAppError::Invalid(format!(
                    "{label}: tolerances[{i}] ({}) at {factor} x the drawing: {e}",
                    t.key
                ))
            })?;
            let strain = StrainModel::new(contact.gate());
            // one solve per experiment and round at the posterior mode: no memo needed
            Ok((Memo::new(ContactForceModel::new(contact), 0), strain))
        };
        let ((u_lo, low), (u_hi, high)) = (side(1.0 - t.relative_sd)?, side(1.0 + t.relative_sd)?);
        out.push(BuildTolerance {
            name: t.key.clone(),
            low,
            high,
            responses: Some((u_lo, u_hi)),
        });
    }
    Ok(out)
}
