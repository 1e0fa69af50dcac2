"""Bring your own model: the engine's analytic example written as numpy callables gives the
Rust example's numbers; the API's shapes, save/load, draws, threads; every error names the
argument and the expected shape."""

import json
import math
import os
import pathlib
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

import bamudi
from conftest import REPO

sys.path.insert(0, str(REPO / "python" / "examples"))
import analytic  # noqa: E402  (the example file: the model, the data and the configuration)


@pytest.fixture(scope="module")
def data():
    return analytic.experiments()


@pytest.fixture(scope="module")
def cal(data):
    return bamudi.calibrate(analytic.model, data, analytic.CONFIG)


def rust_example():
    """The Rust example's numbers at full precision (`analytic --json`; `cargo test
    --workspace` builds the example before CI runs this suite)."""
    exe = os.environ.get("BAMUDI_ANALYTIC") or str(REPO / "target" / "debug" / "examples" / "analytic")
    if not os.path.isfile(exe):
        pytest.fail(f"no analytic example at {exe}: run `cargo build -p bamudi --example analytic` or set BAMUDI_ANALYTIC")
    out = subprocess.run([exe, "--json"], capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def rel(a, b):
    return np.max(np.abs(np.asarray(a) - np.asarray(b)) / np.abs(np.asarray(b)))


# The C library's exp, the Rust example's `f64::exp`. numpy's `np.exp` is its own SIMD routine on
# machines with AVX-512 and differs from it in the last bit at a few of the 21 points (measured:
# 1-2 points per θ, 5 of A's 126 entries); the engine's optimisers (GP fits, the ρ search) turn
# that into a few 1e-6 of θ's posterior mean (3.8e-6 measured on such a machine). The
# bit-for-bit check below therefore builds the example with this exp.
LIBM_EXP = np.vectorize(math.exp, otypes=[float])


@pytest.fixture(scope="module")
def cal_libm():
    a = analytic.sensor_matrix(LIBM_EXP)
    model = bamudi.Model(lambda x, theta: x[:, :1] * LIBM_EXP(-theta[0] * analytic.POINTS)[None, :],
                         coordinates=analytic.POINTS, inputs=["load_kn_per_m"],
                         outputs=analytic.model.outputs, A=a,
                         prior={"decay_per_m": bamudi.Uniform(0.5, 3.0)},
                         discrepancy=bamudi.Discrepancy("legendre", terms=2, interval=(0.0, 1.0)))
    return bamudi.calibrate(model, analytic.experiments(exp=LIBM_EXP), analytic.CONFIG)


def test_the_example_with_numpys_exp_is_the_rust_examples_posterior_to_the_optimisers_tolerance(cal):
    """The example as shipped (numpy's exp). Where numpy's exp is the C library's, this is the
    bit-for-bit case below; where it is not, a last-bit difference of the data reaches θ
    through the optimisers: 1e-4 relative is 25x the 3.8e-6 measured on an AVX-512 machine and
    0.08 of θ's posterior sd (0.002 at 1.6), so a real disagreement (a different posterior)
    still fails. (This bound replaced the 1e-9 one that failed on an AVX-512 machine; the 1e-9
    claim is kept, with the exp it needs, in the next test.)"""
    rust = rust_example()
    (lo, hi), = cal.theta_ci95
    ours = [cal.theta_mean[0], cal.theta_sd[0], lo, hi]
    assert rel(ours, rust["theta"]) < 1e-4, (ours, rust["theta"])
    assert rel(cal.rho_star, rust["rho_star"]) < 1e-4


def test_the_analytic_example_as_numpy_callables_is_the_rust_examples_posterior(cal_libm):
    rust = rust_example()
    cal = cal_libm
    (lo, hi), = cal.theta_ci95
    ours = [cal.theta_mean[0], cal.theta_sd[0], lo, hi]
    assert rel(ours, rust["theta"]) < 1e-9, (ours, rust["theta"])
    assert rel(cal.rho_star, rust["rho_star"]) < 1e-9
    assert rel(cal.sigma_eps, rust["sigma_eps"]) < 1e-9
    band = cal.predict(5.0)
    assert rel(band["response_mean"][0], rust["load_mean"]) < 1e-9
    assert rel([band["response_lower"][0, 10], band["response_upper"][0, 10]], rust["load_band"]) < 1e-9

    def peak_and_resultant(x, theta, q):
        return [q[0].max(), np.sum(0.05 * 0.5 * (q[0, 1:] + q[0, :-1]))]

    p = cal.predict_through(peak_and_resultant, ["peak", "resultant"], [5.0], 2000, 7)
    assert rel([p["mean"][1], p["lower"][1], p["upper"][1]], rust["resultant"]) < 1e-9


def test_one_input_per_call_gives_the_vectorised_posterior(data, cal):
    calls = []

    def one(x, theta):
        calls.append(x.shape)
        return x[0] * np.exp(-theta[0] * analytic.POINTS)

    m = bamudi.Model(one, coordinates=analytic.POINTS, inputs=["load_kn_per_m"],
                     outputs=analytic.model.outputs, A=analytic.A,
                     prior={"decay_per_m": bamudi.Uniform(0.5, 3.0)},
                     discrepancy=bamudi.Discrepancy("legendre", 2, (0.0, 1.0)), vectorised=False)
    c = bamudi.calibrate(m, data, analytic.CONFIG)
    assert set(calls) == {(1,)}
    np.testing.assert_allclose(c.theta_mean, cal.theta_mean, rtol=1e-12)
    np.testing.assert_allclose(c.theta_sd, cal.theta_sd, rtol=1e-9)


def test_shapes_of_predictions_draws_and_the_model(cal):
    x = np.array([[2.0], [5.0], [8.0]])
    p = cal.predict(x)
    assert p["response_mean"].shape == (3, 1, 21) and p["discrepancy_sd"].shape == (3, 1, 21)
    assert p["outputs_upper"].shape == (3, 6)
    assert np.all(p["outputs_lower"] <= p["outputs_upper"])
    d = cal.posterior_draws(n=400, chains=4, seed=3)
    assert d["theta"].shape == (4, 100, 1) and d["rho"].shape == (4, 100)
    assert d["rho_kind"] == "point estimate" and np.all(d["rho"] == cal.rho_star)
    assert abs(d["theta"].mean() - cal.theta_mean[0]) < 4 * cal.theta_sd[0] / np.sqrt(400)
    assert np.array_equal(cal.posterior_draws(n=400, seed=3)["theta"], d["theta"])  # seeded
    dr = cal.predictive_draws(x, n=50, seed=1)
    assert dr["response"].shape == (3, 50, 1, 21) and dr["outputs"].shape == (3, 50, 6)
    # the outputs are A response (no offset) draw by draw
    np.testing.assert_allclose(dr["outputs"][1], dr["response"][1, :, 0, :] @ analytic.A.T, rtol=1e-12)
    g = analytic.model.response(x, [1.6])
    assert g.shape == (3, 1, 21)
    np.testing.assert_allclose(g[:, 0, :], analytic.strip_load(x, np.array([1.6])))
    assert cal.verdict in ("adequate", "inadequate", "not_assessed")
    assert cal.config["theta_grid_points"] == 121 and cal.mode == "conditional_on_theta"


def test_dataframe_and_arrays_give_the_same_calibration(data, cal):
    pd = pytest.importorskip("pandas")
    x, y = data
    frame = pd.DataFrame(np.column_stack([y, x]), columns=analytic.model.outputs + ["load_kn_per_m"])
    c = bamudi.calibrate(analytic.model, frame, analytic.CONFIG)
    assert c.theta_mean[0] == cal.theta_mean[0]


def test_save_and_load(tmp_path, cal):
    cal.save(tmp_path)
    desc = json.loads((tmp_path / "model.json").read_text())
    assert desc["parameters"] == ["decay_per_m"] and len(desc["a"]) == 6
    bare = bamudi.ModelCalibration.load(tmp_path)
    assert bare.theta_mean[0] == cal.theta_mean[0] and bare.rho_star == cal.rho_star
    with pytest.raises(bamudi.BamudiError, match="loaded without its model"):
        bare.predict(5.0)
    again = bamudi.ModelCalibration.load(tmp_path, model=analytic.model)
    np.testing.assert_array_equal(again.predict(5.0)["response_mean"], cal.predict(5.0)["response_mean"])
    other = bamudi.Model(analytic.strip_load, coordinates=analytic.POINTS, inputs=["load_kn_per_m"],
                         outputs=analytic.model.outputs, A=analytic.A,
                         prior={"decay_per_m": bamudi.Uniform(0.5, 4.0)},
                         discrepancy=bamudi.Discrepancy("legendre", 2, (0.0, 1.0)))
    with pytest.raises(bamudi.BamudiError, match="its prior differs"):
        bamudi.ModelCalibration.load(tmp_path, model=other)


def test_the_marginal_mode_gives_rho_draws_and_a_verdict(data):
    config = {"estimator": {"kind": "exact_linear"}, "sampling": {"noise_sd": 0.002}, "theta_grid_points": 121}
    c = bamudi.calibrate(analytic.model, data, config, seed=5)
    assert c.mode == "marginal" and c.rho_posterior is not None
    d = c.posterior_draws(n=2000, seed=1)
    assert d["rho_kind"] == "posterior"
    lo, hi = c.config["sampling"]["rho_range"]
    assert np.all((d["rho"] >= lo) & (d["rho"] <= hi))
    mean, sd = c.rho_posterior
    assert abs(d["rho"].mean() - mean) < 0.1 * sd + 4 * sd / np.sqrt(2000)
    assert c.verdict in ("adequate", "inadequate")
    # the default weighs the calibrations with and without a discrepancy by their evidence;
    # assumed, or in another mode, there is no such weight
    assert 0.0 <= c.probability_without <= 1.0
    assumed = bamudi.calibrate(analytic.model, data, {**config, "marginal": {"presence": "assumed"}}, seed=5)
    assert assumed.probability_without is None
    assert assumed.theta_mean[0] == c.theta_mean[0]  # the gap's posterior is not weighed
    # the marginal mode's settings are its own: beside another mode they are refused, naming them
    other = {**config, "coefficients": "prior_marginal", "marginal": {"presence": "assumed"}}
    with pytest.raises(bamudi.BamudiError, match=r"\[marginal\] settings belong"):
        bamudi.calibrate(analytic.model, data, other, seed=5)


def test_two_threads_calibrate_with_callbacks_at_once(data, cal):
    results, errors = [None, None], []

    def work(k):
        try:
            results[k] = bamudi.calibrate(analytic.model, data, analytic.CONFIG).theta_mean[0]
        except Exception as e:  # noqa: BLE001
            errors.append(e)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not any(t.is_alive() for t in threads), "a calibration hung"
    assert not errors and results == [cal.theta_mean[0]] * 2


def test_arviz_export(cal, data):
    az = pytest.importorskip("arviz")
    idata = cal.to_inference_data(x_new=[[2.0], [5.0]], draws=200, chains=2, seed=4)
    assert isinstance(idata, az.InferenceData)
    post = idata.posterior
    assert post["decay_per_m"].shape == (2, 100) and post["rho"].shape == (2, 100)
    assert post.attrs["theta_method"] == "grid"
    np.testing.assert_array_equal(idata.observed_data["y"].values, data[1])
    assert idata.predictions["response"].shape == (1, 200, 2, 1, 21)
    assert idata.predictions["outputs"].shape == (1, 200, 2, 6)
    s = az.summary(idata, var_names=["decay_per_m"])
    assert abs(s["mean"].iloc[0] - cal.theta_mean[0]) < 0.001
    bands = cal.predict([[2.0], [5.0]], as_xarray=True)
    assert bands["response_mean"].dims == ("condition", "component", "point")
    assert bands["outputs_upper"].sel(output="sensor_3").shape == (2,)


def test_arviz_missing_is_a_clear_message(cal, monkeypatch):
    monkeypatch.setitem(sys.modules, "arviz", None)
    with pytest.raises(ImportError, match="pip install arviz"):
        cal.to_inference_data()


def test_coverage_study_of_a_user_model():
    # the truth is the model itself (no discrepancy): the marginal mode's intervals, which
    # allow for one, may be conservative but must not be over-confident (hits at or above the
    # 1 % binomial acceptance region's lower end at every level)
    x = np.linspace(1.0, 10.0, 25).reshape(-1, 1)

    def truth(x, theta):
        return analytic.strip_load(x, theta) @ analytic.A.T

    config = {"estimator": {"kind": "exact_linear"}, "sampling": {"noise_sd": 0.002},
              "theta_grid_points": 81, "adequacy": {"enabled": False}}
    r = bamudi.coverage(analytic.model, truth, x, noise_sd=0.002, replicates=12, config=config, seed=11)
    assert r["failed"] == 0 and len(r["replicates"]) == 12
    thetas = np.array([rep["theta_true"][0] for rep in r["replicates"]])
    assert np.all((thetas >= 0.5) & (thetas <= 3.0)) and len(set(thetas)) == 12
    dim = r["dimensions"][0]
    assert dim["parameter"] == "decay_per_m" and sum(dim["rank_counts"]) == 12
    for level in dim["levels"]:
        assert level["hits"] >= level["acceptance"][0], level
    pits = np.array([rep["pit"][0] for rep in r["replicates"]])
    assert np.all((pits >= 0.0) & (pits <= 1.0))
    again = bamudi.coverage(analytic.model, truth, x, noise_sd=0.002, replicates=12, config=config, seed=11)
    assert [a["pit"] for a in again["replicates"]] == [a["pit"] for a in r["replicates"]]


# ---------------------------------------------------------------- errors


def model_with(response, **over):
    kw = dict(coordinates=analytic.POINTS, inputs=["load_kn_per_m"], outputs=analytic.model.outputs,
              A=analytic.A, prior={"decay_per_m": bamudi.Uniform(0.5, 3.0)})
    kw.update(over)
    return bamudi.Model(response, **kw)


def expect(fragment, fn, *args, **kwargs):
    with pytest.raises(bamudi.BamudiError) as e:
        fn(*args, **kwargs)
    assert fragment in str(e.value), str(e.value)
    return e.value


def test_a_callback_of_the_wrong_shape_names_the_expected_one(data):
    bad = model_with(lambda x, t: np.zeros((x.shape[0], 20)))
    expect("`response` returned shape (40, 20) at 40 inputs x, theta = [", bamudi.calibrate, bad, data, analytic.CONFIG)
    e = expect("expected (40, 21) or (40, 1, 21) (inputs, components × points)", bamudi.calibrate, bad, data,
               analytic.CONFIG)
    assert e.__cause__ is None
    one = model_with(lambda x, t: np.zeros(3), vectorised=False)
    expect("expected (21,) or (1, 21) (components × points)", bamudi.calibrate, one, data, analytic.CONFIG)
    text = model_with(lambda x, t: "load")
    expect("`response` returned a str, not an array of numbers", bamudi.calibrate, text, data, analytic.CONFIG)


def test_nan_from_a_callback_names_the_input_and_theta(data):
    def nan_at_7(x, theta):
        q = analytic.strip_load(x, theta)
        q[x[:, 0] > 7.0, 3] = np.nan
        return q

    e = expect("`response` returned NaN at input row", bamudi.calibrate, model_with(nan_at_7), data, analytic.CONFIG)
    assert "theta = [" in str(e) and "value 3 of the row's 21" in str(e)
    offset = model_with(analytic.strip_load, offset=lambda x, t: np.full((x.shape[0], 6), np.inf))
    expect("`offset` returned inf", bamudi.calibrate, offset, data, analytic.CONFIG)


def test_a_raising_callback_is_reported_with_its_traceback_and_nothing_hangs(data):
    def deep(theta):
        if theta[0] > 1.0:
            raise ValueError(f"no load model beyond decay 1 (got {theta[0]})")

    def raising(x, theta):
        deep(theta)
        return analytic.strip_load(x, theta)

    start = time.perf_counter()
    e = expect("`response` raised ValueError: no load model beyond decay 1", bamudi.calibrate, model_with(raising),
               data, analytic.CONFIG)
    assert time.perf_counter() - start < 60
    msg = str(e)
    assert "Traceback (most recent call last)" in msg and "in deep" in msg and "theta = [" in msg
    assert isinstance(e.__cause__, ValueError)
    # the calibration's predictions report a raising callback the same way
    flaky = {"on": False}

    def sometimes(x, theta):
        if flaky["on"]:
            raise RuntimeError("sensor model offline")
        return analytic.strip_load(x, theta)

    c = bamudi.calibrate(model_with(sometimes), data, analytic.CONFIG)
    flaky["on"] = True
    expect("`response` raised RuntimeError: sensor model offline", c.predict, 5.0)
    flaky["on"] = False
    assert c.predict(5.0)["response_mean"].shape == (1, 21)  # a new run after a failed one


def test_prior_errors_name_the_dimension():
    expect("prior[0] (decay_per_m): Uniform(lo, hi) needs finite lo < hi, got (0.5, inf)", model_with,
           analytic.strip_load, prior={"decay_per_m": bamudi.Uniform(0.5, float("inf"))})
    expect("prior[1] (b): Uniform(lo, hi) needs finite lo < hi, got (3, 1)", model_with, analytic.strip_load,
           prior={"a": bamudi.Uniform(0.0, 1.0), "b": bamudi.Uniform(3.0, 1.0)})
    expect("Normal(mean, sd) needs a finite mean and a finite sd > 0, got (NaN, 1)", model_with,
           analytic.strip_load, prior=[bamudi.Normal(float("nan"), 1.0)])
    expect("Normal(mean, sd) needs a finite mean and a finite sd > 0, got (1, 0)", model_with,
           analytic.strip_load, prior=[bamudi.Normal(1.0, 0.0)])
    expect("at least one dimension", model_with, analytic.strip_load, prior=[])
    with pytest.raises(TypeError, match="prior\\[0\\] must be bamudi.Uniform or bamudi.Normal"):
        model_with(analytic.strip_load, prior=[(0.5, 3.0)])


def test_model_and_data_errors_name_the_argument(data):
    x, y = data
    expect("A has shape (6, 20); expected (outputs, components × points) = (6, 21)", model_with,
           analytic.strip_load, A=analytic.A[:, :20])
    expect("A[2, 3] is NaN", model_with, analytic.strip_load, A=_nan_a())
    expect("discrepancy terms: 2 entries for 1 component(s)", model_with, analytic.strip_load,
           discrepancy=bamudi.Discrepancy("legendre", [2, 2]))
    expect("`bessel` is not one of legendre, chebyshev, hermite", model_with, analytic.strip_load,
           discrepancy=bamudi.Discrepancy("bessel"))
    expect("response must be callable", model_with, 42)
    expect("outputs: `sensor_1` is named twice", model_with, analytic.strip_load, outputs=["sensor_1"] * 6)
    expect("y has shape (40, 5); expected (experiments, outputs) = (40, 6)", bamudi.calibrate, analytic.model,
           (x, y[:, :5]), analytic.CONFIG)
    expect("x has shape (40, 2); expected (experiments, inputs) = (n, 1)", bamudi.calibrate, analytic.model,
           (np.hstack([x, x]), y), analytic.CONFIG)
    bad = y.copy()
    bad[4, 2] = np.nan
    expect("y[4, 2] (row 4, column `sensor_3`) is NaN", bamudi.calibrate, analytic.model, (x, bad), analytic.CONFIG)
    expect("no column ['sensor_6']", bamudi.calibrate, analytic.model,
           {"load_kn_per_m": x[:, 0], **{f"sensor_{s}": y[:, s - 1] for s in range(1, 6)}}, analytic.CONFIG)
    expect("unknown field `colour`", bamudi.calibrate, analytic.model, data, {"colour": "red"})
    expect("theta_grid_points", bamudi.calibrate, analytic.model, data, {"theta_grid_points": 1})


def _nan_a():
    a = analytic.A.copy()
    a[2, 3] = np.nan
    return a


def test_prediction_and_coverage_errors(cal):
    expect("x has shape (1, 2); expected (conditions, inputs) = (n, 1)", cal.predict, [[1.0, 2.0]])
    expect("`prediction` returned shape [3]", cal.predict_through, lambda x, t, q: np.zeros(3), ["a", "b"], [5.0])
    expect("`prediction` raised ZeroDivisionError", cal.predict_through, lambda x, t, q: 1 / 0, ["a"], [5.0])
    x = np.linspace(1.0, 10.0, 12).reshape(-1, 1)
    expect("`truth` returned shape (12, 5)", bamudi.coverage, analytic.model, lambda x, t: np.zeros((12, 5)), x,
           noise_sd=0.01, replicates=2)
    expect("noise_sd must be finite and > 0", bamudi.coverage, analytic.model, lambda x, t: np.zeros((12, 6)), x,
           noise_sd=0.0, replicates=2)


def test_the_documented_example_runs_as_printed(tmp_path):
    src = (REPO / "python" / "examples" / "own_model.py").read_text()
    docs = (REPO / "docs" / "python.md").read_text()
    assert "```python\n" + src + "```" in docs, "docs/python.md must show python/examples/own_model.py verbatim"
    assert len(src.splitlines()) < 40
    out = subprocess.run([sys.executable, str(REPO / "python" / "examples" / "own_model.py")], cwd=tmp_path,
                         capture_output=True, text=True, check=True).stdout
    # The line docs/python.md shows, printed by the example as run (a check that the page and
    # the code agree, not a bound). It read 1.654 [1.585, 1.725] until the default discrepancy
    # prior became isotropic and zero-mean (issue 57, 8cd6b02); page and test moved together.
    assert "decay 1.655 1/m, 95 % [1.584, 1.728] (truth 1.6)" in out, out
    assert (tmp_path / "own_model_calibration" / "model.json").is_file()


def test_two_parameters_with_mixed_priors_take_the_mcmc_path():
    points = analytic.POINTS

    def two(x, theta):  # the strip load plus an extra linear load of slope theta[1] (kN/m per m)
        return x[:, :1] * np.exp(-theta[0] * points) + theta[1] * points

    m = bamudi.Model(two, coordinates=points, inputs=["load_kn_per_m"], outputs=analytic.model.outputs,
                     A=analytic.A, prior={"decay": bamudi.Uniform(0.5, 3.0), "slope": bamudi.Normal(0.0, 0.2)})
    x = np.linspace(1.0, 10.0, 40).reshape(-1, 1)
    y = two(x, [1.6, 0.1]) @ analytic.A.T + 0.002 * np.random.default_rng(0).standard_normal((40, 6))
    c = bamudi.calibrate(m, (x, y), {"estimator": {"kind": "exact_linear"},
                                     "mcmc": {"chains": 2, "warmup": 300, "samples": 600}}, seed=3)
    assert c.theta_ci95.shape == (2, 2) and c.parameters == ["decay", "slope"]
    assert c.theta_ci95[0, 0] < 1.6 < c.theta_ci95[0, 1] and c.theta_ci95[1, 0] < 0.1 < c.theta_ci95[1, 1]
    d = c.posterior_draws()
    assert d["method"] == "mcmc" and d["theta"].shape == (2, 600, 2) and d["rho"].shape == (2, 600)
    assert c.posterior_grid() is None
    prior = json.loads(c._native.description_json())["prior"]
    assert prior == [{"uniform": {"lo": 0.5, "hi": 3.0}}, {"normal": {"mean": 0.0, "sd": 0.2}}]
