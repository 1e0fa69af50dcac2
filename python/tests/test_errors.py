"""Every refused input raises BamudiError (or TypeError for a wrong Python type) with a
message naming the culprit: the command line's message where the command line has one."""

import pathlib

import numpy as np
import pytest

import bamudi
from conftest import CONFIG


def expect(fragment, fn, *args, **kwargs):
    with pytest.raises(bamudi.BamudiError) as e:
        fn(*args, **kwargs)
    assert fragment in str(e.value), str(e.value)
    return str(e.value)


def cfg(**over):
    c = {k: v for k, v in CONFIG.items()}
    c.update(over)
    return c


def test_gate_errors(tmp_path):
    expect("element_size must be in (0, 240]", bamudi.Gate, element_size=-1.0)
    expect("element_size must be in (0, 240]", bamudi.Gate, element_size=float("nan"))
    expect("nope.toml", bamudi.Gate, path=str(tmp_path / "nope.toml"))
    bad = tmp_path / "bad.toml"
    bad.write_text("[geometry]\nquoin_height = -5.0\n")
    expect("bad.toml", bamudi.Gate, path=str(bad))


def test_simulation_errors(gate, tmp_path):
    expect("scenarios 1 and 2", bamudi.simulate_experiments, gate, 3)
    expect("n must be in [1, 1000000]", bamudi.simulate_experiments, gate, 1, n=0)
    expect("noise_sd must be in [0, 1000]", bamudi.simulate_experiments, gate, 1, noise_sd=-1.0)
    expect("missing.toml", bamudi.simulate_experiments, gate, 1, n=5, reality=tmp_path / "missing.toml")
    expect("unknown effect `volcano`", bamudi.simulate_field, gate, effects=["volcano"])
    expect("days must be in (0, 3650]", bamudi.simulate_field, gate, days=0.0)
    expect("4320000 rows; at most 200000", bamudi.simulate_field, gate, days=3000.0, step_minutes=1.0)
    expect("missing must be in [0, 0.9]", bamudi.simulate_field, gate, missing=1.0)


def test_configuration_errors(gate, experiments):
    expect("`gap_prior` must be two numbers", bamudi.calibrate, gate, experiments, cfg(gap_prior=[81.0]))
    expect("below the quoin height", bamudi.calibrate, gate, experiments, cfg(gap_prior=[10.0, 1e5]))
    expect("`discrepancy_terms` must be in [1, 20]", bamudi.calibrate, gate, experiments,
           cfg(discrepancy_terms=[0, 6]))
    expect("unknown field", bamudi.calibrate, gate, experiments, cfg(colour="red"))
    expect("tolerances[0].key", bamudi.calibrate, gate, experiments,
           cfg(tolerances=[{"key": "skin_plate.colour", "relative_sd": 0.03}]))
    expect("tolerances[0].relative_sd", bamudi.calibrate, gate, experiments,
           cfg(tolerances=[{"key": "skin_plate.thickness", "relative_sd": 0.9}]))
    expect("in table [calibration]", bamudi.calibrate, gate, experiments,
           cfg(calibration={"theta_grid_points": 1}))
    expect("parsing config", bamudi.calibrate, gate, experiments, "gap_prior = [")
    expect("config nope.toml: file does not exist", bamudi.calibrate, gate, experiments, "nope.toml")
    expect("file does not exist", bamudi.calibrate, gate, experiments, pathlib.Path("nope.toml"))
    with pytest.raises(TypeError):
        bamudi.calibrate(gate, experiments, 42)


def test_data_errors(gate, experiments):
    cols, data = list(experiments.columns), experiments.data
    expect("9 columns named but the array has 8", bamudi.calibrate, gate, data[:, :8], CONFIG, columns=cols)
    renamed = cols[:-1] + ["SG99"]
    expect("SG7", bamudi.calibrate, gate, data, CONFIG, columns=renamed)
    bad = data.copy()
    bad[4, 3] = np.nan
    msg = expect("line 6", bamudi.calibrate, gate, bad, CONFIG, columns=cols)
    assert "SG2" in msg
    stuck = data.copy()
    stuck[:, 5] = 12.0
    expect("column `SG4` is constant", bamudi.calibrate, gate, stuck, CONFIG, columns=cols)
    few = np.repeat(data[:3], 10, axis=0)
    expect("3 distinct water-level pair(s)", bamudi.calibrate, gate, few, CONFIG, columns=cols)
    out = data.copy()
    out[0, 0] = -50.0
    expect("h_up", bamudi.calibrate, gate, out, CONFIG, columns=cols)
    expect("2-D array", bamudi.calibrate, gate, data[0], CONFIG, columns=cols)
    named = {c: data[:, i] for i, c in enumerate(cols)}
    named["SG5"] = ["x"] * len(data)
    expect("data column `SG5` is not numeric", bamudi.calibrate, gate, named, CONFIG)


def test_prediction_and_file_errors(calibration, tmp_path):
    expect("h_up has 2 values and h_down 1", calibration.predict, [700.0, 600.0], [100.0])
    expect("predicting at h_up = -5 in", calibration.predict, -5.0, 100.0)
    expect("calibration.json", bamudi.Calibration.load, tmp_path)
    (tmp_path / "calibration.json").write_text("{")
    expect("calibration.json", bamudi.Calibration.load, tmp_path)


def test_close_loop_errors(gate, tmp_path):
    rec = bamudi.simulate_field(gate, days=2.0, seed=1)
    expect("gap_prior must be (lo, hi)", bamudi.close_loop, gate, rec, gap_prior=(120.0, 60.0))
    expect("max_experiments must be in [10, 100000]", bamudi.close_loop, gate, rec, max_experiments=5)
    expect("holdout_fraction must be in (0, 1)", bamudi.close_loop, gate, rec, holdout_fraction=1.5)
    expect("too few rows", bamudi.close_loop, gate, rec)
    # declared tolerances are checked before the record is read
    colour = [{"key": "skin_plate.colour", "relative_sd": 0.03}]
    expect("tolerances[0].key", bamudi.close_loop, gate, rec, tolerances=colour)
    wide = [{"key": "skin_plate.thickness", "relative_sd": 0.9}]
    expect("tolerances[0].relative_sd", bamudi.close_loop, gate, rec, tolerances=wide)
    expect("tolerances", bamudi.close_loop, gate, rec, tolerances=[{"key": "skin_plate.thickness"}])
    bad = tmp_path / "r.csv"
    bad.write_text(rec.csv.replace("h_down", "h_low"))
    expect("h_down", bamudi.close_loop, gate, bad)
