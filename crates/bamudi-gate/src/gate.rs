//! The gate as the engine sees it: its multi-level model, the file that lets `predict` rebuild
//! exactly the calibrated model, and the gate's record layout for the close loop.

use crate::error::{GateAppError, Result};
use crate::tolerance::{ToleranceSpec, build_tolerances};
use bamudi_closeloop::{CloseLoopConfig, IngestConfig, LoadSpec, MeasuredRecord};
use mitergate::data::field::{FieldConfig, FieldRecord, simulate};
use mitergate::{ContactModel, GateConfig, GateMultiLevel, GateSummary, MultiLevelSpec};
use mlmodel::{ObservableModel, UnobservableModel};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The unit of the gate's outputs.
pub const GAUGE_UNIT: &str = "microstrain";

/// Most model rows (`A g` and `b` at one `(x, θ)`, [`mlmodel::RowMemo`]) the application's
/// models remember: a row of the 7 gauges takes about 260 bytes with its key and hash-table
/// slot, so a full memo holds about 260 MB, where as many remembered contact solves (8 kB each
/// at 509 points) would take 8 GB. Module 3's rows and Module 4's output moments read the
/// contact solves through these rows (Module 4's force predictions and Module 2's prior-node
/// contexts read the forces themselves), so the rows a calibration meets again (another
/// coefficient mode on the same experiments and `θ` nodes, a close loop's recalibrations on
/// overlapping windows, predictions at support points met before) are not solved again. Every
/// model built by [`SavedModel::multilevel`] has this memo (it costs nothing until rows are
/// read).
pub const ROW_MEMO_CAPACITY: usize = 1_000_000;

/// Builds and condenses the gate of `cfg` (Module 1) with its contact model, timed.
pub fn build(cfg: &GateConfig) -> Result<(ContactModel, GateSummary, f64)> {
    let start = std::time::Instant::now();
    let (contact, summary) = mitergate::build_contact(cfg)?;
    Ok((contact, summary, start.elapsed().as_secs_f64()))
}

/// The calibrated model's definition, saved as `model.json` beside `calibration.json` so that
/// `predict` uses exactly the same gate, prior and discrepancy basis without rebuilding the
/// gate (the declared tolerances' ± models are rebuilt from the stored configuration).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SavedModel {
    /// The gate configuration the contact model was built from (`None` for an imported
    /// deck: the contact model holds everything a prediction needs).
    pub gate: Option<GateConfig>,
    /// The condensed gate with its contact parameters.
    pub contact: ContactModel,
    /// Uniform prior of the gap θ (in).
    pub gap_prior: (f64, f64),
    /// Legendre terms of the discrepancy (normal, tangential).
    pub discrepancy_terms: [usize; 2],
    /// The declared tolerances of the gate's build the calibration integrated (none in files
    /// written before they were saved).
    #[serde(default)]
    pub tolerances: Vec<ToleranceSpec>,
}

impl SavedModel {
    /// Writes the JSON file atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string(self).map_err(|e| GateAppError::Serde {
            context: path.display().to_string(),
            reason: e.to_string(),
        })?;
        Ok(bamudi::data::write_atomic(path, text.as_bytes())?)
    }

    /// Reads the JSON file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| GateAppError::Io {
            path: path.display().to_string(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|e| GateAppError::Serde {
            context: path.display().to_string(),
            reason: e.to_string(),
        })
    }

    /// The multi-level model (contact forces memoised, `memo_capacity` entries; model rows,
    /// [`ROW_MEMO_CAPACITY`]) with the
    /// declared tolerances the calibration integrated, rebuilt one sd either side, so that
    /// Module 4 predicts with them.
    pub fn multilevel(&self, memo_capacity: usize) -> Result<GateMultiLevel> {
        self.multilevel_with(memo_capacity, &self.tolerances, "the saved model")
    }

    /// As [`multilevel`](Self::multilevel), with the tolerances `specs` (errors name `label`).
    pub(crate) fn multilevel_with(
        &self,
        memo_capacity: usize,
        specs: &[ToleranceSpec],
        label: &str,
    ) -> Result<GateMultiLevel> {
        let spec = MultiLevelSpec {
            gap_prior_in: self.gap_prior,
            discrepancy_terms: self.discrepancy_terms,
            memo_capacity,
            row_memo_capacity: ROW_MEMO_CAPACITY,
        };
        let model = mitergate::multilevel(self.contact.clone(), &spec)?;
        if specs.is_empty() {
            return Ok(model);
        }
        let tolerances = build_tolerances(specs, self.gate.as_ref(), label)?;
        model
            .with_tolerances(tolerances)
            .map_err(|e| GateAppError::Invalid(format!("{label}: `tolerances`: {e}")))
    }
}

/// How a gate's field record is read: `time`, `h_up`, `h_down` (in) and the gauges.
pub fn ingest_config(model: &GateMultiLevel) -> IngestConfig {
    let gauges = model.observable.output_names();
    let gauges: Vec<&str> = gauges.iter().map(String::as_str).collect();
    IngestConfig::new(&["h_up", "h_down"], &gauges)
}

/// The truth's contact model of a reality: the as-built gate (with the truth's mesh) built
/// and condensed, with the reality's wall support; the reality is checked against `drawing`
/// first.
pub fn build_truth(
    reality: &mitergate::reality::Reality,
    drawing: &GateConfig,
) -> Result<ContactModel> {
    reality.check(drawing)?;
    let (built, _, _) = build(&reality.truth_gate(drawing)?)?;
    let params = reality.contact_params(built.params().clone());
    Ok(ContactModel::new(built.gate().clone(), params)?)
}

/// Checks every row's levels against the gate's input domain.
pub fn check_record(rec: &MeasuredRecord, model: &GateMultiLevel) -> Result<()> {
    let u = &model.unobservable;
    Ok(rec.check_inputs(|x| u.check_input(x).map_err(|e| e.to_string()))?)
}

/// The close loop on a gate record: the head `h_up − h_down` as the load (the gate is open
/// below [`mitergate::MIN_HEAD_IN`]), the gap as the parameter, strains in microstrain, and
/// the field layout's column units ([`declare_field_units`]).
pub fn close_loop_config(base: CloseLoopConfig, rec: &MeasuredRecord) -> CloseLoopConfig {
    let base = declare_field_units(base, rec);
    base.load(LoadSpec::difference(
        "head",
        0,
        1,
        2,
        mitergate::MIN_HEAD_IN,
    ))
    .parameter_name("gap")
    .output_unit(GAUGE_UNIT)
}

/// `cfg` with the units of the field layout's covariates
/// ([`COVARIATE_UNITS`](mitergate::data::field::COVARIATE_UNITS)) declared for those `rec`
/// has and `cfg` does not declare itself.
pub fn declare_field_units(cfg: CloseLoopConfig, rec: &MeasuredRecord) -> CloseLoopConfig {
    let mut cfg = cfg;
    for (column, unit) in mitergate::data::field::COVARIATE_UNITS {
        if rec.covariate_names.iter().any(|c| c == column) && !cfg.column_units.contains_key(column)
        {
            cfg = cfg.column_unit(column, unit);
        }
    }
    cfg
}

/// Simulates a field record with the gate of `contact` as the TRUE strain function
/// `A g_BC(h_up, h_down, gap) + s_w(h_up, h_down)`; the gauge columns carry the gate's gauge
/// names. A failed contact solve is an error naming the levels and the gap.
pub fn simulate_field(cfg: &FieldConfig, contact: &ContactModel) -> Result<FieldRecord> {
    let failure = std::sync::Mutex::new(None::<String>);
    let truth = |hu: f64, hd: f64, gap: f64| -> Vec<f64> {
        match contact.solve(hu, hd, gap) {
            Ok(sol) => contact
                .gate()
                .strain(&sol.forces, hu, hd)
                .as_slice()
                .to_vec(),
            Err(e) => {
                if let Ok(mut f) = failure.lock() {
                    f.get_or_insert(format!(
                        "contact solve at h_up = {hu} in, h_down = {hd} in, gap = {gap} in: {e}"
                    ));
                }
                Vec::new() // makes `simulate` stop with a length error
            }
        }
    };
    let mut rec = match simulate(cfg, &truth) {
        Ok(r) => r,
        Err(e) => {
            let why = failure.lock().ok().and_then(|f| f.clone());
            return Err(why.map_or(GateAppError::Gate(e), GateAppError::Simulation));
        }
    };
    rec.gauge_names = contact.gate().gauge_names.clone();
    Ok(rec)
}

/// A simulated field record read back exactly as a measured one would be (from its CSV text,
/// labelled `label`), checked against the gate's input domain.
pub fn as_measured(
    rec: &FieldRecord,
    model: &GateMultiLevel,
    label: &str,
) -> Result<MeasuredRecord> {
    let data = bamudi_closeloop::parse_csv(&rec.to_csv_string(), label, &ingest_config(model))?;
    check_record(&data, model)?;
    Ok(data)
}
