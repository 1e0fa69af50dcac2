//! `bamudi.calibrate(model, ...)` for a user's [`Model`]: Modules 2-3 through the engine
//! (`bamudi::Calibrate`, the same code as the gate's), Module-4 predictions, posterior draws,
//! save and load, and the coverage study of a user's model.

use crate::model::{Model, ModelDescription, ModelSpec, RunState, call_outputs, to_matrix};
use crate::progress::Callback;
use crate::{invalid, to_py};
use bamudi::posterior::ThetaPosterior;
use bamudi::validation::{Coverage, RankHistogram, binomial_acceptance};
use bamudi::{Calibrate, CalibrationConfig, CalibrationParams, Experiments};
use mlmodel::{LinearObservableModel, PredictionModel};
use nalgebra::DMatrix;
use numerics::random::{derive_seed, standard_normal};
use numpy::{IntoPyArray, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rand::{RngExt, SeedableRng, rngs::StdRng};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The checked engine configuration from a dict (JSON) or TOML text, or the engine's
/// defaults; `seed` replaces its seed. Every key of `bamudi::CalibrationParams` is accepted,
/// so keys the engine gains flow through; an unknown key is an error naming it.
fn read_config(
    json: Option<&str>,
    toml: Option<&str>,
    label: &str,
    seed: Option<u64>,
) -> PyResult<CalibrationConfig> {
    let mut params: CalibrationParams = match (json, toml) {
        (Some(j), None) => serde_json::from_str(j).map_err(|e| invalid(format!("{label}: {e}")))?,
        (None, Some(t)) => CalibrationConfig::from_toml_str(t)
            .map_err(|e| invalid(format!("{label}: {e}")))?
            .into_params(),
        (None, None) => CalibrationParams::default(),
        _ => return Err(invalid("give the configuration once: a dict or TOML text")),
    };
    if let Some(s) = seed {
        params.seed = s;
    }
    params.check().map_err(|e| invalid(format!("{label}: {e}")))
}

/// `x` and `y` as matrices after checking their shapes against the model and their values;
/// messages name the argument, the row and the column.
fn experiments(
    desc: &ModelDescription,
    x: &PyReadonlyArray2<'_, f64>,
    y: &PyReadonlyArray2<'_, f64>,
) -> PyResult<Experiments> {
    let (xa, ya) = (x.as_array(), y.as_array());
    let (d, n_o) = (desc.inputs.len(), desc.outputs.len());
    if xa.ncols() != d {
        return Err(invalid(format!(
            "x has shape ({}, {}); expected (experiments, inputs) = (n, {d}) for inputs {:?}",
            xa.nrows(),
            xa.ncols(),
            desc.inputs
        )));
    }
    if ya.shape() != [xa.nrows(), n_o] {
        return Err(invalid(format!(
            "y has shape ({}, {}); expected (experiments, outputs) = ({}, {n_o}) for outputs {:?}",
            ya.nrows(),
            ya.ncols(),
            xa.nrows(),
            desc.outputs
        )));
    }
    for (what, arr, names) in [("x", &xa, &desc.inputs), ("y", &ya, &desc.outputs)] {
        if let Some(((i, j), v)) = arr.indexed_iter().find(|(_, v)| !v.is_finite()) {
            return Err(invalid(format!(
                "{what}[{i}, {j}] (row {i}, column `{}`) is {v}",
                names[j]
            )));
        }
    }
    Experiments::new(
        desc.inputs.clone(),
        desc.outputs.clone(),
        to_matrix(&xa),
        to_matrix(&ya),
    )
    .map_err(to_py)
}

/// The grid posterior's warnings per dimension (mass at a bound of a uniform prior, an
/// under-resolved interval), as lines naming the parameter.
fn posterior_warnings(cal: &bamudi::Calibration, desc: &ModelDescription) -> Vec<String> {
    let ThetaPosterior::Grid(g) = &cal.module3().posterior else {
        return vec![];
    };
    let name = &desc.parameters[0];
    // a normal prior has no bound to press against: only the resolution is judged
    let bounds = desc
        .prior
        .uniform_bounds(0)
        .unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
    g.warnings(bounds)
        .iter()
        .map(|w| format!("prior of `{name}`: {w}"))
        .collect()
}

/// A calibration of a user's model: θ's posterior, ρ, σ_ε, the adequacy verdict, Module-4
/// predictions and posterior draws.
#[pyclass(module = "bamudi._native", frozen)]
pub struct ModelCalibration {
    cal: bamudi::Calibration,
    desc: ModelDescription,
    /// The model's callables (none for a calibration loaded without its model).
    spec: Option<Arc<ModelSpec>>,
    /// The measured outputs (none for a loaded calibration).
    y: Option<DMatrix<f64>>,
}

/// Calibrates `model` on the experiments `x` (`n x inputs`) and `y` (`n x outputs`); the
/// engine's configuration is a dict (`config_json`, its JSON) or TOML text (`config_toml`)
/// with the keys of `bamudi::CalibrationParams` (none: the engine's defaults); `seed` replaces
/// its seed.
#[pyfunction]
#[pyo3(signature = (model, x, y, config_json=None, config_toml=None,
                    config_label="config".to_string(), seed=None, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn calibrate_model(
    py: Python<'_>,
    model: &Model,
    x: PyReadonlyArray2<'_, f64>,
    y: PyReadonlyArray2<'_, f64>,
    config_json: Option<String>,
    config_toml: Option<String>,
    config_label: String,
    seed: Option<u64>,
    progress: Option<Py<PyAny>>,
) -> PyResult<ModelCalibration> {
    let config = read_config(
        config_json.as_deref(),
        config_toml.as_deref(),
        &config_label,
        seed,
    )?;
    let exps = experiments(&model.spec.desc, &x, &y)?;
    let (cal, y) = run(py, &model.spec, exps, &config, progress)?;
    let me = ModelCalibration {
        cal,
        desc: model.spec.desc.clone(),
        spec: Some(model.spec.clone()),
        y: Some(y),
    };
    for w in posterior_warnings(&me.cal, &me.desc) {
        log::warn!("{w}");
    }
    Ok(me)
}

/// Modules 2-3 on `exps` with the GIL released; a callback's failure is raised as itself.
fn run(
    py: Python<'_>,
    spec: &ModelSpec,
    exps: Experiments,
    config: &CalibrationConfig,
    progress: Option<Py<PyAny>>,
) -> PyResult<(bamudi::Calibration, DMatrix<f64>)> {
    let (model, state) = spec.instantiate(Some(&exps.x))?;
    let observer = Callback::new(progress);
    let cal = py
        .detach(|| {
            Calibrate::new(config)
                .observer(&observer)
                .run(&model, &exps)
        })
        .map_err(|e| state.error(py, e))?;
    Ok((cal, exps.y))
}

/// The rows of `x` as inputs, checked against the model's input count.
fn rows_of(desc: &ModelDescription, x: &PyReadonlyArray2<'_, f64>) -> PyResult<DMatrix<f64>> {
    let a = x.as_array();
    let d = desc.inputs.len();
    if a.ncols() != d {
        return Err(invalid(format!(
            "x has shape ({}, {}); expected (conditions, inputs) = (n, {d}) for inputs {:?}",
            a.nrows(),
            a.ncols(),
            desc.inputs
        )));
    }
    if let Some(((i, j), v)) = a.indexed_iter().find(|(_, v)| !v.is_finite()) {
        return Err(invalid(format!("x[{i}, {j}] is {v}")));
    }
    Ok(to_matrix(&a))
}

/// A prediction model `g_p` (Eq. 8) as a Python callable `f(x, theta, response) -> values`
/// (`response` of shape `(components, points)`).
struct PyPrediction {
    names: Vec<String>,
    func: Py<PyAny>,
    shape: (usize, usize),
    state: Arc<RunState>,
}

impl PredictionModel for PyPrediction {
    fn output_names(&self) -> Vec<String> {
        self.names.clone()
    }
    fn evaluate(
        &self,
        x: &[f64],
        theta: &[f64],
        y_u: &[f64],
        out: &mut [f64],
    ) -> mlmodel::Result<()> {
        let n = self.names.len();
        let at = format!("x = {x:?}, theta = {theta:?}");
        let r = Python::attach(|py| -> Result<Vec<f64>, (String, Option<PyErr>)> {
            let resp = ndarray::Array2::from_shape_vec(self.shape, y_u.to_vec())
                .map_err(|e| (e.to_string(), None))?;
            let args = (
                x.to_vec().into_pyarray(py),
                theta.to_vec().into_pyarray(py),
                resp.into_pyarray(py),
            );
            let v = self
                .func
                .call1(py, args)
                .map_err(|e| crate::model::raised(py, "prediction", &at, e))?;
            let expected = format!("expected ({n},) values for outputs {:?}", self.names);
            let arr = v
                .bind(py)
                .extract::<numpy::PyArrayLikeDyn<'_, f64, numpy::AllowTypeChange>>()
                .map_err(|_| {
                    let msg =
                        format!("`prediction` returned no array of numbers at {at}; {expected}");
                    (msg, None)
                })?;
            if arr.shape() != [n] {
                let msg = format!(
                    "`prediction` returned shape {:?} at {at}; {expected}",
                    arr.shape()
                );
                return Err((msg, None));
            }
            let vals: Vec<f64> = arr.as_array().iter().copied().collect();
            if let Some(k) = vals.iter().position(|v| !v.is_finite()) {
                let msg = format!("`prediction` returned {} (value {k}) at {at}", vals[k]);
                return Err((msg, None));
            }
            Ok(vals)
        });
        match r {
            Ok(v) => {
                out.copy_from_slice(&v);
                Ok(())
            }
            Err((m, c)) => Err(self.state.fail(m, c)),
        }
    }
}

/// Band statistics, in the order of the arrays returned.
type Pick = fn(&bamudi::Band) -> &Vec<f64>;
const STATS: [(&str, Pick); 4] = [
    ("mean", |b| &b.mean),
    ("sd", |b| &b.sd),
    ("lower", |b| &b.lower),
    ("upper", |b| &b.upper),
];

/// Response, output and discrepancy bands at one input.
struct Bands {
    response: bamudi::Band,
    outputs: bamudi::Band,
    discrepancy: bamudi::Band,
}

/// The draws of `θ` and `ρ` (see [`ModelCalibration::posterior_draws`]).
struct Draws {
    theta: Vec<Vec<Vec<f64>>>,
    rho: Vec<Vec<f64>>,
    method: &'static str,
    rho_kind: &'static str,
}

impl ModelCalibration {
    fn spec(&self) -> PyResult<&Arc<ModelSpec>> {
        self.spec.as_ref().ok_or_else(|| {
            invalid(
                "this calibration was loaded without its model: predictions need the model's \
                 callables; load it with `model=` (the same model it was calibrated with)",
            )
        })
    }

    /// The θ draws: MCMC chains as they are, or `chains x n/chains` independent draws from the
    /// grid posterior's CDF (linear between nodes, as `ThetaPosterior::cdf` and the interval).
    fn draws(&self, n: usize, chains: usize, seed: u64) -> PyResult<Draws> {
        let m3 = self.cal.module3();
        let mut rng = StdRng::seed_from_u64(seed);
        let (theta, method): (Vec<Vec<Vec<f64>>>, _) = match &m3.posterior {
            ThetaPosterior::Mcmc(m) => (m.chains.clone(), "mcmc"),
            ThetaPosterior::Grid(g) => {
                let per = n.div_ceil(chains.max(1)).max(1);
                let draw = |rng: &mut StdRng| {
                    let u: f64 = rng.random::<f64>() * g.cdf[g.cdf.len() - 1];
                    let k = g.cdf.partition_point(|c| *c <= u).clamp(1, g.cdf.len() - 1);
                    let (c0, c1) = (g.cdf[k - 1], g.cdf[k]);
                    let (t0, t1) = (g.theta[k - 1], g.theta[k]);
                    let f = if c1 > c0 { (u - c0) / (c1 - c0) } else { 0.5 };
                    vec![t0 + f * (t1 - t0)]
                };
                let t = (0..chains.max(1))
                    .map(|_| (0..per).map(|_| draw(&mut rng)).collect())
                    .collect();
                (t, "grid")
            }
        };
        let (rho, rho_kind) = match m3.marginal() {
            Some(fit) => {
                let sd: Vec<f64> = m3.posterior.sd().iter().map(|s| s.max(1e-300)).collect();
                let (lo, hi) = fit.rho_prior;
                let rho = theta
                    .iter()
                    .map(|chain| {
                        chain
                            .iter()
                            .map(|t| {
                                let node = fit
                                    .nodes
                                    .iter()
                                    .min_by(|a, b| {
                                        let d = |n: &bamudi::posterior::MarginalNode| {
                                            n.theta
                                                .iter()
                                                .zip(t)
                                                .zip(&sd)
                                                .map(|((a, b), s)| ((a - b) / s).powi(2))
                                                .sum::<f64>()
                                        };
                                        d(a).total_cmp(&d(b))
                                    })
                                    .map_or((fit.rho_mean, fit.rho_sd.powi(2)), |n| {
                                        (n.rho_mean, n.rho_var)
                                    });
                                let s = node.1.max(0.0).sqrt();
                                let mut r = node.0;
                                for _ in 0..1000 {
                                    let c = node.0 + s * standard_normal(&mut rng);
                                    if (lo..=hi).contains(&c) {
                                        r = c;
                                        break;
                                    }
                                }
                                r
                            })
                            .collect()
                    })
                    .collect();
                (rho, "posterior")
            }
            None => {
                let r = self.cal.rho_star();
                (
                    theta.iter().map(|c| vec![r; c.len()]).collect(),
                    "point estimate",
                )
            }
        };
        Ok(Draws {
            theta,
            rho,
            method,
            rho_kind,
        })
    }
}

#[pymethods]
impl ModelCalibration {
    /// Posterior mean of θ per dimension.
    #[getter]
    fn theta_mean(&self) -> Vec<f64> {
        self.cal.module3().posterior.mean()
    }
    /// Posterior standard deviation of θ per dimension.
    #[getter]
    fn theta_sd(&self) -> Vec<f64> {
        self.cal.module3().posterior.sd()
    }
    /// Central 95 % interval of θ per dimension.
    #[getter]
    fn theta_ci95(&self) -> Vec<(f64, f64)> {
        self.cal.module3().posterior.ci95()
    }

    /// The posterior probability that the data hold no discrepancy the model lacks, when the
    /// calibrations with and without one were weighed by their evidence (the default; the
    /// predictions mix the two with this weight, leaving the fit without one out below 1e-9);
    /// `None` otherwise.
    #[getter]
    fn probability_without(&self) -> Option<f64> {
        self.cal.module3().probability_without()
    }
    /// `P(θ_j <= t | data)` (the grid CDF, linear between nodes, or the share of MCMC draws).
    fn theta_cdf(&self, j: usize, t: f64) -> PyResult<f64> {
        if j >= self.desc.parameters.len() {
            return Err(invalid(format!(
                "j = {j}: theta has {} dimension(s)",
                self.desc.parameters.len()
            )));
        }
        Ok(self.cal.module3().posterior.cdf(j, t))
    }
    /// `ρ*` used by Modules 3-4 (in the marginal mode, ρ's posterior mean).
    #[getter]
    fn rho_star(&self) -> f64 {
        self.cal.rho_star()
    }
    /// ρ's posterior `(mean, sd)` in the marginal mode (ρ integrated out); `None` in the other
    /// modes, where ρ is the point estimate `rho_star`.
    #[getter]
    fn rho_posterior(&self) -> Option<(f64, f64)> {
        self.cal
            .module3()
            .marginal()
            .map(|f| (f.rho_mean, f.rho_sd))
    }
    /// Measurement-noise sd σ_ε (output units).
    #[getter]
    fn sigma_eps(&self) -> f64 {
        self.cal.sigma_eps()
    }
    /// The coefficient mode (`marginal`, `conditional_on_theta`, `prior_marginal`).
    #[getter]
    fn mode(&self) -> &'static str {
        self.cal.config().coefficients.kind().name()
    }
    /// The model's description (names, coordinates, A, prior, discrepancy) as JSON text.
    fn description_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.desc).map_err(to_py)
    }
    /// The checked engine configuration used, as JSON text.
    fn config_json(&self) -> PyResult<String> {
        serde_json::to_string(self.cal.config()).map_err(to_py)
    }
    /// Seconds per stage as JSON text.
    fn timings_json(&self) -> PyResult<String> {
        serde_json::to_string(self.cal.timings()).map_err(to_py)
    }
    /// The grid posterior `(theta, density, cdf)` (one-dimensional θ; `None` for MCMC).
    fn posterior_grid<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let ThetaPosterior::Grid(g) = &self.cal.module3().posterior else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        d.set_item("theta", g.theta.clone().into_pyarray(py))?;
        d.set_item("density", g.density.clone().into_pyarray(py))?;
        d.set_item("cdf", g.cdf.clone().into_pyarray(py))?;
        Ok(Some(d))
    }
    /// The posterior without discrepancy (`δ = 0`, `ρ` integrated over its prior range, the
    /// noise sd fitted at each θ unless the configuration states `sigma_eps`; Fig. 16):
    /// `(mean, sd, ci95)` per dimension. For a peer's `reality = model + noise`, give `ρ` the
    /// range `[0.99999, 1.00001]`.
    fn no_discrepancy_summary(&self) -> Vec<(f64, f64, (f64, f64))> {
        let p = &self.cal.module3().posterior_no_discrepancy;
        let (m, s, c) = (p.mean(), p.sd(), p.ci95());
        (0..m.len()).map(|j| (m[j], s[j], c[j])).collect()
    }
    /// The adequacy report as JSON text (`None` when the checks were switched off).
    fn adequacy_json(&self) -> PyResult<Option<String>> {
        self.cal
            .adequacy()
            .map(|a| serde_json::to_string(a).map_err(to_py))
            .transpose()
    }
    /// The adequacy verdict's one-line summary (`None` without checks).
    #[getter]
    fn adequacy_summary(&self) -> Option<String> {
        self.cal.adequacy().map(|a| a.summary())
    }
    /// The posterior's warnings (mass at a uniform prior's bound, an under-resolved interval).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        posterior_warnings(&self.cal, &self.desc)
    }
    /// The experiment inputs the calibration was fitted at (`n x inputs`).
    fn x_experiments<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray2<f64>> {
        let x = self.cal.x_experiments();
        ndarray::Array2::from_shape_fn(x.shape(), |(i, j)| x[(i, j)]).into_pyarray(py)
    }
    /// The measured outputs (`n x outputs`; `None` for a loaded calibration).
    fn y_experiments<'py>(&self, py: Python<'py>) -> Option<Bound<'py, numpy::PyArray2<f64>>> {
        self.y
            .as_ref()
            .map(|y| ndarray::Array2::from_shape_fn(y.shape(), |(i, j)| y[(i, j)]).into_pyarray(py))
    }

    /// `n` posterior draws of θ and ρ as `(theta (chains, draws, d), rho (chains, draws),
    /// method, rho_kind)`: MCMC chains as they are (`n`, `chains` ignored), or independent
    /// draws from the grid posterior split into `chains`; ρ given each θ from the marginal
    /// mode's conditional normal at the nearest stored support point, truncated to ρ's prior
    /// (`rho_kind` `posterior`), or `rho_star` in the other modes (`point estimate`).
    #[pyo3(signature = (n=4000, chains=4, seed=0))]
    fn posterior_draws<'py>(
        &self,
        py: Python<'py>,
        n: usize,
        chains: usize,
        seed: u64,
    ) -> PyResult<Bound<'py, PyDict>> {
        if n == 0 || chains == 0 || n > 10_000_000 {
            return Err(invalid(format!(
                "posterior_draws: need 1 <= chains and 1 <= n <= 1e7, got n = {n}, chains = {chains}"
            )));
        }
        let d = self.draws(n, chains, seed)?;
        let (c, k, dim) = (d.theta.len(), d.theta[0].len(), self.desc.parameters.len());
        let theta = ndarray::Array3::from_shape_fn((c, k, dim), |(a, b, j)| d.theta[a][b][j]);
        let rho = ndarray::Array2::from_shape_fn((c, k), |(a, b)| d.rho[a][b]);
        let out = PyDict::new(py);
        out.set_item("theta", theta.into_pyarray(py))?;
        out.set_item("rho", rho.into_pyarray(py))?;
        out.set_item("method", d.method)?;
        out.set_item("rho_kind", d.rho_kind)?;
        Ok(out)
    }

    /// Module 4 at the rows of `x` (`n x inputs`): the corrected response (Eq. 52) and the
    /// discrepancy `L μ_α` (`(n, components, points)`), the noise-free outputs (Eq. 44;
    /// `(n, outputs)`), each `{mean, sd, lower, upper}` (2.5 / 97.5 %).
    fn predict<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArray2<'_, f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let xm = rows_of(&self.desc, &x)?;
        let (model, state) = self.spec()?.instantiate(Some(&xm))?;
        let bands = py
            .detach(|| {
                let p = self.cal.predictor(&model)?;
                (0..xm.nrows())
                    .map(|i| {
                        let xi: Vec<f64> = xm.row(i).iter().copied().collect();
                        Ok(Bands {
                            response: p.response(&xi)?,
                            outputs: p.outputs(&xi)?,
                            discrepancy: p.discrepancy(&xi)?,
                        })
                    })
                    .collect::<bamudi::Result<Vec<_>>>()
            })
            .map_err(|e| state.error(py, e))?;
        let (c, n_u, n_o) = (
            self.desc.components,
            self.desc.coordinates.len(),
            self.desc.outputs.len(),
        );
        let n = bands.len();
        let out = PyDict::new(py);
        for (name, pick) in STATS {
            let field = |f: fn(&Bands) -> &bamudi::Band| {
                ndarray::Array3::from_shape_fn((n, c, n_u), |(i, k, b)| {
                    pick(f(&bands[i]))[k * n_u + b]
                })
            };
            out.set_item(
                format!("response_{name}"),
                field(|b| &b.response).into_pyarray(py),
            )?;
            out.set_item(
                format!("discrepancy_{name}"),
                field(|b| &b.discrepancy).into_pyarray(py),
            )?;
            let o = ndarray::Array2::from_shape_fn((n, n_o), |(i, q)| pick(&bands[i].outputs)[q]);
            out.set_item(format!("outputs_{name}"), o.into_pyarray(py))?;
        }
        Ok(out)
    }

    /// `n` joint draws of Module 4's mixture (Eq. 52) at each row of `x`, the same draw paths
    /// at every row (`bamudi::Predictor::draw_paths`): `theta` (`(n, d)`, each draw's support
    /// point), `response` (`(rows, n, components, points)`) and the noise-free `outputs`
    /// `A response + b(x, θ)` (`(rows, n, outputs)`).
    #[pyo3(signature = (x, n=1000, seed=0))]
    fn predictive_draws<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArray2<'_, f64>,
        n: usize,
        seed: u64,
    ) -> PyResult<Bound<'py, PyDict>> {
        if n == 0 || n > 1_000_000 {
            return Err(invalid(format!(
                "predictive_draws: n must be in [1, 1e6], got {n}"
            )));
        }
        let xm = rows_of(&self.desc, &x)?;
        let (model, state) = self.spec()?.instantiate(Some(&xm))?;
        let n_o = self.desc.outputs.len();
        let (thetas, rows) = py
            .detach(|| {
                let p = self.cal.predictor(&model)?;
                let paths = p.draw_paths(n, seed);
                let mut thetas = vec![];
                let mut rows = vec![];
                for i in 0..xm.nrows() {
                    let xi: Vec<f64> = xm.row(i).iter().copied().collect();
                    let draws = p.draws_at(&paths, &xi)?;
                    let mut outs = Vec::with_capacity(draws.len());
                    for d in &draws {
                        let mut b = vec![0.0; n_o];
                        model.observable.offset(&xi, &d.theta, &mut b)?;
                        let ag = model.observable.matrix()
                            * nalgebra::DVector::from_column_slice(&d.response);
                        outs.push(ag.iter().zip(&b).map(|(a, b)| a + b).collect::<Vec<f64>>());
                    }
                    if i == 0 {
                        thetas = draws.iter().map(|d| d.theta.clone()).collect();
                    }
                    rows.push((draws, outs));
                }
                Ok::<_, bamudi::BamudiError>((thetas, rows))
            })
            .map_err(|e| state.error(py, e))?;
        let (c, n_u, dim) = (
            self.desc.components,
            self.desc.coordinates.len(),
            self.desc.parameters.len(),
        );
        let m = rows.len();
        let out = PyDict::new(py);
        let th = ndarray::Array2::from_shape_fn((n, dim), |(k, j)| {
            thetas.get(k).map_or(f64::NAN, |t: &Vec<f64>| t[j])
        });
        out.set_item("theta", th.into_pyarray(py))?;
        let resp = ndarray::Array4::from_shape_fn((m, n, c, n_u), |(i, k, a, b)| {
            rows[i].0[k].response[a * n_u + b]
        });
        out.set_item("response", resp.into_pyarray(py))?;
        let outs = ndarray::Array3::from_shape_fn((m, n, n_o), |(i, k, q)| rows[i].1[k][q]);
        out.set_item("outputs", outs.into_pyarray(py))?;
        Ok(out)
    }

    /// The third level (Eq. 8): `n_draws` joint draws of the corrected response at `x` (one
    /// condition, `(inputs,)`) pushed through `prediction(x, theta, response) -> (len(names),)`
    /// (`response` of shape `(components, points)`); `{mean, sd, lower, upper}` per output.
    #[pyo3(signature = (prediction, names, x, n_draws=2000, seed=0))]
    fn predict_through<'py>(
        &self,
        py: Python<'py>,
        prediction: Py<PyAny>,
        names: Vec<String>,
        x: Vec<f64>,
        n_draws: usize,
        seed: u64,
    ) -> PyResult<Bound<'py, PyDict>> {
        if !prediction.bind(py).is_callable() {
            return Err(invalid(
                "prediction must be callable: prediction(x, theta, response)",
            ));
        }
        if names.is_empty() {
            return Err(invalid("names: name at least one predicted quantity"));
        }
        if x.len() != self.desc.inputs.len() || x.iter().any(|v| !v.is_finite()) {
            return Err(invalid(format!(
                "x must be {} finite number(s) (inputs {:?}), got {x:?}",
                self.desc.inputs.len(),
                self.desc.inputs
            )));
        }
        let xm = DMatrix::from_row_slice(1, x.len(), &x);
        let (model, state) = self.spec()?.instantiate(Some(&xm))?;
        let g = PyPrediction {
            names,
            func: prediction,
            shape: (self.desc.components, self.desc.coordinates.len()),
            state: state.clone(),
        };
        let band = py
            .detach(|| {
                self.cal
                    .predictor(&model)?
                    .predict_through(&g, &x, n_draws, seed)
            })
            .map_err(|e| state.error(py, e))?;
        let out = PyDict::new(py);
        for (name, pick) in STATS {
            out.set_item(name, pick(&band).clone().into_pyarray(py))?;
        }
        Ok(out)
    }

    /// Writes `calibration.json` (the engine's) and `model.json` (the model's description)
    /// into the directory `dir` (created), each atomically.
    fn save(&self, py: Python<'_>, dir: PathBuf) -> PyResult<()> {
        py.detach(|| {
            std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
            self.cal
                .save(&dir.join("calibration.json"))
                .map_err(|e| e.to_string())?;
            let text = serde_json::to_string_pretty(&self.desc).map_err(|e| e.to_string())?;
            bamudi::data::write_atomic(&dir.join("model.json"), text.as_bytes())
                .map_err(|e| e.to_string())
        })
        .map_err(invalid)
    }

    /// Reads a calibration written by [`save`](Self::save): `calibration` is the
    /// `calibration.json` file (its `model.json` beside it); `model`, when given, must be the
    /// model it was calibrated with (checked field by field, then by the engine) and makes
    /// predictions possible.
    #[staticmethod]
    #[pyo3(signature = (calibration, model=None))]
    fn load(py: Python<'_>, calibration: PathBuf, model: Option<&Model>) -> PyResult<Self> {
        let (cal, desc) = py.detach(|| load_files(&calibration))?;
        let spec = match model {
            None => None,
            Some(m) => {
                if let Some(what) = desc.difference(&m.spec.desc) {
                    return Err(invalid(format!(
                        "model: its {what} differs from the calibrated model's ({})",
                        calibration.with_file_name("model.json").display()
                    )));
                }
                Some(m.spec.clone())
            }
        };
        Ok(Self {
            cal,
            desc,
            spec,
            y: None,
        })
    }

    fn __repr__(&self) -> String {
        let m = self.theta_mean();
        let s = self.theta_sd();
        let parts: Vec<String> = self
            .desc
            .parameters
            .iter()
            .enumerate()
            .map(|(j, p)| format!("{p} {:.4} ± {:.4}", m[j], s[j]))
            .collect();
        format!(
            "ModelCalibration({}, rho* {:.4}, {}{})",
            parts.join(", "),
            self.rho_star(),
            self.mode(),
            self.adequacy_summary()
                .map_or(String::new(), |s| format!(", {s}"))
        )
    }
}

fn load_files(calibration: &Path) -> PyResult<(bamudi::Calibration, ModelDescription)> {
    let cal = bamudi::Calibration::load(calibration).map_err(to_py)?;
    let path = calibration.with_file_name("model.json");
    let text =
        std::fs::read_to_string(&path).map_err(|e| invalid(format!("{}: {e}", path.display())))?;
    let desc: ModelDescription =
        serde_json::from_str(&text).map_err(|e| invalid(format!("{}: {e}", path.display())))?;
    if cal.input_names() != desc.inputs.as_slice() || cal.output_names() != desc.outputs.as_slice()
    {
        return Err(invalid(format!(
            "{}: its inputs and outputs are not those of {}",
            path.display(),
            calibration.display()
        )));
    }
    Ok((cal, desc))
}

/// One replicate of a coverage study.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Replicate {
    theta_true: Vec<f64>,
    /// `P(θ_j <= θ*_j | data)` per dimension (`None` when the calibration failed).
    pit: Option<Vec<f64>>,
    theta_mean: Option<Vec<f64>>,
    theta_sd: Option<Vec<f64>>,
    rho_star: Option<f64>,
    verdict: Option<String>,
    seconds: f64,
    error: Option<String>,
}

/// One nominal level's coverage for one dimension.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct LevelSummary {
    level: f64,
    hits: usize,
    n: usize,
    rate: f64,
    /// Exact 95 % (Clopper-Pearson) interval of the true coverage.
    interval95: (f64, f64),
    /// The 1 % binomial acceptance region of hit counts at the nominal level.
    acceptance: (usize, usize),
    accepted: bool,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct DimensionSummary {
    parameter: String,
    levels: Vec<LevelSummary>,
    rank_counts: Vec<usize>,
    rank_p_value: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct CoverageReport {
    replicates: Vec<Replicate>,
    dimensions: Vec<DimensionSummary>,
    failed: usize,
    seed: u64,
    noise_sd: Vec<f64>,
}

/// The coverage study of a user's model (simulation-based calibration): for each replicate
/// `r`, `θ*` is drawn from the model's prior, the data are `truth(x, θ*)` plus Gaussian noise
/// of `noise_sd` (output units, one value or one per output), both from seeds derived from
/// `seed` and `r`; the engine calibrates them; the truth's posterior transform
/// `u = P(θ ≤ θ* | data)` gives the central intervals' hits and the SBC rank
/// (`bamudi::validation`). A replicate whose calibration fails is reported with its error and
/// left out of the counts; a failing callback stops the study. Returns the report as JSON.
#[pyfunction]
#[pyo3(signature = (model, truth, x, noise_sd, replicates=20, config_json=None,
                    config_toml=None, config_label="config".to_string(), seed=0,
                    levels=vec![0.5, 0.8, 0.9, 0.95], bins=10, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn coverage(
    py: Python<'_>,
    model: &Model,
    truth: Py<PyAny>,
    x: PyReadonlyArray2<'_, f64>,
    noise_sd: Vec<f64>,
    replicates: usize,
    config_json: Option<String>,
    config_toml: Option<String>,
    config_label: String,
    seed: u64,
    levels: Vec<f64>,
    bins: usize,
    progress: Option<Py<PyAny>>,
) -> PyResult<String> {
    let desc = &model.spec.desc;
    if !truth.bind(py).is_callable() {
        return Err(invalid(
            "truth must be callable: truth(x, theta) -> (n, outputs)",
        ));
    }
    if !(1..=100_000).contains(&replicates) {
        return Err(invalid(format!(
            "replicates must be in [1, 100000], got {replicates}"
        )));
    }
    if let Some(l) = levels.iter().find(|l| !(**l > 0.0 && **l < 1.0)) {
        return Err(invalid(format!("levels must be in (0, 1), got {l}")));
    }
    if bins < 2 {
        return Err(invalid(format!("bins must be at least 2, got {bins}")));
    }
    let n_o = desc.outputs.len();
    let noise: Vec<f64> = match noise_sd.len() {
        1 => vec![noise_sd[0]; n_o],
        k if k == n_o => noise_sd,
        k => {
            return Err(invalid(format!(
                "noise_sd: {k} values for {n_o} outputs; give one, or one per output"
            )));
        }
    };
    if let Some(s) = noise.iter().find(|s| !(s.is_finite() && **s > 0.0)) {
        return Err(invalid(format!(
            "noise_sd must be finite and > 0 (output units), got {s}"
        )));
    }
    let base = read_config(
        config_json.as_deref(),
        config_toml.as_deref(),
        &config_label,
        None,
    )?;
    let xm = rows_of(desc, &x)?;
    let truths = model.spec.prior()?.sample(replicates, derive_seed(seed, 0));
    let truth = Arc::new(truth);
    let mut reps = Vec::with_capacity(replicates);
    for (r, theta) in truths.into_iter().enumerate() {
        let start = std::time::Instant::now();
        let clean = call_outputs("truth", &truth, &xm, &theta, n_o)?;
        let mut rng = StdRng::seed_from_u64(derive_seed(seed, 1 + r as u64));
        let y = DMatrix::from_fn(xm.nrows(), n_o, |_, _| 0.0);
        let mut y = y;
        for i in 0..xm.nrows() {
            for q in 0..n_o {
                y[(i, q)] = clean[(i, q)] + noise[q] * standard_normal(&mut rng);
            }
        }
        let exps = Experiments::new(desc.inputs.clone(), desc.outputs.clone(), xm.clone(), y)
            .map_err(to_py)?;
        let cfg = base
            .clone()
            .into_params()
            .seed(derive_seed(seed, 1_000_000 + r as u64))
            .check()
            .map_err(to_py)?;
        let (model_r, state) = model.spec.instantiate(Some(&exps.x))?;
        let observer = Callback::new(progress.as_ref().map(|p| p.clone_ref(py)));
        let result = py.detach(|| {
            Calibrate::new(&cfg)
                .observer(&observer)
                .run(&model_r, &exps)
        });
        let rep = match result {
            Ok(cal) => {
                let post = &cal.module3().posterior;
                Replicate {
                    pit: Some((0..theta.len()).map(|j| post.cdf(j, theta[j])).collect()),
                    theta_mean: Some(post.mean()),
                    theta_sd: Some(post.sd()),
                    rho_star: Some(cal.rho_star()),
                    verdict: cal
                        .adequacy()
                        .map(|a| format!("{:?}", a.verdict).to_lowercase()),
                    seconds: start.elapsed().as_secs_f64(),
                    error: None,
                    theta_true: theta,
                }
            }
            Err(e) => {
                // a callback's failure is the user's to fix: stop and raise it
                if state.has_failed() {
                    return Err(state.error(py, e));
                }
                Replicate {
                    pit: None,
                    theta_mean: None,
                    theta_sd: None,
                    rho_star: None,
                    verdict: None,
                    seconds: start.elapsed().as_secs_f64(),
                    error: Some(bamudi_gate::error::one_line_of(&e)),
                    theta_true: theta,
                }
            }
        };
        reps.push(rep);
    }
    let ok: Vec<&Replicate> = reps.iter().filter(|r| r.pit.is_some()).collect();
    let mut dims = vec![];
    if !ok.is_empty() {
        for (j, name) in desc.parameters.iter().enumerate() {
            let pits: Vec<f64> = ok
                .iter()
                .map(|r| r.pit.as_ref().map_or(0.0, |p| p[j]))
                .collect();
            let mut lv = vec![];
            for &level in &levels {
                let c = Coverage::from_pits(&pits, level);
                let acceptance = binomial_acceptance(c.n, level, 0.01).map_err(to_py)?;
                lv.push(LevelSummary {
                    level,
                    hits: c.hits,
                    n: c.n,
                    rate: c.rate(),
                    interval95: c.clopper_pearson(0.95).map_err(to_py)?,
                    acceptance,
                    accepted: c.accepts_nominal(0.01).map_err(to_py)?,
                });
            }
            let h = RankHistogram::new(&pits, bins).map_err(to_py)?;
            dims.push(DimensionSummary {
                parameter: name.clone(),
                levels: lv,
                rank_counts: h.counts,
                rank_p_value: h.p_value,
            });
        }
    }
    let report = CoverageReport {
        failed: reps.len() - ok.len(),
        replicates: reps,
        dimensions: dims,
        seed,
        noise_sd: noise,
    };
    serde_json::to_string(&report).map_err(to_py)
}
