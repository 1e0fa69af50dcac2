"""bamudi: Bayesian calibration of multi-level models with unobservable distributed response
(BA-MUDI), on a navigation-lock miter gate.

The numbers come from the same Rust functions as the ``bamudi`` command line: for the same
inputs and seed, Python and the command line give the same results, and every refused input
raises :class:`BamudiError` with the command line's message. Long computations release the
GIL (threads can calibrate at once) and report progress through an optional callback
``progress(stage, done, total)``; diagnostics go to :mod:`logging`.

Units: inches (in), pounds-force per inch (lbf/in), microstrain.

>>> import bamudi
>>> gate = bamudi.Gate(element_size=60.0)            # the embedded default gate, coarse mesh
>>> exps = bamudi.simulate_experiments(gate, scenario=1, n=60, seed=1)
>>> cal = bamudi.calibrate(gate, exps, {"gap_prior": [81.0, 105.0],
...                                     "calibration": {"estimator": {"kind": "exact_linear"}}})
>>> lo, hi = cal.theta_ci95
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._native import BamudiError, Gate
from .models import (
    Discrepancy,
    Model,
    ModelCalibration,
    Normal,
    Uniform,
    calibrate_model,
    coverage,
)

__all__ = [
    "BamudiError",
    "Calibration",
    "Discrepancy",
    "Experiments",
    "FieldRecord",
    "Gate",
    "Model",
    "ModelCalibration",
    "Normal",
    "Uniform",
    "calibrate",
    "calibrate_model",
    "close_loop",
    "coverage",
    "simulate_experiments",
    "simulate_field",
]
__version__ = _native.__version__

Progress = Callable[[str, int, int], Any]


def _has_pandas() -> bool:
    try:
        import pandas  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class Experiments:
    """Experiments: ``columns`` (``h_up``, ``h_down`` in inches, then one per gauge in
    microstrain) and ``data``, a float64 array of shape ``(n, len(columns))``."""

    columns: Tuple[str, ...]
    data: np.ndarray

    def to_frame(self):
        """The experiments as a pandas DataFrame (needs pandas)."""
        import pandas as pd

        return pd.DataFrame(self.data, columns=list(self.columns))

    def to_csv(self) -> str:
        """The CSV text ``bamudi simulate experiments`` writes for these experiments (the same
        Rust function: exact values, the same digits)."""
        return _native.experiments_csv(list(self.columns), np.ascontiguousarray(self.data, dtype=np.float64))


@dataclass(frozen=True)
class FieldRecord:
    """A field record: ``csv`` (the text ``bamudi simulate field`` writes, rounded as there),
    ``columns`` and ``data`` (float64, NaN where missing, the time column left out),
    ``time_unix_s`` (int64 seconds since 1970) and the true gap ``gap_in`` per row."""

    csv: str
    columns: Tuple[str, ...]
    data: np.ndarray
    time_unix_s: np.ndarray
    gap_in: np.ndarray

    def to_frame(self):
        """The record as a pandas DataFrame indexed by UTC time (needs pandas)."""
        import pandas as pd

        index = pd.to_datetime(self.time_unix_s, unit="s", utc=True)
        return pd.DataFrame(self.data, columns=list(self.columns), index=index)


def simulate_experiments(
    gate: Gate,
    scenario: int,
    n: int = 500,
    noise_sd: float = 1.0,
    seed: Optional[int] = None,
    reality: Optional[Union[str, os.PathLike]] = None,
    as_frame: bool = False,
):
    """The paper's synthetic experiments of ``scenario`` (1: true gap 90 in, 2: 150 in):
    ``n`` random water levels, Gaussian noise of ``noise_sd`` microstrain, seeded by ``seed``
    (default: the scenario number, as on the command line); ``reality`` is a TOML file whose
    truth departs from the gate (docs/reality.md). Returns :class:`Experiments`, or a pandas
    DataFrame when ``as_frame``."""
    columns, data = _native.simulate_experiments(
        gate, scenario, n, noise_sd, seed, _path(reality)
    )
    exps = Experiments(tuple(columns), data)
    return exps.to_frame() if as_frame else exps


def simulate_field(
    gate: Gate,
    days: float = 60.0,
    step_minutes: float = 60.0,
    effects: Sequence[str] = ("none",),
    gap: float = 90.0,
    final_gap: Optional[float] = None,
    noise_sd: float = 1.0,
    missing: Optional[float] = None,
    seed: Optional[int] = None,
    reality: Optional[Union[str, os.PathLike]] = None,
) -> FieldRecord:
    """A field record of ``days`` (a row every ``step_minutes``) with the gate (or a reality)
    as the truth and the named ``effects`` switched on (thermal, drift, offset-jump,
    gap-growth, hysteresis, wall-flexure, none; ``none`` alone, each at most once);
    ``final_gap`` (in, default 130) only with ``gap-growth``; as ``bamudi simulate field``."""
    if isinstance(effects, str):
        effects = [effects]
    d = _native.simulate_field(
        gate, days, step_minutes, list(effects), gap, final_gap, noise_sd, missing, seed,
        _path(reality),
    )
    return FieldRecord(
        d["csv"], tuple(d["columns"]), d["data"], d["time_unix_s"], d["gap_in"]
    )


class Calibration:
    """A calibrated gate: the gap posterior, ρ*, σ_ε, the adequacy verdict, and Module-4
    predictions. Save it with :meth:`save` (the files of ``bamudi calibrate``, readable by
    ``bamudi predict``) and read it back with :meth:`load`."""

    def __init__(self, native: "_native.Calibration"):
        self._native = native

    theta_mean = property(lambda self: self._native.theta_mean, doc="posterior mean of the gap (in)")
    theta_sd = property(lambda self: self._native.theta_sd, doc="posterior sd of the gap (in)")
    theta_ci95 = property(lambda self: self._native.theta_ci95, doc="central 95 % interval of the gap (in)")
    probability_without = property(lambda self: self._native.probability_without, doc="P(no discrepancy): the weight of the fit without one in the predictions (None unless weighed)")
    rho_star = property(lambda self: self._native.rho_star, doc="Module-2 scale ρ* (Eq. 30)")
    sigma_eps = property(lambda self: self._native.sigma_eps, doc="noise sd σ_ε (microstrain)")
    gap_prior = property(lambda self: self._native.gap_prior, doc="uniform gap prior (lo, hi) in inches")
    gauge_names = property(lambda self: list(self._native.gauge_names), doc="the strain outputs")
    z_in = property(lambda self: self._native.z_in, doc="quoin points of the force predictions (in)")

    @property
    def adequacy(self) -> Optional[dict]:
        """The adequacy report (``verdict`` ``adequate`` or ``inadequate`` and the failed
        checks), as in ``results.json``; ``None`` when the checks were switched off."""
        text = self._native.adequacy_json()
        return None if text is None else json.loads(text)

    @property
    def tolerances(self) -> list:
        """The declared build tolerances (``[[tolerances]]`` of the configuration, marginal mode)
        with what the data say of each: ``[{"name", "mean", "sd"}]``, the posterior mean and sd
        of the build's deviation in the tolerance's own standard deviations (prior N(0, 1)), as
        in ``results.json``; ``[]`` when none were declared."""
        return json.loads(self._native.tolerances_json())

    @property
    def warnings(self) -> list:
        """The posterior's warnings (mass at a prior bound, an under-resolved interval), as the
        command line prints them; also logged (``logging``) when the calibration ends."""
        return list(self._native.warnings)

    @property
    def verdict(self) -> Optional[str]:
        """``"adequate"`` or ``"inadequate"`` (``None`` without checks)."""
        a = self.adequacy
        return None if a is None else a["verdict"]

    def predict(self, h_up, h_down) -> dict:
        """Module 4 at the water levels (in; scalars or equal-length arrays): a dict of arrays
        ``strain_{mean,sd,lower,upper}`` (per gauge, microstrain) and
        ``normal_*`` / ``tangential_*`` (per quoin point of :attr:`z_in`, lbf/in); one row per
        condition, or 1-D arrays for scalar levels. The bands are 2.5 / 97.5 % quantiles."""
        scalar = np.ndim(h_up) == 0 and np.ndim(h_down) == 0
        hu = np.atleast_1d(np.asarray(h_up, dtype=np.float64))
        hd = np.atleast_1d(np.asarray(h_down, dtype=np.float64))
        out = self._native.predict(np.ascontiguousarray(hu), np.ascontiguousarray(hd))
        return {k: v[0] for k, v in out.items()} if scalar else dict(out)

    def save(self, directory: Union[str, os.PathLike]) -> None:
        """Writes ``calibration.json`` and ``model.json`` into ``directory`` (created)."""
        self._native.save(os.fspath(directory))

    @staticmethod
    def load(path: Union[str, os.PathLike], model: Optional[Union[str, os.PathLike]] = None) -> "Calibration":
        """Reads a calibration: a directory holding ``calibration.json`` and ``model.json``
        (as written by :meth:`save` or ``bamudi calibrate``), or the calibration file itself
        (``model`` beside it unless given)."""
        path = os.fspath(path)
        if os.path.isdir(path):
            path = os.path.join(path, "calibration.json")
        return Calibration(_native.Calibration.load(path, _path(model)))

    def __repr__(self) -> str:
        return repr(self._native)


def _path(p) -> Optional[str]:
    return None if p is None else os.fspath(p)


def _read_toml(value, what: str) -> Tuple[str, str]:
    """``(text, label)`` of TOML given as a file path (``os.PathLike``, or a one-line string
    ending in ``.toml``) or as text; a path that cannot be read as UTF-8 text is an error
    naming it (and the line of a bad byte)."""
    if isinstance(value, os.PathLike) or (
        isinstance(value, str) and "\n" not in value and value.strip().endswith(".toml")
    ):
        path = os.fspath(value)
        # read as the command line reads its files: a missing file, a directory, a link loop
        # or a byte that is not UTF-8 (with its line) raise BamudiError naming `what` and path
        return _native.read_input_text(what, path), path
    if isinstance(value, str):
        return value, what
    raise TypeError(f"{what} must be TOML text or a TOML file path, not {type(value).__name__}")


def _config_args(config) -> dict:
    """The configuration as the native call takes it: a dict (JSON), TOML text, or a path to
    a TOML file (the file of ``bamudi calibrate --config``)."""
    if isinstance(config, Mapping):
        return {"config_json": json.dumps(config), "config_label": "config"}
    if not isinstance(config, (str, os.PathLike)):
        raise TypeError(f"config must be a dict, TOML text or a TOML file path, not {type(config).__name__}")
    text, label = _read_toml(config, "config")
    return {"config_toml": text, "config_label": label}


def _numeric_columns(names, columns) -> np.ndarray:
    """The columns as one float64 array; a column that is not numeric is an error naming it."""
    out = []
    for name, col in zip(names, columns):
        try:
            out.append(np.asarray(col, dtype=np.float64))
        except (TypeError, ValueError) as e:
            raise BamudiError(f"data column `{name}` is not numeric: {e}") from None
    return np.ascontiguousarray(np.column_stack(out))


def _table(data, columns) -> Tuple[list, np.ndarray]:
    """Columns and a float64 C-contiguous 2-D array from Experiments, a DataFrame, a mapping
    of columns, or an array with ``columns``."""
    if isinstance(data, Experiments):
        return list(data.columns), np.ascontiguousarray(data.data, dtype=np.float64)
    if _has_pandas():
        import pandas as pd

        if isinstance(data, pd.DataFrame):
            names = [str(c) for c in data.columns]
            return names, _numeric_columns(names, [data[c] for c in data.columns])
    if isinstance(data, Mapping):
        names = list(data.keys())
        return names, _numeric_columns(names, [data[k] for k in names])
    arr = np.asarray(data, dtype=np.float64)
    if columns is None:
        raise TypeError("an array needs `columns` (h_up, h_down and the gauge names)")
    if arr.ndim != 2:
        raise BamudiError(f"data must be a 2-D array (rows x columns), got {arr.ndim} dimension(s)")
    return list(columns), np.ascontiguousarray(arr)


def calibrate(
    gate: Union[Gate, Model],
    data,
    config=None,
    columns: Optional[Sequence[str]] = None,
    seed: Optional[int] = None,
    progress: Optional[Progress] = None,
    label: str = "data",
):
    """BA-MUDI Modules 2-3. With a :class:`Model` of your own: :func:`calibrate_model`
    (``data``: ``(x, y)`` arrays or a DataFrame; ``config``: the engine's keys, optional),
    returning a :class:`ModelCalibration`. With a gate: on ``gate`` from experiments ``data`` (:class:`Experiments`, a
    pandas DataFrame, a dict of columns, or a 2-D array with ``columns``: ``h_up``, ``h_down``
    in inches and one column per gauge in microstrain). ``config`` is a dict, TOML text or the
    path of a TOML file with the keys of ``bamudi calibrate --config`` (``gap_prior``,
    ``discrepancy_terms``, ``calibration``); ``seed`` replaces its seed; ``label`` names the
    data in messages (an error at row ``i`` says ``line i + 2``, as in a CSV file with its
    header on line 1)."""
    if isinstance(gate, Model):
        return calibrate_model(gate, data, config, columns=columns, seed=seed, progress=progress)
    if config is None:
        raise TypeError("calibrate(gate, data, config): a gate's calibration needs its config (gap_prior, ...)")
    names, arr = _table(data, columns)
    native = _native.calibrate(
        gate, names, arr, seed=seed, progress=progress, data_label=label, **_config_args(config)
    )
    return Calibration(native)


def close_loop(
    gate: Gate,
    record,
    gap_prior: Tuple[float, float] = (40.0, 200.0),
    max_experiments: int = 240,
    gauge_noise_sd: Optional[float] = None,
    config: Optional[str] = None,
    calibration_config: Optional[str] = None,
    holdout_fraction: Optional[float] = None,
    test_fraction: Optional[float] = None,
    impute: bool = False,
    seed: Optional[int] = None,
    progress: Optional[Progress] = None,
    tolerances: Optional[list] = None,
) -> dict:
    """Closes the loop on a field record (:class:`FieldRecord`, or the path of a field CSV):
    finds, adds and reports the effects the calibration misses, as ``bamudi close-loop``.
    ``config`` and ``calibration_config`` are TOML texts or file paths; ``tolerances`` the
    declared build tolerances (``[{"key": ..., "relative_sd": ...}]``, as in ``calibrate``),
    which every calibration of the loop integrates out. Returns the loop's
    report as a dict: the command line's ``results.json`` without its ``record_fatigue`` part
    (the quoin block's fatigue over the record); with ``tolerances``, its ``"tolerances"`` key
    gives what the final calibration read of each (``[{"name", "mean", "sd"}]`` in their own
    sds); ``"warnings"`` (when any) says when the final gap posterior is pressed against a
    bound of ``gap_prior`` and which bound to widen (also logged)."""
    if isinstance(record, FieldRecord):
        source = {"csv": record.csv, "label": "record"}
    else:
        source = {"path": os.fspath(record)}  # read and checked as `close-loop --data`
    text = _native.close_loop(
        gate, **source, gap_prior=tuple(gap_prior), max_experiments=max_experiments,
        gauge_noise_sd=gauge_noise_sd, config_toml=_text(config, "config"),
        calibration_toml=_text(calibration_config, "calibration_config"), holdout_fraction=holdout_fraction,
        test_fraction=test_fraction, impute=impute, seed=seed, progress=progress,
        tolerances_json=None if tolerances is None else json.dumps(tolerances),
    )
    return json.loads(text)


def _text(t: Optional[Union[str, os.PathLike]], what: str) -> Optional[str]:
    return None if t is None else _read_toml(t, what)[0]
