"""Bring your own multi-level model: :class:`Model` (numpy callables and arrays),
:func:`calibrate_model` (the engine's calibration, the same code as the gate's),
:class:`ModelCalibration` (posterior, predictions with bands, draws, adequacy, save/load,
ArviZ export) and :func:`coverage` (the coverage study of your model).

Shapes (``d`` inputs, ``p`` parameters θ, ``C`` components, ``N_u`` response points,
``N_o`` outputs, ``n`` conditions):

==========================  ===========================================================
``response(x, theta)``      ``x``: ``(n, d)``, ``theta``: ``(p,)`` → ``(n, C*N_u)`` or
                            ``(n, C, N_u)`` (component blocked); one input at a time
                            (``vectorised=False``): ``x``: ``(d,)`` → ``(C*N_u,)`` or
                            ``(C, N_u)``
``offset(x, theta)``        ``b``: ``(n, N_o)`` (or ``(N_o,)`` one at a time)
``A``                       ``(N_o, C*N_u)``, columns component blocked
``coordinates``             ``(N_u,)``
experiments                 ``x``: ``(n, d)``, ``y``: ``(n, N_o)``, or a DataFrame with
                            the input and output columns by name
``truth(x, theta)``         (coverage) ``(n, N_o)`` noise-free outputs
==========================  ===========================================================
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._native import BamudiError

Progress = Callable[[str, int, int], Any]


@dataclass(frozen=True)
class Uniform:
    """A uniform prior ``U(lo, hi)`` of one dimension of θ (finite ``lo < hi``)."""

    lo: float
    hi: float


@dataclass(frozen=True)
class Normal:
    """A normal prior ``N(mean, sd²)`` of one dimension of θ (``sd > 0``)."""

    mean: float
    sd: float


@dataclass(frozen=True)
class Discrepancy:
    """The discrepancy basis (paper Eq. 15-17, 49): ``terms`` orthonormal polynomials
    (degrees ``0 .. terms-1``) of ``family`` (``legendre``, ``chebyshev``, ``hermite``) along the
    response, per component (an int: the same for every component); ``interval``: where the
    polynomials live (default: the range of the coordinates)."""

    family: str = "legendre"
    terms: Union[int, Sequence[int]] = 2
    interval: Optional[Tuple[float, float]] = None


def _prior(prior, parameters) -> Tuple[list, list, list]:
    """``(kinds, pairs, names)`` of a prior given as one distribution, a sequence of them, or a
    mapping name → distribution."""
    if isinstance(prior, Mapping):
        names = [str(k) for k in prior.keys()]
        dists = list(prior.values())
        if parameters is not None and list(parameters) != names:
            raise BamudiError(f"parameters {list(parameters)} and the prior's names {names} differ")
    else:
        dists = [prior] if isinstance(prior, (Uniform, Normal)) else list(prior)
        names = list(parameters) if parameters is not None else [f"theta_{j}" for j in range(len(dists))]
    if not dists:
        raise BamudiError("prior: at least one dimension of theta is required")
    for j, d in enumerate(dists):
        if not isinstance(d, (Uniform, Normal)):
            raise TypeError(f"prior[{j}] must be bamudi.Uniform or bamudi.Normal, not {type(d).__name__}")
    kinds = ["uniform" if isinstance(d, Uniform) else "normal" for d in dists]
    pairs = [(float(d.lo), float(d.hi)) if isinstance(d, Uniform) else (float(d.mean), float(d.sd)) for d in dists]
    return kinds, pairs, names


class Model:
    """A multi-level model of your own (paper Eq. 6-7, 15-17, 47):

    * ``response(x, theta)``: the unobservable distributed response ``g_u`` at ``coordinates``,
      ``components`` components (vectorised: all inputs ``x`` ``(n, d)`` at one ``theta``);
    * ``A`` and an optional ``offset(x, theta)``: the observable outputs ``y = A g_u + b``;
    * ``prior``: ``Uniform``/``Normal`` per dimension of θ, kinds mixed freely (one, a list, or a
      dict name → prior);
    * ``discrepancy``: the basis along the response (:class:`Discrepancy`);
    * ``inputs``/``outputs``: column names (put the units in them).

    ``vectorised=False`` calls ``response`` once per input (``x`` of shape ``(d,)``). Callbacks
    run with the GIL held, one at a time; the engine runs between them without it.
    """

    def __init__(
        self,
        response: Callable,
        *,
        coordinates,
        inputs: Sequence[str],
        outputs: Sequence[str],
        A,
        prior,
        discrepancy: Discrepancy = Discrepancy(),
        components: int = 1,
        offset: Optional[Callable] = None,
        vectorised: bool = True,
        parameters: Optional[Sequence[str]] = None,
    ):
        kinds, pairs, names = _prior(prior, parameters)
        coords = np.asarray(coordinates, dtype=np.float64)
        if coords.ndim != 1:
            raise BamudiError(f"coordinates must be 1-D (points,), got shape {coords.shape}")
        a = np.asarray(A, dtype=np.float64)
        if a.ndim != 2:
            raise BamudiError(f"A must be 2-D (outputs, components × points), got shape {a.shape}")
        terms = discrepancy.terms
        terms = [int(terms)] * int(components) if np.ndim(terms) == 0 else [int(t) for t in terms]
        if isinstance(inputs, str) or isinstance(outputs, str):
            raise TypeError("inputs and outputs must be sequences of names, not a string")
        self._native = _native.Model(
            response, [float(c) for c in coords], [str(s) for s in inputs], [str(s) for s in outputs],
            np.ascontiguousarray(a), kinds, pairs, names, discrepancy.family, terms,
            None if discrepancy.interval is None else tuple(map(float, discrepancy.interval)),
            int(components), offset, bool(vectorised),
        )

    inputs = property(lambda self: list(self._native.inputs), doc="input names")
    outputs = property(lambda self: list(self._native.outputs), doc="output names")
    parameters = property(lambda self: list(self._native.parameters), doc="names of θ's dimensions")
    coordinates = property(lambda self: np.asarray(self._native.coordinates), doc="response coordinates (N_u,)")
    components = property(lambda self: self._native.components, doc="response components C")

    def response(self, x, theta) -> np.ndarray:
        """``g_u`` at the rows of ``x`` through the engine's wrapper of your callable (its shape
        and value checks): ``(n, C, N_u)``."""
        return self._native.response(_rows(x, len(self.inputs)), [float(t) for t in np.atleast_1d(theta)])

    def __repr__(self) -> str:
        return repr(self._native)


def _rows(x, d: int, what: str = "x") -> np.ndarray:
    """``x`` as a C-contiguous float64 ``(n, d)`` array: a 1-D array is ``n`` conditions of a
    one-input model, or one condition of ``d`` inputs."""
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 0:
        arr = arr.reshape(1, 1)
    elif arr.ndim == 1:
        arr = arr.reshape(-1, 1) if d == 1 else arr.reshape(1, -1)
    if arr.ndim != 2:
        raise BamudiError(f"{what} must be 2-D (conditions, inputs) = (n, {d}), got shape {arr.shape}")
    return np.ascontiguousarray(arr)


def _experiments(model: Model, data, columns=None) -> Tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` from a pair of arrays, a DataFrame, a mapping of columns, or an array with
    ``columns`` naming the inputs and outputs."""
    inputs, outputs = model.inputs, model.outputs
    if isinstance(data, tuple) and len(data) == 2:
        x = _rows(data[0], len(inputs))
        y = np.asarray(data[1], dtype=np.float64)
        if y.ndim == 1 and len(outputs) == 1:
            y = y.reshape(-1, 1)
        if y.ndim != 2:
            raise BamudiError(f"y must be 2-D (experiments, outputs) = (n, {len(outputs)}), got shape {y.shape}")
        return x, np.ascontiguousarray(y)
    frame = None
    try:
        import pandas as pd

        if isinstance(data, pd.DataFrame):
            frame = {str(c): data[c] for c in data.columns}
    except ImportError:
        pass
    if frame is None and isinstance(data, Mapping):
        frame = dict(data)
    if frame is None:
        if columns is None:
            raise TypeError("give the experiments as (x, y), a DataFrame, a dict of columns, or an array with `columns`")
        arr = np.asarray(data, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != len(columns):
            raise BamudiError(f"data has shape {arr.shape}; expected (experiments, {len(columns)}) for columns {list(columns)}")
        frame = {str(c): arr[:, j] for j, c in enumerate(columns)}
    missing = [c for c in inputs + outputs if c not in frame]
    if missing:
        raise BamudiError(f"data: no column {missing} (the model's inputs {inputs} and outputs {outputs})")

    def stack(names):
        cols = []
        for n in names:
            try:
                cols.append(np.asarray(frame[n], dtype=np.float64))
            except (TypeError, ValueError) as e:
                raise BamudiError(f"data column `{n}` is not numeric: {e}") from None
        return np.ascontiguousarray(np.column_stack(cols))

    return stack(inputs), stack(outputs)


def _config(config) -> dict:
    if config is None:
        return {}
    if isinstance(config, Mapping):
        return {"config_json": json.dumps(config), "config_label": "config"}
    if isinstance(config, (str, os.PathLike)):
        from . import _read_toml

        text, label = _read_toml(config, "config")
        return {"config_toml": text, "config_label": label}
    raise TypeError(f"config must be a dict, TOML text or a TOML file path, not {type(config).__name__}")


def calibrate_model(
    model: Model,
    data,
    config=None,
    columns: Optional[Sequence[str]] = None,
    seed: Optional[int] = None,
    progress: Optional[Progress] = None,
) -> "ModelCalibration":
    """BA-MUDI Modules 2-3 (with the adequacy checks) of your ``model`` on ``data`` — ``(x, y)``
    arrays, a DataFrame or dict of columns named as the model's inputs and outputs, or an array
    with ``columns`` — through the engine (``bamudi::Calibrate``, the gate's code). ``config``:
    a dict, TOML text or TOML file with the keys of the engine's ``CalibrationParams``
    (``estimator``, ``coefficients``, ``sampling``, ``theta_grid_points``, ``marginal`` (only with
    the marginal mode), ...;
    ``None``: the engine's defaults, i.e. the marginal mode and the exact linear estimator (no
    training set); the paper's LSTM with ``{"estimator": {"kind": "lstm"}}``); ``seed``
    replaces its seed."""
    x, y = _experiments(model, data, columns)
    native = _native.calibrate_model(model._native, x, y, seed=seed, progress=progress, **_config(config))
    return ModelCalibration(native, model)


_STATS = ("mean", "sd", "lower", "upper")


class ModelCalibration:
    """A calibration of your model: θ's posterior, ρ, σ_ε, the adequacy verdict, Module-4
    predictions (Eq. 44, 52) with bands, joint draws, the third level (Eq. 8), ArviZ export,
    save and load."""

    def __init__(self, native, model: Optional[Model] = None):
        self._native = native
        self._model = model
        self._desc = json.loads(native.description_json())

    parameters = property(lambda self: list(self._desc["parameters"]), doc="names of θ's dimensions")
    inputs = property(lambda self: list(self._desc["inputs"]), doc="input names")
    outputs = property(lambda self: list(self._desc["outputs"]), doc="output names")
    coordinates = property(lambda self: np.asarray(self._desc["coordinates"]), doc="response coordinates (N_u,)")
    theta_mean = property(lambda self: np.asarray(self._native.theta_mean), doc="posterior mean of θ (p,)")
    theta_sd = property(lambda self: np.asarray(self._native.theta_sd), doc="posterior sd of θ (p,)")
    theta_ci95 = property(lambda self: np.asarray(self._native.theta_ci95), doc="central 95 % intervals of θ (p, 2)")
    probability_without = property(lambda self: self._native.probability_without, doc="P(no discrepancy): the weight of the fit without one in the predictions (None unless weighed)")
    rho_star = property(lambda self: self._native.rho_star, doc="ρ used by Modules 3-4 (marginal mode: its posterior mean)")
    rho_posterior = property(lambda self: self._native.rho_posterior, doc="(mean, sd) of ρ (marginal mode) or None")
    sigma_eps = property(lambda self: self._native.sigma_eps, doc="noise sd σ_ε (output units)")
    mode = property(lambda self: self._native.mode, doc="the coefficient mode")
    warnings = property(lambda self: list(self._native.warnings), doc="the posterior's warnings")

    @property
    def config(self) -> dict:
        """The checked engine configuration used (every key, defaults filled in; ``marginal``
        only in the marginal mode, whose settings it is: to change the mode of a copy, drop it)."""
        return json.loads(self._native.config_json())

    @property
    def timings(self) -> dict:
        """Seconds per stage."""
        return json.loads(self._native.timings_json())

    @property
    def adequacy(self) -> Optional[dict]:
        """The adequacy report (``verdict`` and the checks), or None when switched off."""
        text = self._native.adequacy_json()
        return None if text is None else json.loads(text)

    @property
    def verdict(self) -> Optional[str]:
        """``"adequate"``, ``"inadequate"`` or ``"not_assessed"`` (None without checks)."""
        a = self.adequacy
        return None if a is None else a["verdict"]

    def theta_cdf(self, t, j: int = 0) -> float:
        """``P(θ_j ≤ t | data)``."""
        return self._native.theta_cdf(j, float(t))

    def posterior_grid(self) -> Optional[dict]:
        """``{theta, density, cdf}`` of a one-dimensional θ's grid posterior (None for MCMC)."""
        return self._native.posterior_grid()

    def posterior_no_discrepancy(self) -> list:
        """``[(mean, sd, (lo, hi))]`` per dimension of the posterior without discrepancy
        (ρ = 1, δ = 0; the paper's Fig. 16 comparison)."""
        return self._native.no_discrepancy_summary()

    def posterior_draws(self, n: int = 4000, chains: int = 4, seed: int = 0) -> dict:
        """Posterior draws: ``theta`` ``(chains, draws, p)``, ``rho`` ``(chains, draws)``.
        A grid posterior (one θ) is sampled exactly (inverse CDF, ``n`` draws in ``chains``);
        MCMC draws are the chains themselves. ``rho_kind`` says whether ρ's draws are its
        posterior (marginal mode: ρ given θ at the nearest stored support point, truncated to
        its prior) or the point estimate ``rho_star`` repeated (the other modes)."""
        return self._native.posterior_draws(n, chains, seed)

    def _x(self, x) -> Tuple[np.ndarray, bool]:
        d = len(self.inputs)
        single = np.ndim(x) == 0 or (np.ndim(x) == 1 and d > 1)
        return _rows(x, d), single

    def predict(self, x, as_xarray: bool = False):
        """Module 4 at ``x`` (``(n, d)``; one condition as ``(d,)``, or a scalar for one input):
        ``response_*`` and ``discrepancy_*`` ``(n, C, N_u)``, ``outputs_*`` ``(n, N_o)`` for
        ``*`` in mean, sd, lower, upper (2.5 / 97.5 %); the first axis is dropped for one
        condition. ``as_xarray``: an ``xarray.Dataset`` with named dimensions."""
        xs, single = self._x(x)
        out = dict(self._native.predict(xs))
        if as_xarray:
            return _bands_dataset(self, xs, out)
        return {k: v[0] for k, v in out.items()} if single else out

    def predictive_draws(self, x, n: int = 1000, seed: int = 0) -> dict:
        """``n`` joint draws of Module 4's mixture at the rows of ``x``: ``theta`` ``(n, p)``,
        ``response`` ``(rows, n, C, N_u)``, ``outputs`` (noise-free) ``(rows, n, N_o)``."""
        xs, _ = self._x(x)
        return dict(self._native.predictive_draws(xs, n, seed))

    def predict_through(self, prediction: Callable, names: Sequence[str], x, n_draws: int = 2000, seed: int = 0) -> dict:
        """The third level (Eq. 8): joint draws of the corrected response at one condition
        ``x`` pushed through ``prediction(x, theta, response) -> (len(names),)`` (``response``
        ``(C, N_u)``); ``{mean, sd, lower, upper}`` per predicted quantity."""
        xs = np.atleast_1d(np.asarray(x, dtype=np.float64))
        return dict(self._native.predict_through(prediction, list(names), [float(v) for v in xs], n_draws, seed))

    def to_inference_data(self, x_new=None, draws: int = 1000, chains: int = 4, seed: int = 0):
        """The posterior as an ArviZ ``InferenceData``: ``posterior`` (θ by name, ``rho``),
        ``observed_data`` (``y``), ``constant_data`` (``x``, ``coordinates``), and with
        ``x_new`` the ``predictions`` group (joint draws of the response and the outputs at
        those conditions; ``predictions_constant_data`` holds ``x_new``). Needs ``arviz``
        (``pip install arviz``)."""
        return _inference_data(self, x_new, draws, chains, seed)

    def save(self, directory: Union[str, os.PathLike]) -> None:
        """Writes ``calibration.json`` (the engine's file) and ``model.json`` (names,
        coordinates, A, prior, discrepancy; not the callables) into ``directory``."""
        self._native.save(os.fspath(directory))

    @staticmethod
    def load(path: Union[str, os.PathLike], model: Optional[Model] = None) -> "ModelCalibration":
        """Reads a saved calibration (a directory, or its ``calibration.json``). Predictions
        need ``model``, which must be the calibrated model (checked)."""
        path = os.fspath(path)
        if os.path.isdir(path):
            path = os.path.join(path, "calibration.json")
        native = _native.ModelCalibration.load(path, None if model is None else model._native)
        return ModelCalibration(native, model)

    def __repr__(self) -> str:
        return repr(self._native)


def _xarray():
    try:
        import xarray as xr
    except ImportError:
        raise ImportError(
            "this export needs xarray (and arviz for InferenceData): pip install arviz"
        ) from None
    return xr


def _bands_dataset(cal: ModelCalibration, xs: np.ndarray, out: dict):
    xr = _xarray()
    comps = [f"component_{c}" for c in range(cal._desc["components"])]
    coords = {
        "condition": np.arange(xs.shape[0]),
        "component": comps,
        "point": np.arange(len(cal.coordinates)),
        "output": cal.outputs,
        "input": cal.inputs,
    }
    data = {"x": (("condition", "input"), xs), "coordinate": (("point",), cal.coordinates)}
    for stat in _STATS:
        data[f"response_{stat}"] = (("condition", "component", "point"), out[f"response_{stat}"])
        data[f"discrepancy_{stat}"] = (("condition", "component", "point"), out[f"discrepancy_{stat}"])
        data[f"outputs_{stat}"] = (("condition", "output"), out[f"outputs_{stat}"])
    return xr.Dataset(data, coords=coords, attrs={"bands": "2.5 % / 97.5 % (Module 4, Eq. 44 and 52)"})


def _inference_data(cal: ModelCalibration, x_new, draws: int, chains: int, seed: int):
    try:
        import arviz as az
    except ImportError:
        raise ImportError(
            "to_inference_data needs ArviZ: pip install arviz (an optional dependency of bamudi)"
        ) from None
    xr = _xarray()
    d = cal.posterior_draws(draws, chains, seed)
    theta, rho = d["theta"], d["rho"]
    c, k = rho.shape
    dims = {"chain": np.arange(c), "draw": np.arange(k)}
    post = {name: (("chain", "draw"), theta[:, :, j]) for j, name in enumerate(cal.parameters)}
    post["rho"] = (("chain", "draw"), rho)
    attrs = {
        "inference_library": "bamudi",
        "inference_library_version": _native.__version__,
        "theta_method": d["method"],
        "rho_kind": d["rho_kind"],
        "coefficient_mode": cal.mode,
    }
    groups = {"posterior": xr.Dataset(post, coords=dims, attrs=attrs)}
    xe = cal._native.x_experiments()
    ye = cal._native.y_experiments()
    exp = {"experiment": np.arange(xe.shape[0])}
    groups["constant_data"] = xr.Dataset(
        {
            "x": (("experiment", "input"), xe),
            "coordinate": (("point",), cal.coordinates),
        },
        coords={**exp, "input": cal.inputs, "point": np.arange(len(cal.coordinates))},
    )
    if ye is not None:
        groups["observed_data"] = xr.Dataset(
            {"y": (("experiment", "output"), ye)}, coords={**exp, "output": cal.outputs}
        )
    if x_new is not None:
        xs, _ = cal._x(x_new)
        p = cal.predictive_draws(xs, n=draws, seed=seed)
        comps = [f"component_{i}" for i in range(cal._desc["components"])]
        # one chain of joint draws, conditions along their own dimension
        groups["predictions"] = xr.Dataset(
            {
                "response": (("chain", "draw", "condition", "component", "point"),
                             np.moveaxis(p["response"], 0, 1)[None]),
                "outputs": (("chain", "draw", "condition", "output"), np.moveaxis(p["outputs"], 0, 1)[None]),
            },
            coords={"chain": [0], "draw": np.arange(p["response"].shape[1]),
                    "condition": np.arange(xs.shape[0]), "component": comps,
                    "point": np.arange(len(cal.coordinates)), "output": cal.outputs},
        )
        groups["predictions_constant_data"] = xr.Dataset(
            {"x": (("condition", "input"), xs)},
            coords={"condition": np.arange(xs.shape[0]), "input": cal.inputs},
        )
    return az.InferenceData(**groups)


def coverage(
    model: Model,
    truth: Callable,
    x,
    noise_sd,
    replicates: int = 20,
    config=None,
    seed: int = 0,
    levels: Sequence[float] = (0.5, 0.8, 0.9, 0.95),
    bins: int = 10,
    progress: Optional[Progress] = None,
) -> dict:
    """The coverage study of your model (simulation-based calibration): per replicate, θ* is
    drawn from the model's prior, the data are ``truth(x, θ*)`` (``(n, N_o)``, noise-free)
    plus Gaussian noise of ``noise_sd`` (output units; one value or one per output), the
    engine calibrates them with ``config``, and the truth's posterior transform
    ``P(θ ≤ θ* | data)`` scores the central intervals at ``levels`` (hits, exact 95 %
    intervals, the 1 % binomial acceptance region) and the SBC rank histogram (``bins``,
    χ² p-value). Seeds derive from ``seed``. Returns the report (``replicates``,
    ``dimensions``, ``failed``)."""
    xs = _rows(x, len(model.inputs))
    text = _native.coverage(
        model._native, truth, xs, [float(s) for s in np.atleast_1d(noise_sd)], replicates,
        seed=seed, levels=[float(v) for v in levels], bins=bins, progress=progress, **_config(config),
    )
    return json.loads(text)
