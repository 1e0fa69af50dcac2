//! `bamudi.calibrate` and `bamudi.Calibration`: BA-MUDI Modules 2-3 on a gate (the same
//! functions as `bamudi calibrate`), Module-4 predictions, save and load in the command
//! line's files (`calibration.json`, `model.json`).

use crate::gate::Gate;
use crate::progress::Callback;
use crate::{invalid, to_py};
use bamudi::data::Table;
use bamudi_gate::gate::SavedModel;
use bamudi_gate::session::{self, CalibrateSpec};
use mitergate::GateMultiLevel;
use mlmodel::{ObservableModel, UnobservableModel};
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Memoised contact solutions of a calibration's model (as `bamudi calibrate`).
const MEMO_CAPACITY: usize = 50_000;

/// A calibrated gate: the θ posterior, ρ*, σ_ε, the adequacy verdict, Module-4 predictions.
#[pyclass(module = "bamudi._native", frozen)]
pub struct Calibration {
    cal: bamudi::Calibration,
    saved: SavedModel,
    model: GateMultiLevel,
}

/// The spec from JSON (a dict) or TOML text; `label` names it in messages.
fn read_spec(json: Option<&str>, toml: Option<&str>, label: &str) -> PyResult<CalibrateSpec> {
    match (json, toml) {
        (Some(j), None) => CalibrateSpec::from_json_str(j, label).map_err(to_py),
        (None, Some(t)) => CalibrateSpec::from_toml_str(t, label).map_err(to_py),
        _ => Err(invalid("give the configuration once: a dict or TOML text")),
    }
}

/// The data array as the table the command line would read from a CSV file: `{:?}` prints
/// the shortest text that parses back to the same number, so the values are exact. Rows
/// are labelled by their line in that CSV (line 2 = row 0).
fn table_of(columns: &[String], data: &PyReadonlyArray2<'_, f64>, label: &str) -> PyResult<Table> {
    let a = data.as_array();
    if a.ncols() != columns.len() {
        return Err(invalid(format!(
            "{label}: {} columns named but the array has {}",
            columns.len(),
            a.ncols()
        )));
    }
    let mut text = columns.join(",");
    text.push('\n');
    for row in a.rows() {
        let cells: Vec<String> = row.iter().map(|v| format!("{v:?}")).collect();
        let _ = writeln!(text, "{}", cells.join(","));
    }
    Table::parse(&text, label).map_err(to_py)
}

/// Calibrates `gate` on experiments given as `columns` + `data` (`h_up`, `h_down` in inches
/// and one column per gauge in microstrain, any order); the configuration is a dict
/// (`config_json`, its JSON) or TOML text (`config_toml`) with the keys of the command line's
/// file; `seed` replaces its seed.
#[pyfunction]
#[pyo3(signature = (gate, columns, data, config_json=None, config_toml=None,
                    config_label="config".to_string(), data_label="data".to_string(),
                    seed=None, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn calibrate(
    py: Python<'_>,
    gate: &Gate,
    columns: Vec<String>,
    data: PyReadonlyArray2<'_, f64>,
    config_json: Option<String>,
    config_toml: Option<String>,
    config_label: String,
    data_label: String,
    seed: Option<u64>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Calibration> {
    let spec = read_spec(
        config_json.as_deref(),
        config_toml.as_deref(),
        &config_label,
    )?;
    let config = spec.config(seed).map_err(to_py)?;
    let table = table_of(&columns, &data, &data_label)?;
    let saved = spec
        .saved_model(&config_label, gate.config().cloned(), gate.contact.clone())
        .map_err(to_py)?;
    let observer = Callback::new(progress);
    let (cal, model) = py
        .detach(|| {
            let model = spec.calibration_model(&saved, MEMO_CAPACITY, &config_label)?;
            let exps = session::experiments_from_table(&table, &model)?;
            let cal = session::calibrate(&model, &exps, &config, &observer)?;
            Ok::<_, bamudi_gate::GateAppError>((cal, model))
        })
        .map_err(to_py)?;
    let warnings = session::posterior_warnings(&cal, saved.gap_prior);
    for w in session::warning_lines(&warnings, &format!("{config_label}: gap_prior")) {
        log::warn!("{w}");
    }
    Ok(Calibration { cal, saved, model })
}

#[pymethods]
impl Calibration {
    /// Posterior mean of the gap θ (in).
    #[getter]
    fn theta_mean(&self) -> f64 {
        self.cal.module3().posterior.mean()[0]
    }

    /// Posterior standard deviation of θ (in).
    #[getter]
    fn theta_sd(&self) -> f64 {
        self.cal.module3().posterior.sd()[0]
    }

    /// Central 95 % interval of θ (in).
    #[getter]
    fn theta_ci95(&self) -> (f64, f64) {
        self.cal.module3().posterior.ci95()[0]
    }

    /// The posterior probability that the data hold no discrepancy the model lacks, when the
    /// calibrations with and without one were weighed by their evidence (the default; the
    /// predictions mix the two with this weight, leaving the fit without one out below 1e-9);
    /// `None` otherwise.
    #[getter]
    fn probability_without(&self) -> Option<f64> {
        self.cal.module3().probability_without()
    }

    /// The Module-2 scale ρ* (Eq. 30).
    #[getter]
    fn rho_star(&self) -> f64 {
        self.cal.rho_star()
    }

    /// Measurement-noise sd σ_ε (microstrain).
    #[getter]
    fn sigma_eps(&self) -> f64 {
        self.cal.sigma_eps()
    }

    /// The gap prior `(lo, hi)` (in).
    #[getter]
    fn gap_prior(&self) -> (f64, f64) {
        self.saved.gap_prior
    }

    /// The gauges' names (the strain outputs, microstrain).
    #[getter]
    fn gauge_names(&self) -> Vec<String> {
        self.model.observable.output_names()
    }

    /// The points along the quoin (in above the sill) at which forces are predicted.
    #[getter]
    fn z_in<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.model.unobservable.coordinates().to_vec())
    }

    /// The adequacy report as JSON text (`None` when the checks were switched off); the
    /// Python layer turns it into a dict.
    fn adequacy_json(&self) -> PyResult<Option<String>> {
        self.cal
            .adequacy()
            .map(|a| serde_json::to_string(a).map_err(to_py))
            .transpose()
    }

    /// The declared build tolerances' posteriors as JSON text (`[]` when none were declared):
    /// each tolerance's name and the posterior mean and sd of its deviation, in its own
    /// standard deviations, as `results.json` (`tolerances`) holds them.
    fn tolerances_json(&self) -> PyResult<String> {
        let tolerances = self
            .cal
            .module3()
            .marginal()
            .map(|m| m.tolerances.clone())
            .unwrap_or_default();
        serde_json::to_string(&tolerances).map_err(to_py)
    }

    /// The posterior's warnings (mass piled at a prior bound, an interval narrower than three
    /// evaluated grid spacings), as the command line prints them and writes them into
    /// `results.json` (`inputs.warnings`); also logged when the calibration ends.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        let warnings = session::posterior_warnings(&self.cal, self.saved.gap_prior);
        session::warning_lines(&warnings, "gap_prior")
    }

    /// The adequacy verdict's one-line summary (`None` without checks).
    #[getter]
    fn adequacy_summary(&self) -> Option<String> {
        self.cal.adequacy().map(|a| a.summary())
    }

    /// Module 4 at the conditions `(h_up[i], h_down[i])` (in): strains (microstrain, per
    /// gauge) and normal and tangential quoin forces (lbf/in, per point), each with mean, sd
    /// and the 2.5 / 97.5 % band, as `(conditions, outputs)` float64 arrays.
    fn predict<'py>(
        &self,
        py: Python<'py>,
        h_up: PyReadonlyArray1<'_, f64>,
        h_down: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (hu, hd) = (h_up.as_array().to_vec(), h_down.as_array().to_vec());
        if hu.len() != hd.len() {
            return Err(invalid(format!(
                "h_up has {} values and h_down {}",
                hu.len(),
                hd.len()
            )));
        }
        let bands = py.detach(|| self.bands(&hu, &hd))?;
        let gauges = self.model.observable.output_names().len();
        bands_dict(
            py,
            bands,
            gauges,
            self.model.unobservable.coordinates().len(),
        )
    }

    /// Writes `calibration.json` and `model.json` (the files of `bamudi calibrate`, readable
    /// by `bamudi predict`) into the directory `dir` (created), each atomically.
    fn save(&self, py: Python<'_>, dir: PathBuf) -> PyResult<()> {
        py.detach(|| {
            std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
            self.cal
                .save(&dir.join("calibration.json"))
                .map_err(|e| e.to_string())?;
            self.saved
                .save(&dir.join("model.json"))
                .map_err(|e| e.to_string())
        })
        .map_err(invalid)
    }

    /// Reads a calibration saved by [`save`](Self::save) or by `bamudi calibrate`:
    /// `calibration.json`, and `model.json` beside it unless `model` is given.
    #[staticmethod]
    #[pyo3(signature = (calibration, model=None))]
    fn load(py: Python<'_>, calibration: PathBuf, model: Option<PathBuf>) -> PyResult<Self> {
        py.detach(|| load(&calibration, model.as_deref()))
    }

    /// Pickling (e.g. to return a calibration from a Dask worker): the JSON of
    /// `calibration.json` and `model.json`.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, (String, String))> {
        let me = slf.get();
        let cal = me.cal.to_json_string().map_err(to_py)?;
        let saved = serde_json::to_string(&me.saved).map_err(to_py)?;
        Ok((slf.get_type().getattr("_from_json")?, (cal, saved)))
    }

    /// The calibration of the JSON texts [`__reduce__`](Self::__reduce__) gives.
    #[staticmethod]
    fn _from_json(py: Python<'_>, calibration: &str, model: &str) -> PyResult<Self> {
        py.detach(|| {
            let cal = bamudi::Calibration::from_json_str(calibration, "pickled calibration")
                .map_err(to_py)?;
            let saved: SavedModel = serde_json::from_str(model).map_err(to_py)?;
            let model = saved.multilevel(0).map_err(to_py)?;
            Ok(Calibration { cal, saved, model })
        })
    }

    fn __repr__(&self) -> String {
        let (lo, hi) = self.theta_ci95();
        format!(
            "Calibration(theta {:.3} ± {:.3} in, 95 % [{lo:.3}, {hi:.3}], rho* {:.4}{})",
            self.theta_mean(),
            self.theta_sd(),
            self.rho_star(),
            self.adequacy_summary()
                .map_or(String::new(), |s| format!(", {s}"))
        )
    }
}

/// Strain and force bands at each condition.
type Bands = Vec<(bamudi::Band, bamudi::Band)>;

impl Calibration {
    fn bands(&self, hu: &[f64], hd: &[f64]) -> PyResult<Bands> {
        let predictor = self.cal.predictor(&self.model).map_err(to_py)?;
        hu.iter()
            .zip(hd)
            .map(|(&u, &d)| {
                let x = [u, d];
                let at = || format!("predicting at h_up = {u} in, h_down = {d} in");
                self.model
                    .unobservable
                    .check_input(&x)
                    .map_err(|e| invalid(format!("{}: {e}", at())))?;
                let strains = predictor
                    .outputs(&x)
                    .map_err(|e| invalid(format!("{}: {e}", at())))?;
                let forces = predictor
                    .response(&x)
                    .map_err(|e| invalid(format!("{}: {e}", at())))?;
                Ok((strains, forces))
            })
            .collect()
    }
}

/// The bands as `(conditions, outputs)` arrays: `strain_*` per gauge, `normal_*` and
/// `tangential_*` per quoin point (the force band is blocked `[normal; tangential]`).
fn bands_dict<'py>(
    py: Python<'py>,
    bands: Bands,
    gauges: usize,
    points: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let rows = bands.len();
    type Pick = fn(&bamudi::Band) -> &Vec<f64>;
    let stats: [(&str, Pick); 4] = [
        ("mean", |b| &b.mean),
        ("sd", |b| &b.sd),
        ("lower", |b| &b.lower),
        ("upper", |b| &b.upper),
    ];
    for (stat, pick) in stats {
        let strain = ndarray::Array2::from_shape_fn((rows, gauges), |(i, j)| pick(&bands[i].0)[j]);
        let normal = ndarray::Array2::from_shape_fn((rows, points), |(i, j)| pick(&bands[i].1)[j]);
        let tangential =
            ndarray::Array2::from_shape_fn((rows, points), |(i, j)| pick(&bands[i].1)[points + j]);
        d.set_item(format!("strain_{stat}"), strain.into_pyarray(py))?;
        d.set_item(format!("normal_{stat}"), normal.into_pyarray(py))?;
        d.set_item(format!("tangential_{stat}"), tangential.into_pyarray(py))?;
    }
    Ok(d)
}

fn load(calibration: &Path, model: Option<&Path>) -> PyResult<Calibration> {
    let cal = bamudi::Calibration::load(calibration).map_err(to_py)?;
    let model_path = model.map_or_else(
        || calibration.with_file_name("model.json"),
        Path::to_path_buf,
    );
    let saved = SavedModel::load(&model_path).map_err(to_py)?;
    let model = saved
        .multilevel(0)
        .map_err(|e| invalid(format!("the model in {}: {e}", model_path.display())))?;
    Ok(Calibration { cal, saved, model })
}
