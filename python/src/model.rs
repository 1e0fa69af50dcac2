//! `bamudi.Model`: bring your own multi-level model from Python. The `mlmodel` traits the
//! engine is generic over are implemented here by Python callables and numpy arrays, so a
//! user's model runs through the same engine code as the gate (no second implementation):
//!
//! * [`PyResponse`] is the unobservable model `g_u(x, θ)` of Eq. 6: a Python callable;
//! * [`PyObservable`] the linear observable model `y = A g_u + b(x, θ)` of Eq. 47: a matrix
//!   `A` and an optional offset callable `b`;
//! * the prior ([`PriorSpec`]: uniform or normal per dimension) and the discrepancy basis
//!   (Eq. 15-17, 49: Legendre, Chebyshev or Hermite terms per component).
//!
//! **Threads and the GIL.** The engine evaluates the model in parallel (rayon). Each callback
//! takes the GIL (`Python::attach`) only while the Python function runs and converts its
//! result; the engine itself runs with the GIL released by its caller (`Python::detach`), so a
//! thread waiting for the GIL never holds engine work another thread waits for.
//!
//! **Vectorised callables.** A vectorised callable gets many inputs at one `θ`
//! (`f(x: (n, d_x), theta: (d_θ,))`). The engine asks for one `(x, θ)` at a time, but mostly
//! for every experiment at one `θ` (Eq. 50's mean, the Module-2 contexts): when the asked `x`
//! is one of the known inputs of the run (the experiments, or the inputs predicted at), the
//! whole batch is evaluated in one call at that `θ` and kept in a small cache (first come,
//! first evicted) that the other threads read; any other `x` is a batch of one.
//!
//! **Errors.** A callback that raises, returns the wrong shape or a non-finite value fails
//! the run: the first failure is kept with its Python exception (and traceback), later
//! callbacks of the run fail at once without calling Python, and the engine's error is
//! replaced by a `BamudiError` naming the callable, the expected shape and the `(x, θ)` it
//! was called at, with the original exception as its `__cause__`.

use crate::invalid;
use mlmodel::{
    DiscrepancyBasis, IndependentPrior, LinearObservableModel, ModelError, MultiLevelModel,
    NormalPrior, ObservableModel, Prior, PriorDimension, UniformPrior, UnobservableModel,
};
use nalgebra::DMatrix;
use numpy::{AllowTypeChange, IntoPyArray, PyArrayLikeDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyTracebackMethods;
use serde::{Deserialize, Serialize};
use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

/// Rows of `A g_u` and `b` the engine remembers per run ([`MultiLevelModel::with_row_memo`]).
const ROW_MEMO: usize = 50_000;

/// Bytes of batch results a vectorised callable keeps per run (at least
/// [`CACHED_THETAS_PER_THREAD`] `θ` values per worker thread whatever their size).
const BATCH_CACHE_BYTES: usize = 256 << 20;

/// Fewest `θ` values whose batches are kept, per worker thread: enough for every thread to be
/// at its own `θ` without evicting another's batch before its rows are read.
const CACHED_THETAS_PER_THREAD: usize = 4;

/// The first failure of a run's callbacks, kept to be raised when the engine returns.
pub(crate) struct Failure {
    message: String,
    cause: Option<PyErr>,
}

/// What the callbacks of one run (a calibration, a prediction) share: whether one failed,
/// and the first failure.
#[derive(Default)]
pub(crate) struct RunState {
    failed: AtomicBool,
    first: Mutex<Option<Failure>>,
}

impl RunState {
    /// Records a failure (the first one is kept) and returns the engine's error for it.
    pub(crate) fn fail(&self, message: String, cause: Option<PyErr>) -> ModelError {
        if let Ok(mut first) = self.first.lock()
            && first.is_none()
        {
            *first = Some(Failure {
                message: message.clone(),
                cause,
            });
        }
        self.failed.store(true, Ordering::SeqCst);
        ModelError::Numerical {
            context: "a Python callback".into(),
            reason: message,
        }
    }

    /// The error of a callback skipped because an earlier one failed.
    fn skipped(&self) -> Option<ModelError> {
        self.failed
            .load(Ordering::SeqCst)
            .then(|| ModelError::Numerical {
                context: "a Python callback".into(),
                reason: "not called: an earlier callback of this run failed".into(),
            })
    }

    /// Whether a callback of this run failed.
    pub(crate) fn has_failed(&self) -> bool {
        self.failed.load(Ordering::SeqCst)
    }

    /// The Python exception for an engine error of this run: the first callback failure
    /// (its message, the original exception as `__cause__`) when there was one, else the
    /// engine's message.
    pub(crate) fn error(&self, py: Python<'_>, engine: impl std::fmt::Display) -> PyErr {
        let first = self.first.lock().ok().and_then(|mut f| f.take());
        match first {
            Some(f) => {
                let e = invalid(f.message);
                e.set_cause(py, f.cause);
                e
            }
            None => invalid(engine.to_string()),
        }
    }
}

/// A Python callable of `(x, θ)` with the shape of its result.
struct Callback {
    /// The argument's name in the API (`response`, `offset`, `truth`).
    name: &'static str,
    func: Arc<Py<PyAny>>,
    vectorised: bool,
    /// Values per input row.
    width: usize,
    /// The accepted shapes of one row besides `(width,)` (e.g. `(components, points)`).
    row_shape: Vec<usize>,
}

impl Callback {
    /// `func(x, θ)` at the rows of `x` (`n x d`, row-major) into a row-major `n x width`
    /// vector; the error message names the callable, the expected shape and where it was
    /// called, with the Python exception when it raised.
    fn call(
        &self,
        x: &[f64],
        d: usize,
        theta: &[f64],
    ) -> std::result::Result<Vec<f64>, (String, Option<PyErr>)> {
        let n = x.len().checked_div(d).unwrap_or(0);
        let at = || {
            let shown = if n == 1 {
                format!("x = {x:?}")
            } else {
                format!("{n} inputs x")
            };
            format!("{shown}, theta = {theta:?}")
        };
        Python::attach(|py| {
            let th = theta.to_vec().into_pyarray(py);
            let result = if self.vectorised {
                let xs = ndarray::Array2::from_shape_vec((n, d), x.to_vec())
                    .map_err(|e| (format!("{}: {e}", self.name), None))?;
                self.func.call1(py, (xs.into_pyarray(py), th))
            } else {
                self.func.call1(py, (x.to_vec().into_pyarray(py), th))
            };
            let result = result.map_err(|e| raised(py, self.name, &at(), e))?;
            let arr = result
                .bind(py)
                .extract::<PyArrayLikeDyn<'_, f64, AllowTypeChange>>()
                .map_err(|_| {
                    let ty = result
                        .bind(py)
                        .get_type()
                        .name()
                        .map_or("?".into(), |s| s.to_string());
                    (
                        format!(
                            "`{}` returned a {ty}, not an array of numbers, at {}; expected {}",
                            self.name,
                            at(),
                            self.expected(n)
                        ),
                        None,
                    )
                })?;
            let shape = arr.shape().to_vec();
            if !self.accepts(&shape, n) {
                return Err((
                    format!(
                        "`{}` returned shape {} at {}; expected {}",
                        self.name,
                        tuple(&shape),
                        at(),
                        self.expected(n)
                    ),
                    None,
                ));
            }
            let values: Vec<f64> = arr.as_array().iter().copied().collect();
            if let Some(k) = values.iter().position(|v| !v.is_finite()) {
                let (row, col) = (k / self.width, k % self.width);
                let where_ = if n == 1 {
                    at()
                } else {
                    format!(
                        "input row {row} = {:?}, theta = {theta:?}",
                        &x[row * d..][..d]
                    )
                };
                return Err((
                    format!(
                        "`{}` returned {} at {where_} (value {col} of the row's {})",
                        self.name, values[k], self.width
                    ),
                    None,
                ));
            }
            Ok(values)
        })
    }

    /// Whether a result of `shape` fits `n` rows.
    fn accepts(&self, shape: &[usize], n: usize) -> bool {
        let row_ok = |s: &[usize]| s == [self.width] || s == self.row_shape.as_slice();
        if self.vectorised {
            shape.first() == Some(&n) && row_ok(&shape[1..])
        } else {
            row_ok(shape)
        }
    }

    /// The shapes accepted for `n` rows, as a message says them.
    fn expected(&self, n: usize) -> String {
        let lead: Vec<usize> = if self.vectorised { vec![n] } else { vec![] };
        let flat = [lead.clone(), vec![self.width]].concat();
        let mut text = tuple(&flat);
        if self.row_shape.len() > 1 {
            let full = [lead, self.row_shape.clone()].concat();
            text = format!("{text} or {}", tuple(&full));
        }
        let what = match self.name {
            "response" => "components × points",
            _ => "outputs",
        };
        match self.vectorised {
            true => format!("{text} (inputs, {what}) float64 values"),
            false => format!("{text} ({what}) float64 values"),
        }
    }
}

/// `(2, 21)` for a shape.
fn tuple(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|s| s.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// The message and cause of a callable `name` that raised `e` at `at`: the exception, where
/// it was called, and the Python traceback.
pub(crate) fn raised(py: Python<'_>, name: &str, at: &str, e: PyErr) -> (String, Option<PyErr>) {
    let tb = e
        .traceback(py)
        .and_then(|t| t.format().ok())
        .unwrap_or_default();
    let what = describe_exception(py, &e);
    (
        format!("`{name}` raised {what} at {at}\n{tb}{what}"),
        Some(e),
    )
}

/// `ValueError: boom`.
fn describe_exception(py: Python<'_>, e: &PyErr) -> String {
    let ty = e
        .get_type(py)
        .name()
        .map_or("Exception".into(), |s| s.to_string());
    format!("{ty}: {}", e.value(py))
}

/// The known inputs of a run, whose batches a vectorised callable evaluates at once.
struct Known {
    /// Row-major `n x d`.
    x: Vec<f64>,
    d: usize,
    index: HashMap<Vec<u64>, usize>,
}

impl Known {
    fn new(x: &DMatrix<f64>) -> Self {
        let d = x.ncols();
        let mut rows = Vec::with_capacity(x.len());
        let mut index = HashMap::new();
        for i in 0..x.nrows() {
            let row: Vec<f64> = x.row(i).iter().copied().collect();
            index.entry(bits(&row)).or_insert(i);
            rows.extend(row);
        }
        Self { x: rows, d, index }
    }
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|t| t.to_bits()).collect()
}

/// One batch: the values at every known input for one `θ`, or the failure's message.
type Batch = Arc<OnceLock<std::result::Result<Arc<[f64]>, String>>>;

/// The batches of the most recent `θ` values.
struct BatchCache {
    capacity: usize,
    order: VecDeque<Vec<u64>>,
    map: HashMap<Vec<u64>, Batch>,
}

impl BatchCache {
    fn entry(&mut self, theta: Vec<u64>) -> Batch {
        if let Some(b) = self.map.get(&theta) {
            return b.clone();
        }
        while self.order.len() >= self.capacity {
            if let Some(old) = self.order.pop_front() {
                self.map.remove(&old);
            }
        }
        let b: Batch = Arc::default();
        self.order.push_back(theta.clone());
        self.map.insert(theta, b.clone());
        b
    }
}

/// A callback of one run: its state, its known inputs and their batches.
struct RunCallback {
    cb: Callback,
    state: Arc<RunState>,
    known: Option<Known>,
    cache: Mutex<BatchCache>,
}

impl RunCallback {
    fn new(cb: Callback, state: Arc<RunState>, known: Option<&DMatrix<f64>>) -> Self {
        let known = known.filter(|_| cb.vectorised).map(Known::new);
        let rows = known.as_ref().map_or(1, |k| k.index.len().max(1));
        let per_theta = rows * cb.width * 8;
        let floor = CACHED_THETAS_PER_THREAD * rayon::current_num_threads();
        let capacity = (BATCH_CACHE_BYTES / per_theta.max(1)).max(floor);
        Self {
            cb,
            state,
            known,
            cache: Mutex::new(BatchCache {
                capacity,
                order: VecDeque::new(),
                map: HashMap::new(),
            }),
        }
    }

    /// The values at `(x, θ)` into `out` (length `width`).
    fn eval(&self, x: &[f64], theta: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        if let Some(e) = self.state.skipped() {
            return Err(e);
        }
        mlmodel::check_len(self.cb.name, out, self.cb.width)?;
        if let Some(k) = &self.known
            && let Some(&row) = k.index.get(&bits(x))
        {
            let batch = match self.cache.lock() {
                Ok(mut c) => c.entry(bits(theta)),
                Err(_) => return Err(self.state.fail("batch cache poisoned".into(), None)),
            };
            let values = batch.get_or_init(|| match self.cb.call(&k.x, k.d, theta) {
                Ok(v) => Ok(v.into()),
                Err((message, cause)) => {
                    self.state.fail(message.clone(), cause);
                    Err(message)
                }
            });
            return match values {
                Ok(v) => {
                    out.copy_from_slice(&v[row * self.cb.width..][..self.cb.width]);
                    Ok(())
                }
                Err(message) => Err(ModelError::Numerical {
                    context: "a Python callback".into(),
                    reason: message.clone(),
                }),
            };
        }
        match self.cb.call(x, x.len(), theta) {
            Ok(v) => {
                out.copy_from_slice(&v);
                Ok(())
            }
            Err((message, cause)) => Err(self.state.fail(message, cause)),
        }
    }
}

/// The unobservable model `g_u(x, θ)` (Eq. 6) as a Python callable.
pub(crate) struct PyResponse {
    inputs: Vec<String>,
    param_dim: usize,
    components: usize,
    coordinates: Vec<f64>,
    call: RunCallback,
}

impl UnobservableModel for PyResponse {
    fn input_names(&self) -> Vec<String> {
        self.inputs.clone()
    }
    fn param_dim(&self) -> usize {
        self.param_dim
    }
    fn components(&self) -> usize {
        self.components
    }
    fn coordinates(&self) -> &[f64] {
        &self.coordinates
    }
    fn evaluate(&self, x: &[f64], theta: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        mlmodel::check_len("x", x, self.inputs.len())?;
        mlmodel::check_len("theta", theta, self.param_dim)?;
        self.call.eval(x, theta, out)
    }
}

/// The linear observable model `y = A g_u + b(x, θ)` (Eq. 47) as a matrix and an optional
/// offset callable.
pub(crate) struct PyObservable {
    outputs: Vec<String>,
    a: DMatrix<f64>,
    offset: Option<RunCallback>,
}

impl ObservableModel for PyObservable {
    fn output_names(&self) -> Vec<String> {
        self.outputs.clone()
    }
    fn evaluate(
        &self,
        x: &[f64],
        theta: &[f64],
        y_u: &[f64],
        out: &mut [f64],
    ) -> mlmodel::Result<()> {
        mlmodel::check_len("y_u", y_u, self.a.ncols())?;
        self.offset(x, theta, out)?;
        let y = &self.a * nalgebra::DVector::from_column_slice(y_u);
        out.iter_mut().zip(y.iter()).for_each(|(o, v)| *o += v);
        Ok(())
    }
}

impl LinearObservableModel for PyObservable {
    fn matrix(&self) -> &DMatrix<f64> {
        &self.a
    }
    fn offset(&self, x: &[f64], theta: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        mlmodel::check_len("offset out", out, self.a.nrows())?;
        match &self.offset {
            None => {
                out.fill(0.0);
                Ok(())
            }
            Some(cb) => cb.eval(x, theta, out),
        }
    }
}

/// A user's multi-level model as the engine consumes it.
pub(crate) type UserModel = MultiLevelModel<PyResponse, PyObservable>;

/// The prior of `θ`: independent dimensions, each uniform or normal; all-uniform and
/// all-normal priors are the engine's [`UniformPrior`] and [`NormalPrior`], a mix is
/// [`IndependentPrior`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub(crate) struct PriorSpec(Vec<PriorDimension>);

impl PriorSpec {
    fn build(&self) -> PyResult<Box<dyn Prior>> {
        let pairs = |f: fn(&PriorDimension) -> Option<(f64, f64)>| -> Option<Vec<(f64, f64)>> {
            self.0.iter().map(f).collect()
        };
        let uniform = pairs(|d| match *d {
            PriorDimension::Uniform { lo, hi } => Some((lo, hi)),
            PriorDimension::Normal { .. } => None,
        });
        let normal = pairs(|d| match *d {
            PriorDimension::Normal { mean, sd } => Some((mean, sd)),
            PriorDimension::Uniform { .. } => None,
        });
        let prior: mlmodel::Result<Box<dyn Prior>> = match (uniform, normal) {
            (Some(b), _) => UniformPrior::new(b).map(|p| Box::new(p) as Box<dyn Prior>),
            (_, Some(m)) => NormalPrior::new(m).map(|p| Box::new(p) as Box<dyn Prior>),
            _ => IndependentPrior::new(self.0.clone()).map(|p| Box::new(p) as Box<dyn Prior>),
        };
        prior.map_err(|e| invalid(format!("prior: {e}")))
    }

    /// The bounds of a uniform dimension `j` (`None` for a normal one, which has none).
    pub(crate) fn uniform_bounds(&self, j: usize) -> Option<(f64, f64)> {
        match self.0[j] {
            PriorDimension::Uniform { lo, hi } => Some((lo, hi)),
            PriorDimension::Normal { .. } => None,
        }
    }
}

/// The discrepancy basis as given (Eq. 15-17, 49).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct BasisSpec {
    pub(crate) family: orthopoly::Family,
    pub(crate) interval: (f64, f64),
    pub(crate) terms: Vec<usize>,
}

/// Everything of a user's model but its callables: what a saved calibration records so that
/// loading it can check the model it is given, and report without one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct ModelDescription {
    /// Input names (with units).
    pub(crate) inputs: Vec<String>,
    /// Output names (with units).
    pub(crate) outputs: Vec<String>,
    /// Names of `θ`'s dimensions.
    pub(crate) parameters: Vec<String>,
    /// Response coordinates `d_u` (`N_u`).
    pub(crate) coordinates: Vec<f64>,
    /// Response components `C`.
    pub(crate) components: usize,
    /// The matrix `A` row by row (`N_o x C N_u`).
    pub(crate) a: Vec<Vec<f64>>,
    /// Whether the model has an offset `b(x, θ)`.
    pub(crate) has_offset: bool,
    /// The prior of `θ`.
    pub(crate) prior: PriorSpec,
    /// The discrepancy basis.
    pub(crate) discrepancy: BasisSpec,
}

impl ModelDescription {
    /// The first field in which `other` differs, as a message names it.
    pub(crate) fn difference(&self, other: &Self) -> Option<&'static str> {
        [
            ("inputs", self.inputs == other.inputs),
            ("outputs", self.outputs == other.outputs),
            ("parameters", self.parameters == other.parameters),
            ("coordinates", self.coordinates == other.coordinates),
            ("components", self.components == other.components),
            ("A", self.a == other.a),
            ("offset (given or not)", self.has_offset == other.has_offset),
            ("prior", self.prior == other.prior),
            ("discrepancy", self.discrepancy == other.discrepancy),
        ]
        .into_iter()
        .find(|(_, same)| !same)
        .map(|(what, _)| what)
    }
}

/// A user's model: the description and the callables.
pub(crate) struct ModelSpec {
    pub(crate) desc: ModelDescription,
    a: DMatrix<f64>,
    basis: DiscrepancyBasis,
    response: Arc<Py<PyAny>>,
    offset: Option<Arc<Py<PyAny>>>,
    vectorised: bool,
}

impl ModelSpec {
    /// The engine's model for one run, with a fresh [`RunState`]; `known` are the inputs the
    /// run evaluates at most (the experiments, or the inputs predicted at).
    pub(crate) fn instantiate(
        &self,
        known: Option<&DMatrix<f64>>,
    ) -> PyResult<(UserModel, Arc<RunState>)> {
        let state = Arc::new(RunState::default());
        let d = &self.desc;
        let n_u = d.coordinates.len();
        let response = Callback {
            name: "response",
            func: self.response.clone(),
            vectorised: self.vectorised,
            width: d.components * n_u,
            row_shape: vec![d.components, n_u],
        };
        let offset = self.offset.as_ref().map(|f| Callback {
            name: "offset",
            func: f.clone(),
            vectorised: self.vectorised,
            width: d.outputs.len(),
            row_shape: vec![d.outputs.len()],
        });
        let unobservable = PyResponse {
            inputs: d.inputs.clone(),
            param_dim: d.parameters.len(),
            components: d.components,
            coordinates: d.coordinates.clone(),
            call: RunCallback::new(response, state.clone(), known),
        };
        let observable = PyObservable {
            outputs: d.outputs.clone(),
            a: self.a.clone(),
            offset: offset.map(|cb| RunCallback::new(cb, state.clone(), known)),
        };
        let model = MultiLevelModel::new(
            unobservable,
            observable,
            d.prior.build()?,
            self.basis.clone(),
        )
        .map_err(|e| invalid(format!("model: {e}")))?
        .with_row_memo(ROW_MEMO);
        Ok((model, state))
    }

    /// The prior of `θ`.
    pub(crate) fn prior(&self) -> PyResult<Box<dyn Prior>> {
        self.desc.prior.build()
    }
}

/// A truth (or any `(x, θ) -> outputs` function) evaluated once at all rows of `x`, with the
/// GIL held by the caller; the message names `name` and the expected shape.
pub(crate) fn call_outputs(
    name: &'static str,
    func: &Arc<Py<PyAny>>,
    x: &DMatrix<f64>,
    theta: &[f64],
    outputs: usize,
) -> PyResult<DMatrix<f64>> {
    let cb = Callback {
        name,
        func: func.clone(),
        vectorised: true,
        width: outputs,
        row_shape: vec![outputs],
    };
    let rows: Vec<f64> = (0..x.nrows())
        .flat_map(|i| x.row(i).iter().copied().collect::<Vec<_>>())
        .collect();
    let values = cb
        .call(&rows, x.ncols(), theta)
        .map_err(|(message, cause)| {
            Python::attach(|py| {
                let e = invalid(message);
                e.set_cause(py, cause);
                e
            })
        })?;
    Ok(DMatrix::from_row_slice(x.nrows(), outputs, &values))
}

/// Parses a polynomial family's name.
fn family(name: &str) -> PyResult<orthopoly::Family> {
    match name.to_ascii_lowercase().as_str() {
        "legendre" => Ok(orthopoly::Family::Legendre),
        "chebyshev" => Ok(orthopoly::Family::Chebyshev),
        "hermite" => Ok(orthopoly::Family::Hermite),
        other => Err(invalid(format!(
            "discrepancy family: `{other}` is not one of legendre, chebyshev, hermite"
        ))),
    }
}

/// A multi-level model made of Python callables and numpy arrays (see the module docs).
/// Immutable; shareable between threads.
#[pyclass(module = "bamudi._native", frozen)]
pub struct Model {
    pub(crate) spec: Arc<ModelSpec>,
}

#[pymethods]
impl Model {
    /// `response(x, theta)`: the distributed response `g_u` at `coordinates` (`N_u` points)
    /// for `components` components; `a` (`N_o x components·N_u`, columns component blocked)
    /// maps it to the `outputs`; `offset(x, theta)` adds `b` (none: 0). The prior is
    /// `prior_kinds[j]` (`uniform`: a `(lo, hi)` pair; `normal`: `(mean, sd)`) with
    /// `prior_pairs[j]` for each dimension (`parameters[j]`), one pair per
    /// `parameters` entry; the discrepancy has `terms[c]` terms of `family` on `interval`
    /// (default: the coordinates' range) for component `c`.
    #[new]
    #[pyo3(signature = (response, coordinates, inputs, outputs, a, prior_kinds, prior_pairs,
                        parameters, family_name="legendre", terms=vec![2], interval=None,
                        components=1, offset=None, vectorised=true))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        response: Py<PyAny>,
        coordinates: Vec<f64>,
        inputs: Vec<String>,
        outputs: Vec<String>,
        a: numpy::PyReadonlyArray2<'_, f64>,
        prior_kinds: Vec<String>,
        prior_pairs: Vec<(f64, f64)>,
        parameters: Vec<String>,
        family_name: &str,
        terms: Vec<usize>,
        interval: Option<(f64, f64)>,
        components: usize,
        offset: Option<Py<PyAny>>,
        vectorised: bool,
    ) -> PyResult<Self> {
        if !response.bind(py).is_callable() {
            return Err(invalid("response must be callable: response(x, theta)"));
        }
        if let Some(o) = &offset
            && !o.bind(py).is_callable()
        {
            return Err(invalid(
                "offset must be callable: offset(x, theta), or None",
            ));
        }
        if inputs.is_empty() {
            return Err(invalid("inputs: name at least one input"));
        }
        if outputs.is_empty() {
            return Err(invalid("outputs: name at least one output"));
        }
        for (what, names) in [
            ("inputs", &inputs),
            ("outputs", &outputs),
            ("parameters", &parameters),
        ] {
            let mut seen = std::collections::HashSet::new();
            if let Some(dup) = names.iter().find(|n| !seen.insert(n.as_str())) {
                return Err(invalid(format!("{what}: `{dup}` is named twice")));
            }
        }
        if coordinates.is_empty() {
            return Err(invalid("coordinates: need at least 1 response point"));
        }
        if let Some(k) = coordinates.iter().position(|c| !c.is_finite()) {
            return Err(invalid(format!("coordinates[{k}] is {}", coordinates[k])));
        }
        if components == 0 {
            return Err(invalid("components must be at least 1"));
        }
        let n_u = coordinates.len();
        let a_arr = a.as_array();
        let (n_o, width) = (outputs.len(), components * n_u);
        if a_arr.shape() != [n_o, width] {
            return Err(invalid(format!(
                "A has shape {}; expected (outputs, components × points) = ({n_o}, {width})",
                tuple(a_arr.shape())
            )));
        }
        if let Some(((i, j), v)) = a_arr.indexed_iter().find(|(_, v)| !v.is_finite()) {
            return Err(invalid(format!("A[{i}, {j}] is {v}")));
        }
        let matrix = DMatrix::from_fn(n_o, width, |i, j| a_arr[[i, j]]);
        if prior_kinds.len() != prior_pairs.len() {
            return Err(invalid(format!(
                "prior: {} kinds for {} pairs",
                prior_kinds.len(),
                prior_pairs.len()
            )));
        }
        if prior_pairs.is_empty() {
            return Err(invalid(
                "prior: at least one dimension of theta is required",
            ));
        }
        let mut dims = Vec::with_capacity(prior_pairs.len());
        for (j, (kind, &(p, q))) in prior_kinds.iter().zip(&prior_pairs).enumerate() {
            let name = parameters.get(j).map_or("?", |s| s.as_str());
            let (dim, ok, need) = match kind.as_str() {
                "uniform" => (
                    PriorDimension::Uniform { lo: p, hi: q },
                    p.is_finite() && q.is_finite() && p < q,
                    "Uniform(lo, hi) needs finite lo < hi",
                ),
                "normal" => (
                    PriorDimension::Normal { mean: p, sd: q },
                    p.is_finite() && q.is_finite() && q > 0.0,
                    "Normal(mean, sd) needs a finite mean and a finite sd > 0",
                ),
                other => {
                    return Err(invalid(format!(
                        "prior[{j}] ({name}): unknown kind `{other}` (uniform, normal)"
                    )));
                }
            };
            if !ok {
                return Err(invalid(format!(
                    "prior[{j}] ({name}): {need}, got ({p}, {q})"
                )));
            }
            dims.push(dim);
        }
        let prior = PriorSpec(dims);
        if parameters.len() != prior.0.len() {
            return Err(invalid(format!(
                "parameters: {} names for a prior of {} dimension(s)",
                parameters.len(),
                prior.0.len()
            )));
        }
        if terms.len() != components {
            return Err(invalid(format!(
                "discrepancy terms: {} entries for {components} component(s); give one per component",
                terms.len()
            )));
        }
        if let Some(t) = terms.iter().find(|t| !(1..=20).contains(*t)) {
            return Err(invalid(format!(
                "discrepancy terms must be in [1, 20] each, got {t}"
            )));
        }
        let lo = coordinates.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = coordinates
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        // one point (a scalar response, the single-level case): the polynomials' interval
        // only scales the constant term, any interval around the point serves
        let interval = interval.unwrap_or(if lo < hi {
            (lo, hi)
        } else {
            (lo - 1.0, lo + 1.0)
        });
        if !(interval.0.is_finite() && interval.1.is_finite() && interval.0 < interval.1) {
            return Err(invalid(format!(
                "discrepancy interval: need finite lo < hi, got ({}, {})",
                interval.0, interval.1
            )));
        }
        let fam = family(family_name)?;
        let basis = DiscrepancyBasis::new(fam, interval, &coordinates, &terms)
            .map_err(|e| invalid(format!("discrepancy: {e}")))?;
        let desc = ModelDescription {
            inputs,
            outputs,
            parameters,
            coordinates,
            components,
            a: (0..n_o)
                .map(|i| matrix.row(i).iter().copied().collect())
                .collect(),
            has_offset: offset.is_some(),
            prior,
            discrepancy: BasisSpec {
                family: fam,
                interval,
                terms,
            },
        };
        Ok(Self {
            spec: Arc::new(ModelSpec {
                desc,
                a: matrix,
                basis,
                response: Arc::new(response),
                offset: offset.map(Arc::new),
                vectorised,
            }),
        })
    }

    /// Input names.
    #[getter]
    fn inputs(&self) -> Vec<String> {
        self.spec.desc.inputs.clone()
    }
    /// Output names.
    #[getter]
    fn outputs(&self) -> Vec<String> {
        self.spec.desc.outputs.clone()
    }
    /// Names of θ's dimensions.
    #[getter]
    fn parameters(&self) -> Vec<String> {
        self.spec.desc.parameters.clone()
    }
    /// Response coordinates `d_u`.
    #[getter]
    fn coordinates(&self) -> Vec<f64> {
        self.spec.desc.coordinates.clone()
    }
    /// Response components `C`.
    #[getter]
    fn components(&self) -> usize {
        self.spec.desc.components
    }
    /// Whether the callables are vectorised.
    #[getter]
    fn vectorised(&self) -> bool {
        self.spec.vectorised
    }
    /// The model's description (no callables) as JSON text.
    fn description_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.spec.desc).map_err(crate::to_py)
    }

    /// `g_u(x, θ)` at the rows of `x` through the engine's model (the callable, its checks):
    /// `(n, components, points)`.
    fn response<'py>(
        &self,
        py: Python<'py>,
        x: numpy::PyReadonlyArray2<'_, f64>,
        theta: Vec<f64>,
    ) -> PyResult<Bound<'py, numpy::PyArray3<f64>>> {
        let xm = to_matrix(&x.as_array());
        let (model, state) = self.spec.instantiate(Some(&xm))?;
        let d = &self.spec.desc;
        let (c, n_u) = (d.components, d.coordinates.len());
        let values = py
            .detach(|| {
                (0..xm.nrows())
                    .map(|i| {
                        let xi: Vec<f64> = xm.row(i).iter().copied().collect();
                        let mut g = vec![0.0; c * n_u];
                        model.unobservable.evaluate(&xi, &theta, &mut g)?;
                        Ok(g)
                    })
                    .collect::<mlmodel::Result<Vec<_>>>()
            })
            .map_err(|e| state.error(py, e))?;
        let arr = ndarray::Array3::from_shape_fn((xm.nrows(), c, n_u), |(i, k, b)| {
            values[i][k * n_u + b]
        });
        Ok(arr.into_pyarray(py))
    }

    fn __repr__(&self) -> String {
        let d = &self.spec.desc;
        format!(
            "Model(inputs {:?}, {} component(s) at {} points, outputs {:?}, theta {:?}, {})",
            d.inputs,
            d.components,
            d.coordinates.len(),
            d.outputs,
            d.parameters,
            if self.spec.vectorised {
                "vectorised"
            } else {
                "one input per call"
            }
        )
    }
}

/// An `ndarray` view as a `DMatrix`.
pub(crate) fn to_matrix(a: &ndarray::ArrayView2<'_, f64>) -> DMatrix<f64> {
    DMatrix::from_fn(a.nrows(), a.ncols(), |i, j| a[[i, j]])
}
