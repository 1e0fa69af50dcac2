"""Shapes and dtypes, progress and logging, and the GIL: long computations run without it,
so two threads calibrate at once and Python keeps running meanwhile."""

import logging
import threading
import time

import numpy as np
import pytest

import bamudi
from conftest import CONFIG


def test_gate_and_experiment_shapes(gate, experiments):
    assert gate.element_size == 60.0 and gate.n_dofs > 0 and gate.quoin_height > 0
    assert experiments.columns == ("h_up", "h_down", *gate.gauge_names)
    assert experiments.data.shape == (60, 2 + len(gate.gauge_names))
    assert experiments.data.dtype == np.float64 and np.isfinite(experiments.data).all()


def test_field_record_arrays(gate):
    rec = bamudi.simulate_field(gate, days=2.0, step_minutes=60.0, missing=0.1, seed=2)
    n = 48
    assert rec.data.shape == (n, len(rec.columns)) and rec.data.dtype == np.float64
    assert rec.time_unix_s.dtype == np.int64 and rec.time_unix_s.shape == (n,)
    assert np.all(np.diff(rec.time_unix_s) == 3600)
    assert rec.gap_in.shape == (n,) and np.all(rec.gap_in == 90.0)
    gauges = rec.data[:, rec.columns.index("SG1"):]
    assert np.isnan(gauges).any(), "10 % missing values must show as NaN"
    assert rec.csv.count("\n") == n + 1


def test_calibration_outputs(calibration, gate):
    lo, hi = calibration.theta_ci95
    assert 81.0 <= lo < calibration.theta_mean < hi <= 105.0
    assert calibration.theta_sd > 0 and 0 < calibration.rho_star <= 1.5
    assert calibration.verdict in ("adequate", "inadequate")
    assert set(calibration.adequacy) >= {"verdict", "failed"}
    z = calibration.z_in
    p = calibration.predict(np.array([700.0, 650.0, 600.0]), np.array([100.0, 80.0, 50.0]))
    assert p["strain_mean"].shape == (3, len(gate.gauge_names))
    for part in ("normal", "tangential"):
        assert p[f"{part}_mean"].shape == (3, z.size)
        assert np.all(p[f"{part}_lower"] <= p[f"{part}_upper"])
    assert np.all(p["strain_sd"] >= 0)
    none = calibration.predict(np.array([]), np.array([]))
    assert none["strain_mean"].shape == (0, len(gate.gauge_names))
    assert none["normal_mean"].shape == (0, z.size)
    one = calibration.predict(700.0, 100.0)
    assert one["normal_mean"].shape == (z.size,)
    assert np.array_equal(one["normal_mean"], p["normal_mean"][0])


def test_inputs_as_dataframe_dict_and_array_agree(gate, experiments, calibration):
    as_dict = {c: experiments.data[:, i] for i, c in enumerate(experiments.columns)}
    cal = bamudi.calibrate(gate, as_dict, CONFIG)
    assert cal.theta_mean == calibration.theta_mean
    cal = bamudi.calibrate(gate, experiments.data, CONFIG, columns=experiments.columns)
    assert cal.theta_mean == calibration.theta_mean
    pd = pytest.importorskip("pandas")
    frame = experiments.to_frame()
    assert isinstance(frame, pd.DataFrame)
    assert bamudi.calibrate(gate, frame, CONFIG).theta_mean == calibration.theta_mean


def test_posterior_warnings_are_kept_and_logged(gate, experiments, calibration, caplog):
    # the truth (90 in) lies outside this prior: the posterior piles up at its upper bound
    narrow = {**CONFIG, "gap_prior": [70.0, 85.0]}
    with caplog.at_level(logging.WARNING):
        cal = bamudi.calibrate(gate, experiments, narrow)
    assert any("bound" in w for w in cal.warnings), cal.warnings
    assert any(w in r.getMessage() for r in caplog.records for w in cal.warnings)
    assert calibration.warnings == []  # the prior holds the truth: nothing to warn about


def test_progress_reports_every_stage(gate, experiments):
    calls = []
    bamudi.calibrate(gate, experiments, CONFIG, progress=lambda s, d, t: calls.append((s, d, t)))
    stages = {s for s, _, _ in calls}
    assert "Module 3: theta posterior" in stages and "Module 2: rho*" in stages
    assert all(d <= t for _, d, t in calls if t > 0)
    last = {}
    for s, d, t in calls:
        last[s] = (d, t)
    assert all(d == t for d, t in last.values())


def test_engine_warnings_reach_python_logging(gate, experiments, caplog):
    data = experiments.data.copy()
    data[:3, 1] = data[:3, 0]  # three rows with the gate open: left out with a warning
    with caplog.at_level(logging.WARNING):
        bamudi.calibrate(gate, data, CONFIG, columns=experiments.columns)
    assert any("gate open" in r.getMessage() for r in caplog.records), caplog.records


def test_two_threads_calibrate_at_once_without_the_gil(gate, experiments, calibration):
    results, spans = {}, {}

    def work(name):
        t0 = time.perf_counter()
        results[name] = bamudi.calibrate(gate, experiments, CONFIG)
        spans[name] = (t0, time.perf_counter())

    threads = [threading.Thread(target=work, args=(k,)) for k in ("a", "b")]
    start = time.perf_counter()
    for t in threads:
        t.start()
    ticks = 0
    while any(t.is_alive() for t in threads):
        ticks += 1  # runs only while the calibrations do not hold the GIL
        time.sleep(0.001)
    wall = time.perf_counter() - start
    for t in threads:
        t.join()
    (a0, a1), (b0, b1) = spans["a"], spans["b"]
    assert max(a0, b0) < min(a1, b1), "the two calibrations did not overlap"
    # a free main thread ticks about once per millisecond (sleep granularity); one blocked by
    # the GIL would tick a handful of times in all. A tenth of the ideal count leaves room for
    # the two busy cores delaying its wake-ups.
    assert ticks >= 0.1 * wall / 0.001, (ticks, wall)
    # and running concurrently changes no number
    assert results["a"].theta_mean == results["b"].theta_mean == calibration.theta_mean


def test_the_quick_start_example_runs(capsys):
    import pathlib
    import runpy
    import sys

    example = pathlib.Path(__file__).resolve().parents[1] / "examples" / "quickstart.py"
    argv = sys.argv
    sys.argv = [str(example), "60"]  # the coarse gate: the example's flow, a CI-sized mesh
    try:
        runpy.run_path(str(example), run_name="__main__")
    finally:
        sys.argv = argv
    out = capsys.readouterr().out
    assert "saved and reloaded" in out and "gap: " in out


SKIN_TOLERANCE = {"key": "skin_plate.thickness", "relative_sd": 0.03}


def test_a_declared_tolerance_reads_the_as_built_skin(gate, experiments, tmp_path):
    # the truth's skin plate is 5 % thinner than drawn (0.59375 in against 0.625): -1.67 of a
    # declared 3 % tolerance; the same seed and noise from the drawing is the paired reference
    (tmp_path / "reality.toml").write_text("[as_built.skin_plate]\nthickness = 0.59375\n")
    thin = bamudi.simulate_experiments(gate, scenario=1, n=60, seed=1, reality=tmp_path / "reality.toml")
    config = dict(CONFIG, tolerances=[SKIN_TOLERANCE])
    read = {}
    for name, data in (("drawing", experiments), ("thin", thin)):
        tols = bamudi.calibrate(gate, data, config).tolerances
        assert [t["name"] for t in tols] == ["skin_plate.thickness"]
        # a Gaussian posterior of an N(0, 1) deviation is narrower than its prior
        assert 0.0 < tols[0]["sd"] < 1.0, tols
        read[name] = tols[0]["mean"]
    # Measured on this gate (60-in elements, 60 experiments), seeds 1, 2, 3: the thin plate
    # reads -1.58, -1.77, -1.56 (sd 0.12-0.13), the drawing's data +0.11, 0.00, +0.11; without
    # the tolerance the thin gate's 95 % gap interval missed 90 in on seeds 1 and 2, with it
    # all three held it. Asserted on seed 1: the reading lies within 0.5 sd of the truth's
    # -1.67 (four posterior sds, and wider than the three seeds' spread), and at least one sd
    # below the paired drawing's (a tolerance column of the wrong sign or size fails both).
    assert abs(read["thin"] + 1.67) < 0.5, read
    assert read["thin"] < read["drawing"] - 1.0, read
    assert bamudi.calibrate(gate, experiments, CONFIG).tolerances == []


def test_predictions_carry_the_skin_the_data_read(gate, tmp_path):
    # Module 4 predicts with the deviation the calibration read: the true (noise-free) strains
    # of the 5 %-thinner skin at 8 new conditions, against the 95 % strain bands. Measured
    # (this gate, seeds 1 and 77): 54 of 56 inside, RMSE 0.25 microstrain; the same calibration
    # predicted without the deviation (the commit before) held 11 of 56, RMSE 3.9. Bounds:
    # 45 of 56 (nominal 53; the 56 share one calibration's errors, so they are not independent
    # draws) and an RMSE below the 1 microstrain noise, 4x the measured value and 4x below the
    # prediction that leaves the deviation out.
    (tmp_path / "reality.toml").write_text("[as_built.skin_plate]\nthickness = 0.59375\n")
    reality = tmp_path / "reality.toml"
    thin = bamudi.simulate_experiments(gate, scenario=1, n=60, seed=1, reality=reality)
    cal = bamudi.calibrate(gate, thin, dict(CONFIG, tolerances=[SKIN_TOLERANCE]))
    truth = bamudi.simulate_experiments(gate, scenario=1, n=8, noise_sd=0.0, seed=77, reality=reality)
    frame = truth.data
    pred = cal.predict(frame[:, 0], frame[:, 1])
    strains = frame[:, 2:]
    inside = (pred["strain_lower"] <= strains) & (strains <= pred["strain_upper"])
    rmse = float(np.sqrt(np.mean((pred["strain_mean"] - strains) ** 2)))
    assert inside.sum() >= 45, (inside.sum(), rmse)
    assert rmse < 1.0, rmse
