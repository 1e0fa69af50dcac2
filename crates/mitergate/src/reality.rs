//! Realities: a truth that differs from the calibration's model by declared deviations.
//!
//! A calibration is only checked when its data come from something other than its own model.
//! A [`Reality`] says how the simulated truth departs from the gate the calibration uses (the
//! "drawing"):
//!
//! * **as built** — any gate-configuration field overridden (plate and web thicknesses, the
//!   steel's modulus, the geometry), and gauges moved or turned, named by gauge;
//! * **a finer (or coarser) mesh** for the truth;
//! * **the wall support** — the contact law's normal stiffness and tangential coefficient;
//! * **sensors** — per gauge a gain (`scale`), an `offset`, a linear `drift` over the data set
//!   and a `step` (a re-zeroing or a debond) from a given fraction of the rows on.
//!
//! The paper's discrepancy δ of a scenario still applies on top (it is part of the scenario, not
//! of the reality). Everything is deterministic: a reality adds no randomness.
//!
//! ```
//! use mitergate::{GateConfig, reality::Reality};
//! let r = Reality::from_toml_str(r#"
//! mesh_element_size_in = 18.0
//! [as_built.skin_plate]
//! thickness = 0.47
//! [as_built.gauges.SG3]
//! direction = [0.996, 0.087, 0.0]
//! [[sensors]]
//! gauge = "SG5"
//! scale = 1.04
//! step = { at_fraction = 0.7, size_microstrain = 12.0 }
//! "#).unwrap();
//! let drawing = GateConfig::default();
//! let truth = r.truth_gate(&drawing).unwrap();
//! assert_eq!(truth.skin_plate.thickness, 0.47);
//! assert_eq!(truth.mesh.element_size, 18.0);
//! assert_eq!(truth.gauges[2].direction, [0.996, 0.087, 0.0]);
//! assert_eq!(truth.girders, drawing.girders); // what is not named is the drawing's
//! // a gauge the gate does not have is an error naming it
//! let bad = Reality::from_toml_str("[[sensors]]\ngauge = \"SG9\"\nscale = 2.0\n").unwrap();
//! assert!(bad.check(&drawing).unwrap_err().to_string().contains("SG9"));
//! ```

use crate::contact::ContactParams;
use crate::error::GateError;
use crate::gate::GateConfig;
use serde::{Deserialize, Serialize};

/// How the truth departs from the calibration's gate (see the module docs).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Reality {
    /// Overrides of the gate configuration, as TOML tables mirroring
    /// [`GateConfig`]'s (`[as_built.material] youngs_modulus = 2.85e7`); gauges by name under
    /// `[as_built.gauges.<name>]` (`location`, `direction`).
    #[serde(default)]
    pub as_built: Option<toml::Table>,
    /// Element size of the truth's mesh (in); default: the drawing's.
    #[serde(default)]
    pub mesh_element_size_in: Option<f64>,
    /// The wall support of the truth (the contact law); default: the calibration's.
    #[serde(default)]
    pub support: Option<Support>,
    /// Per-gauge sensor behaviour.
    #[serde(default)]
    pub sensors: Vec<SensorFault>,
}

/// The contact law's stiffnesses (see [`ContactParams`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Support {
    /// Normal stiffness `k_N` (psi, lbf/in per inch of penetration).
    #[serde(default)]
    pub normal_stiffness_psi: Option<f64>,
    /// Tangential coefficient `k_T` (1/in).
    #[serde(default)]
    pub tangential_coefficient_per_in: Option<f64>,
}

/// One gauge's error: `reading = scale × strain + offset + drift × s + step(s)`, with
/// `s ∈ [0, 1]` the row's position in the data set (first row 0, last row 1; time for a field
/// record).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorFault {
    /// Gauge name.
    pub gauge: String,
    /// Gain (1: none).
    #[serde(default = "one")]
    pub scale: f64,
    /// Constant offset (microstrain).
    #[serde(default)]
    pub offset_microstrain: f64,
    /// Drift reached at the last row, linear from zero at the first (microstrain).
    #[serde(default)]
    pub drift_microstrain: f64,
    /// A step from a position in the data set on.
    #[serde(default)]
    pub step: Option<SensorStep>,
}

fn one() -> f64 {
    1.0
}

/// A step in a gauge's reading (a re-zeroing, a debond).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorStep {
    /// Where it starts: a fraction of the data set in `[0, 1]`.
    pub at_fraction: f64,
    /// Its size (microstrain).
    pub size_microstrain: f64,
}

fn field_error(key: &str, reason: impl Into<String>) -> GateError {
    GateError::GateField {
        key: key.to_string(),
        reason: reason.into(),
    }
}

fn invalid(key: impl Into<String>, reason: impl Into<String>) -> GateError {
    GateError::InvalidReality {
        key: key.into(),
        reason: reason.into(),
    }
}

impl Reality {
    /// Parses a reality (TOML). Unknown keys are errors; the gauges and the overridden
    /// configuration are checked against a gate by [`check`](Self::check).
    pub fn from_toml_str(text: &str) -> Result<Self, GateError> {
        let r: Self = toml::from_str(text).map_err(|e| invalid("(TOML)", e.to_string()))?;
        r.check_numbers()?;
        Ok(r)
    }

    /// Reads a reality file; errors name the file.
    pub fn from_file(path: &std::path::Path) -> Result<Self, GateError> {
        let text = std::fs::read_to_string(path).map_err(|source| GateError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml_str(&text).map_err(|e| match e {
            GateError::InvalidReality { key, reason } => {
                invalid(format!("{}: {key}", path.display()), reason)
            }
            other => other,
        })
    }

    fn check_numbers(&self) -> Result<(), GateError> {
        let max = crate::MAX_ELEMENT_SIZE_IN;
        if let Some(h) = self.mesh_element_size_in
            && !(h.is_finite() && h > 0.0 && h <= max)
        {
            return Err(invalid(
                "mesh_element_size_in",
                format!("must be in (0, {max}] in, got {h}"),
            ));
        }
        let reading = crate::MAX_GAUGE_READING_MICROSTRAIN;
        for (i, s) in self.sensors.iter().enumerate() {
            let key = |k: &str| format!("sensors[{i}] ({}).{k}", s.gauge);
            if !s.scale.is_finite() {
                return Err(invalid(
                    key("scale"),
                    format!("must be finite, got {}", s.scale),
                ));
            }
            // what a sensor adds is a gauge reading: the readings' own limit applies
            for (k, v) in [
                ("offset_microstrain", s.offset_microstrain),
                ("drift_microstrain", s.drift_microstrain),
            ] {
                if !(v.is_finite() && v.abs() <= reading) {
                    return Err(invalid(
                        key(k),
                        format!("must lie in [-{reading}, {reading}] microstrain, got {v}"),
                    ));
                }
            }
            if let Some(st) = s.step {
                if !(0.0..=1.0).contains(&st.at_fraction) {
                    return Err(invalid(
                        key("step.at_fraction"),
                        format!("must lie in [0, 1], got {}", st.at_fraction),
                    ));
                }
                if !(st.size_microstrain.is_finite() && st.size_microstrain.abs() <= reading) {
                    return Err(invalid(
                        key("step.size_microstrain"),
                        format!(
                            "must lie in [-{reading}, {reading}] microstrain, got {}",
                            st.size_microstrain
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Checks the reality against the calibration's gate: every sensor names one of its
    /// gauges (at most once), and the as-built gate is valid.
    pub fn check(&self, drawing: &GateConfig) -> Result<(), GateError> {
        for (i, s) in self.sensors.iter().enumerate() {
            if !drawing.gauges.iter().any(|g| g.name == s.gauge) {
                return Err(invalid(
                    format!("sensors[{i}].gauge"),
                    format!("the gate has no gauge {:?}", s.gauge),
                ));
            }
            if self.sensors[..i].iter().any(|o| o.gauge == s.gauge) {
                return Err(invalid(
                    format!("sensors[{i}].gauge"),
                    format!("{:?} is described twice", s.gauge),
                ));
            }
        }
        self.truth_gate(drawing).map(|_| ())
    }

    /// The truth's gate: the drawing with the as-built overrides and the truth's mesh.
    pub fn truth_gate(&self, drawing: &GateConfig) -> Result<GateConfig, GateError> {
        let mut value = toml::Value::try_from(drawing)
            .map_err(|e| invalid("as_built", format!("cannot represent the gate: {e}")))?;
        if let (Some(over), Some(base)) = (&self.as_built, value.as_table_mut()) {
            merge_gate(base, over)?;
        }
        let mut cfg: GateConfig = value
            .try_into()
            .map_err(|e: toml::de::Error| invalid("as_built", e.to_string()))?;
        if let Some(h) = self.mesh_element_size_in {
            cfg.mesh.element_size = h;
        }
        cfg.validate()
            .map_err(|e| invalid("as_built", format!("the as-built gate is invalid: {e}")))?;
        Ok(cfg)
    }

    /// The gate `drawing` with the numeric field at the dotted `key` (e.g.
    /// `skin_plate.thickness`, `material.youngs_modulus`) multiplied by `factor`: a build
    /// within a tolerance. Errors name the key: not a field, not a number, or an invalid gate.
    ///
    /// ```
    /// use mitergate::{GateConfig, reality::Reality};
    /// let drawing = GateConfig::default();
    /// let thin = Reality::scaled_field(&drawing, "skin_plate.thickness", 0.97).unwrap();
    /// assert!((thin.skin_plate.thickness - 0.97 * drawing.skin_plate.thickness).abs() < 1e-12);
    /// assert!(Reality::scaled_field(&drawing, "skin_plate.colour", 1.1).is_err());
    /// assert!(Reality::scaled_field(&drawing, "gauges", 1.1).is_err());
    /// ```
    pub fn scaled_field(
        drawing: &GateConfig,
        key: &str,
        factor: f64,
    ) -> Result<GateConfig, GateError> {
        let value = toml::Value::try_from(drawing)
            .map_err(|e| field_error(key, format!("cannot represent the gate: {e}")))?;
        let parts: Vec<&str> = key.split('.').collect();
        let mut at = &value;
        for p in &parts {
            at = at
                .get(p)
                .ok_or_else(|| field_error(key, "not a gate-configuration field"))?;
        }
        let nominal = match at {
            toml::Value::Float(v) => *v,
            toml::Value::Integer(v) => *v as f64,
            _ => {
                return Err(field_error(
                    key,
                    "not a number (only numeric fields can be scaled)",
                ));
            }
        };
        if !(factor.is_finite() && factor > 0.0) {
            return Err(field_error(
                key,
                format!("scale factor must be > 0, got {factor}"),
            ));
        }
        let mut over = toml::Value::Float(nominal * factor);
        for p in parts.iter().rev() {
            let mut t = toml::Table::new();
            t.insert((*p).to_string(), over);
            over = toml::Value::Table(t);
        }
        let as_built = match over {
            toml::Value::Table(t) => t,
            _ => return Err(field_error(key, "empty key")),
        };
        Reality {
            as_built: Some(as_built),
            ..Reality::default()
        }
        .truth_gate(drawing)
        .map_err(|e| {
            let reason = match e {
                GateError::InvalidReality { reason, .. } => reason,
                other => other.to_string(),
            };
            field_error(key, format!("at {factor} x the drawing: {reason}"))
        })
    }

    /// The truth's contact law: `base` with the support's stiffnesses.
    pub fn contact_params(&self, base: ContactParams) -> ContactParams {
        let Some(s) = self.support else { return base };
        let mut p = base;
        if let Some(k) = s.normal_stiffness_psi {
            p = p.normal_stiffness(k);
        }
        if let Some(k) = s.tangential_coefficient_per_in {
            p = p.tangential_coefficient(k);
        }
        p
    }

    /// Applies the sensor errors to row `position` (`s ∈ [0, 1]`) of readings in the order
    /// of `gauge_names` (microstrain; a missing reading stays missing).
    pub fn apply_sensors(
        &self,
        gauge_names: &[String],
        position: f64,
        readings: &mut [Option<f64>],
    ) {
        for s in &self.sensors {
            let Some(g) = gauge_names.iter().position(|n| *n == s.gauge) else {
                continue;
            };
            if let Some(v) = readings.get_mut(g).and_then(Option::as_mut) {
                let step = s
                    .step
                    .filter(|st| position >= st.at_fraction)
                    .map_or(0.0, |st| st.size_microstrain);
                *v = s.scale * *v + s.offset_microstrain + s.drift_microstrain * position + step;
            }
        }
    }

    /// Applies the sensor errors to every row of a field record, `s` being the row's time as
    /// a fraction of the record's span.
    pub fn apply_to_field(&self, rec: &mut crate::data::field::FieldRecord) {
        let (Some(&t0), Some(&t1)) = (rec.time_unix_s.first(), rec.time_unix_s.last()) else {
            return;
        };
        for (row, t) in rec.strains.iter_mut().zip(&rec.time_unix_s) {
            let position = (t - t0) as f64 / (t1 - t0).max(1) as f64;
            self.apply_sensors(&rec.gauge_names, position, row);
        }
    }

    /// Whether anything differs from the drawing.
    pub fn is_identity(&self) -> bool {
        *self == Self::default()
    }
}

/// Merges the overrides into the drawing's table: tables recursively, gauges by name, any
/// other value replaced (its type checked when the result is read back as a gate).
fn merge_gate(base: &mut toml::Table, over: &toml::Table) -> Result<(), GateError> {
    let mut rest = over.clone();
    if let Some(gauges) = rest.remove("gauges") {
        merge_gauges(base, &gauges)?;
    }
    merge_table(base, &rest, "as_built")
}

fn merge_table(base: &mut toml::Table, over: &toml::Table, path: &str) -> Result<(), GateError> {
    for (key, value) in over {
        let Some(slot) = base.get_mut(key) else {
            return Err(invalid(
                format!("{path}.{key}"),
                "not a gate-configuration field",
            ));
        };
        match (slot, value) {
            (toml::Value::Table(b), toml::Value::Table(o)) => {
                merge_table(b, o, &format!("{path}.{key}"))?
            }
            (slot, _) => *slot = value.clone(),
        }
    }
    Ok(())
}

/// `[as_built.gauges.<name>]` tables merged into the drawing's gauge of that name.
fn merge_gauges(base: &mut toml::Table, over: &toml::Value) -> Result<(), GateError> {
    let over = over
        .as_table()
        .ok_or_else(|| invalid("as_built.gauges", "must be tables named by gauge"))?;
    let gauges = base
        .get_mut("gauges")
        .and_then(toml::Value::as_array_mut)
        .ok_or_else(|| invalid("as_built.gauges", "the gate has no gauges"))?;
    for (name, spec) in over {
        let path = format!("as_built.gauges.{name}");
        let spec = spec
            .as_table()
            .ok_or_else(|| invalid(&path, "must be a table (location, direction)"))?;
        let gauge = gauges
            .iter_mut()
            .filter_map(toml::Value::as_table_mut)
            .find(|g| g.get("name").and_then(toml::Value::as_str) == Some(name))
            .ok_or_else(|| invalid(&path, format!("the gate has no gauge {name:?}")))?;
        if spec.contains_key("name") {
            return Err(invalid(format!("{path}.name"), "a gauge keeps its name"));
        }
        merge_table(gauge, spec, &path)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_fields_and_bad_numbers_are_named() {
        let cases = [
            ("mesh_element_size_in = -3.0\n", "mesh_element_size_in"),
            ("colour = 1\n", "colour"),
            ("[[sensors]]\ngauge = \"SG1\"\nscale = nan\n", "scale"),
            (
                "[[sensors]]\ngauge = \"SG1\"\nstep = { at_fraction = 1.5, size_microstrain = 1.0 }\n",
                "at_fraction",
            ),
        ];
        for (text, key) in cases {
            let e = Reality::from_toml_str(text).unwrap_err().to_string();
            assert!(e.contains(key), "{text}: {e}");
        }
        let drawing = GateConfig::default();
        for (text, key) in [
            (
                "[as_built.skin_plate]\nthicknes = 0.5\n",
                "as_built.skin_plate.thicknes",
            ),
            (
                "[as_built.skin_plate]\nthickness = -0.5\n",
                "skin_plate.thickness",
            ),
            ("[as_built.skin_plate]\nthickness = \"thin\"\n", "as_built"),
            (
                "[as_built.gauges.SG42]\ndirection = [0.0, 1.0, 0.0]\n",
                "SG42",
            ),
            ("[as_built.gauges.SG1]\nname = \"X\"\n", "name"),
            (
                "[[sensors]]\ngauge = \"SG1\"\n[[sensors]]\ngauge = \"SG1\"\n",
                "described twice",
            ),
        ] {
            let r = Reality::from_toml_str(text).unwrap();
            let e = r.check(&drawing).unwrap_err().to_string();
            assert!(e.contains(key), "{text}: {e}");
        }
    }

    #[test]
    fn sensors_follow_their_formula_and_leave_other_gauges_alone() {
        let r = Reality::from_toml_str(
            "[[sensors]]\ngauge = \"b\"\nscale = 1.1\noffset_microstrain = 2.0\n\
             drift_microstrain = 4.0\nstep = { at_fraction = 0.5, size_microstrain = -8.0 }\n",
        )
        .unwrap();
        let names: Vec<String> = ["a", "b", "c"].iter().map(|s| s.to_string()).collect();
        let mut early = [Some(10.0), Some(10.0), None];
        r.apply_sensors(&names, 0.25, &mut early);
        assert_eq!(early, [Some(10.0), Some(1.1 * 10.0 + 2.0 + 1.0), None]);
        let mut late = [Some(10.0), Some(10.0), None];
        r.apply_sensors(&names, 1.0, &mut late);
        assert_eq!(late[1], Some(1.1 * 10.0 + 2.0 + 4.0 - 8.0));
        let mut missing = [None, None, None];
        r.apply_sensors(&names, 1.0, &mut missing);
        assert_eq!(missing, [None, None, None]);
    }

    #[test]
    fn the_identity_reality_is_the_drawing() {
        let drawing = GateConfig::default();
        let r = Reality::from_toml_str("").unwrap();
        assert!(r.is_identity());
        assert_eq!(r.truth_gate(&drawing).unwrap(), drawing);
        let k = ContactParams::default();
        assert_eq!(r.contact_params(k.clone()), k);
        let s = Reality::from_toml_str("[support]\nnormal_stiffness_psi = 5e5\n").unwrap();
        assert_eq!(s.contact_params(k).k_normal(), 5e5);
    }
}
