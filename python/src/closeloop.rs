//! `bamudi.close_loop`: the close-the-loop workflow on a field record with the gate's
//! BA-MUDI calibrator (the same functions as `bamudi close-loop`); the report is the
//! command line's `results.json`, as JSON text the Python layer turns into a dict.

use crate::gate::Gate;
use crate::progress::Callback;
use crate::{invalid, to_py};
use bamudi::observe::Observer;
use bamudi_closeloop::{CloseLoopConfig, MissingPolicy, close_loop as run_loop};
use bamudi_gate::gate;
use bamudi_gate::session;
use bamudi_gate::tolerance::ToleranceSpec;
use pyo3::prelude::*;
use std::sync::Arc;

/// Runs the loop on the record `csv` (the text of a field CSV: `time`, `h_up`, `h_down`,
/// gauges, covariates; `label` names it in messages) or the record file `path` (read and
/// checked as `bamudi close-loop --data` reads it). Settings as on the command line:
/// `config_toml` (a close-loop configuration), `holdout_fraction`, `test_fraction`,
/// `impute`, `gap_prior` (in), `max_experiments`, `gauge_noise_sd` (microstrain),
/// `calibration_toml` (the `[calibration]` keys), `seed`; `tolerances_json`, the declared
/// build tolerances (`[{"key", "relative_sd"}]`, as `--tolerances`).
#[pyfunction]
#[pyo3(signature = (gate, csv=None, label="record".to_string(), gap_prior=(40.0, 200.0),
                    max_experiments=240, gauge_noise_sd=None, config_toml=None,
                    calibration_toml=None, holdout_fraction=None, test_fraction=None,
                    impute=false, seed=None, progress=None, tolerances_json=None, path=None))]
#[allow(clippy::too_many_arguments)]
pub fn close_loop(
    py: Python<'_>,
    gate: &Gate,
    csv: Option<String>,
    label: String,
    gap_prior: (f64, f64),
    max_experiments: usize,
    gauge_noise_sd: Option<f64>,
    config_toml: Option<String>,
    calibration_toml: Option<String>,
    holdout_fraction: Option<f64>,
    test_fraction: Option<f64>,
    impute: bool,
    seed: Option<u64>,
    progress: Option<Py<PyAny>>,
    tolerances_json: Option<String>,
    path: Option<std::path::PathBuf>,
) -> PyResult<String> {
    let (lo, hi) = gap_prior;
    let source = match (csv, path) {
        (Some(text), None) => Record::Text(text),
        (None, Some(p)) => {
            session::check_input_file("record", &p).map_err(to_py)?;
            Record::File(p)
        }
        _ => return Err(invalid("give the record once: its CSV text or its path")),
    };
    let top = gate.contact.gate().quoin_height;
    if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && lo < hi && hi < top) {
        return Err(invalid(format!(
            "gap_prior must be (lo, hi) with 0 <= lo < hi < {top} (the quoin height, in), got \
             ({lo}, {hi})"
        )));
    }
    if !(10..=100_000).contains(&max_experiments) {
        return Err(invalid(format!(
            "max_experiments must be in [10, 100000], got {max_experiments}"
        )));
    }
    let cfg = loop_config(config_toml.as_deref(), holdout_fraction, test_fraction)?;
    let cal_cfg = calibration_toml
        .map(|t| bamudi::CalibrationConfig::from_toml_str(&t))
        .transpose()
        .map_err(|e| invalid(format!("calibration_toml: {e}")))?;
    let tolerances: Vec<ToleranceSpec> = match &tolerances_json {
        Some(t) => serde_json::from_str(t).map_err(|e| invalid(format!("tolerances: {e}")))?,
        None => Vec::new(),
    };
    if !tolerances.is_empty() && gate.config().is_none() {
        return Err(invalid(
            "tolerances need a gate configuration, not an imported deck",
        ));
    }
    let observer: Arc<dyn Observer + Send + Sync> = Arc::new(Callback::new(progress));
    let (contact, drawing) = (gate.contact.clone(), gate.config().cloned());
    py.detach(|| {
        let mut calibrator = bamudi_gate::session::gate_calibrator(
            contact,
            (lo, hi),
            max_experiments,
            gauge_noise_sd,
            cal_cfg,
            seed,
        )?;
        if let Some(drawing) = drawing.as_ref().filter(|_| !tolerances.is_empty()) {
            calibrator = calibrator.tolerances(&tolerances, drawing)?;
        }
        let calibrator = calibrator.observer(observer);
        let model = calibrator.model();
        let mut ingest = gate::ingest_config(model);
        if impute {
            ingest.missing = MissingPolicy::Interpolate;
        }
        let rec = match &source {
            Record::Text(text) => session::parse_record(text, &label, model, &ingest)?,
            Record::File(p) => session::read_record(p, model, &ingest)?,
        };
        let cfg = gate::close_loop_config(cfg, &rec);
        let out = run_loop(&rec, &calibrator, &cfg)?;
        let warnings = session::close_loop_warnings(&out, &format!("gap_prior ({lo}, {hi})"));
        for w in &warnings {
            log::warn!("{w}");
        }
        bamudi_gate::report::closeloop::results_json(&out, None, &warnings, "the close-loop report")
    })
    .map_err(to_py)
}

/// Where the record comes from.
enum Record {
    /// CSV text (labelled by `label`).
    Text(String),
    /// A CSV file.
    File(std::path::PathBuf),
}

/// The loop's settings: the configuration text (or the defaults) with the overrides.
fn loop_config(
    toml_text: Option<&str>,
    holdout_fraction: Option<f64>,
    test_fraction: Option<f64>,
) -> PyResult<CloseLoopConfig> {
    let mut cfg = match toml_text {
        Some(t) => bamudi_gate::session::close_loop_config_from_toml(t).map_err(to_py)?,
        None => CloseLoopConfig::default(),
    };
    if let Some(h) = holdout_fraction {
        if !(h.is_finite() && h > 0.0 && h < 1.0) {
            return Err(invalid(format!(
                "holdout_fraction must be in (0, 1), got {h}"
            )));
        }
        cfg = cfg.calibration_fraction(1.0 - h);
    }
    if let Some(t) = test_fraction {
        cfg = cfg.test_fraction(t);
    }
    cfg.validate().map_err(to_py)?;
    Ok(cfg)
}
