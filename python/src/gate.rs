//! `bamudi.Gate`: a gate (the embedded default, a gate TOML, or an imported `.inp` deck with
//! its import spec) with its built and condensed contact model.

use crate::to_py;
use bamudi_gate::session::GateSource;
use mitergate::{ContactModel, GateConfig};
use pyo3::prelude::*;
use std::path::PathBuf;

/// A miter gate and its contact model, built once (Module 1). Immutable and shareable
/// between threads; pickles as its source (TOML text, or the deck's paths) and is built
/// again on unpickling (the build is deterministic).
#[pyclass(module = "bamudi._native", frozen)]
pub struct Gate {
    pub(crate) source: GateSource,
    pub(crate) contact: ContactModel,
    pub(crate) label: String,
    n_dofs: usize,
    element_size: Option<f64>,
    build_seconds: f64,
}

#[pymethods]
impl Gate {
    /// Builds the gate of `path` (a gate TOML, every key of mitergate's default gate) or the
    /// embedded default, with `element_size` (in) overriding the mesh when given.
    #[new]
    #[pyo3(signature = (path=None, element_size=None))]
    fn new(py: Python<'_>, path: Option<PathBuf>, element_size: Option<f64>) -> PyResult<Self> {
        // the command line's reading of `--gate` / `--element-size`: the same checks
        let config = bamudi_gate::session::gate_config(
            path.as_deref(),
            element_size,
            ("gate", "element_size"),
        )
        .map_err(to_py)?;
        let label = path.map_or("embedded default gate".into(), |p| p.display().to_string());
        Self::build(py, GateSource::Config(config), label)
    }

    /// The gate of TOML text (the keys of a gate file); `label` names it in messages and in
    /// [`source`](Self::source).
    #[staticmethod]
    #[pyo3(signature = (text, label="gate TOML".to_string(), element_size=None))]
    fn from_toml(
        py: Python<'_>,
        text: &str,
        label: String,
        element_size: Option<f64>,
    ) -> PyResult<Self> {
        let config =
            GateConfig::from_toml_str(text).map_err(|e| crate::invalid(format!("{label}: {e}")))?;
        Self::configured(py, config, label, element_size)
    }

    /// Your own gate: a finite-element deck (Abaqus / CalculiX `.inp`) and its import spec
    /// (TOML: where the quoin, the wetted skin and the gauges are; `docs/mitergate.md`).
    #[staticmethod]
    fn from_inp(py: Python<'_>, inp: PathBuf, spec: PathBuf) -> PyResult<Self> {
        let label = format!("{} (import spec {})", inp.display(), spec.display());
        Self::build(py, GateSource::Deck { inp, spec }, label)
    }

    /// Writes the gate as a finite-element deck `inp` with its import spec `spec` (default:
    /// beside it, `<name>.spec.toml`), each atomically: a starting point for a deck of your
    /// own gate, read back by [`from_inp`](Self::from_inp) (as `bamudi export-gate`).
    #[pyo3(signature = (inp, spec=None))]
    fn export_inp(&self, py: Python<'_>, inp: PathBuf, spec: Option<PathBuf>) -> PyResult<()> {
        let cfg = self.config().ok_or_else(|| {
            crate::invalid(
                "export_inp writes a gate configuration as a deck; this gate is a deck already",
            )
        })?;
        let spec = spec.unwrap_or_else(|| inp.with_extension("spec.toml"));
        py.detach(|| {
            let (deck, text) = bamudi_gate::session::export_deck(cfg).map_err(to_py)?;
            bamudi::data::write_atomic(&inp, deck.as_bytes()).map_err(to_py)?;
            bamudi::data::write_atomic(&spec, text.as_bytes()).map_err(to_py)
        })
    }

    /// Pickling (e.g. to send a gate to Dask workers): a configured gate as its TOML, a deck
    /// as its two paths (which the unpickling process must be able to read).
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, (String, String))> {
        let me = slf.get();
        let ty = slf.get_type();
        match &me.source {
            GateSource::Config(cfg) => {
                let text = cfg.to_toml_string().map_err(to_py)?;
                Ok((ty.getattr("from_toml")?, (text, me.label.clone())))
            }
            GateSource::Deck { inp, spec } => Ok((
                ty.getattr("from_inp")?,
                (inp.display().to_string(), spec.display().to_string()),
            )),
        }
    }

    /// The gauges' names (the strain columns, microstrain).
    #[getter]
    fn gauge_names(&self) -> Vec<String> {
        self.contact.gate().gauge_names.clone()
    }

    /// Degrees of freedom of the finite-element model.
    #[getter]
    fn n_dofs(&self) -> usize {
        self.n_dofs
    }

    /// Mesh element size (in); `None` for a deck (its own mesh).
    #[getter]
    fn element_size(&self) -> Option<f64> {
        self.element_size
    }

    /// Height of the quoin (in): gaps live in `[0, quoin_height)`.
    #[getter]
    fn quoin_height(&self) -> f64 {
        self.contact.gate().quoin_height
    }

    /// Seconds the build and condensation took.
    #[getter]
    fn build_seconds(&self) -> f64 {
        self.build_seconds
    }

    /// Where the gate came from (a file, a deck and its spec, or `embedded default gate`).
    #[getter]
    fn source(&self) -> String {
        self.label.clone()
    }

    fn __repr__(&self) -> String {
        let mesh = self
            .element_size
            .map_or("its own mesh".into(), |h| format!("element size {h} in"));
        format!(
            "Gate({}, {} dofs, {mesh}, {} gauges)",
            self.label,
            self.n_dofs,
            self.contact.gate().gauge_names.len()
        )
    }
}

impl Gate {
    /// The configuration, when the gate was built from one (`None` for a deck).
    pub(crate) fn config(&self) -> Option<&GateConfig> {
        match &self.source {
            GateSource::Config(cfg) => Some(cfg),
            GateSource::Deck { .. } => None,
        }
    }

    /// Builds a configured gate with the mesh override.
    fn configured(
        py: Python<'_>,
        mut config: GateConfig,
        label: String,
        element_size: Option<f64>,
    ) -> PyResult<Self> {
        if let Some(h) = element_size {
            let max = mitergate::MAX_ELEMENT_SIZE_IN;
            if !(h.is_finite() && h > 0.0 && h <= max) {
                return Err(crate::invalid(format!(
                    "element_size must be in (0, {max}] in, got {h}"
                )));
            }
            config.mesh.element_size = h;
            config
                .validate()
                .map_err(|e| crate::invalid(format!("element_size: {e}")))?;
        }
        Self::build(py, GateSource::Config(config), label)
    }

    /// Builds and condenses the gate of `source` (without the GIL).
    fn build(py: Python<'_>, source: GateSource, label: String) -> PyResult<Self> {
        let built = py.detach(|| source.build()).map_err(to_py)?;
        log::info!(
            "gate: {} dofs, built and condensed in {:.1} s",
            built.n_dofs,
            built.seconds
        );
        Ok(Self {
            source,
            contact: built.contact,
            label,
            n_dofs: built.n_dofs,
            element_size: built.element_size,
            build_seconds: built.seconds,
        })
    }
}
