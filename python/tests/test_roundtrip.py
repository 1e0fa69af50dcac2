"""Python gives the command line's numbers for the same inputs and seed, to the last digit:
both call the same Rust functions, and JSON and CSV carry the f64 values exactly."""

import csv
import json

import numpy as np

import bamudi
from conftest import CONFIG_TOML


def test_simulated_experiments_equal_the_cli_file(experiments, cli, tmp_path):
    done = cli("--seed", 1, "simulate", "experiments", "--scenario", 1, "--n", 60, "--out", "e.csv", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "e.csv").read_text() == experiments.to_csv()


def test_calibration_equals_the_cli_results(gate, experiments, calibration, cli, tmp_path):
    (tmp_path / "cal.toml").write_text(CONFIG_TOML)
    (tmp_path / "e.csv").write_text(experiments.to_csv())
    done = cli("calibrate", "--config", "cal.toml", "--data", "e.csv", "--out", "res", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    results = json.loads((tmp_path / "res" / "results.json").read_text())
    post = results["theta"]["with_discrepancy"]
    # the TOML file read by Python gives what the dict config gives
    from_file = bamudi.calibrate(gate, experiments, str(tmp_path / "cal.toml"))
    for cal in (calibration, from_file):
        assert cal.theta_mean == post["mean"][0]
        assert cal.theta_sd == post["sd"][0]
        assert list(cal.theta_ci95) == post["ci95"][0]
        assert cal.rho_star == results["rho"]["rho_star"]
        assert cal.sigma_eps == results["sigma_eps"]["value"]
        assert cal.adequacy == results["adequacy"]
    # and `bamudi predict` on the command line's calibration equals Python's prediction
    loaded = bamudi.Calibration.load(tmp_path / "res")
    for k, v in loaded.predict(650.0, 80.0).items():
        assert np.array_equal(v, calibration.predict(650.0, 80.0)[k]), k


def test_the_cli_predicts_from_a_python_calibration(calibration, cli, tmp_path):
    calibration.save(tmp_path / "py")
    cal_file = tmp_path / "py" / "calibration.json"
    done = cli("predict", "--calibration", cal_file, "--h-up", 700, "--h-down", 100,
               "--forces-out", "f.csv", "--quoin-block-out", "b.csv", cwd=tmp_path, coarse=False)
    assert done.returncode == 0, done.stderr
    with open(tmp_path / "f.csv") as f:
        rows = list(csv.DictReader(f))
    p = calibration.predict(700.0, 100.0)
    assert np.array_equal([float(r["z_in"]) for r in rows], calibration.z_in)
    for stat in ("mean", "lower", "upper"):
        for part in ("normal", "tangential"):
            got = [float(r[f"{part}_{stat}_lbf_per_in"]) for r in rows]
            assert np.array_equal(got, p[f"{part}_{stat}"]), (part, stat)
    # the strain table the command line prints: mean and band per gauge (3 decimals)
    for name, mean, lo, hi in zip(calibration.gauge_names, p["strain_mean"], p["strain_lower"], p["strain_upper"]):
        line = next(l for l in done.stdout.splitlines() if l.split() and l.split()[0] == name)
        assert line.split()[1:4] == [f"{mean:.3f}", f"{lo:.3f}", f"{hi:.3f}"], line


def test_a_field_record_and_its_close_loop_equal_the_cli(gate, cli, tmp_path):
    rec = bamudi.simulate_field(gate, days=20.0, step_minutes=120.0, effects=["offset-jump"], seed=3)
    done = cli("--seed", 3, "simulate", "field", "--days", 20, "--step-minutes", 120,
               "--effect", "offset-jump", "--out", "r.csv", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "r.csv").read_text() == rec.csv
    # a declared build tolerance: both report what the final calibration read of it
    (tmp_path / "tol.toml").write_text(
        '[[tolerances]]\nkey = "skin_plate.thickness"\nrelative_sd = 0.03\n')
    tolerance = {"key": "skin_plate.thickness", "relative_sd": 0.03}
    args = dict(gap_prior=(60.0, 120.0), max_experiments=40, tolerances=[tolerance])
    done = cli("--seed", 4, "close-loop", "--data", "r.csv", "--gap-prior", "60,120",
               "--max-experiments", 40, "--tolerances", "tol.toml", "--out", "loop", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    cli_report = json.loads((tmp_path / "loop" / "results.json").read_text())
    py_report = bamudi.close_loop(gate, tmp_path / "r.csv", seed=4, **args)
    assert py_report["theta_after"] == cli_report["theta_after"]
    assert py_report["effects"] == cli_report["effects"]
    assert py_report["conclusion"] == cli_report["conclusion"]
    assert py_report["tolerances"] == cli_report["tolerances"]
    [read] = py_report["tolerances"]
    assert read["name"] == "skin_plate.thickness" and read["sd"] > 0, read
    # the record object gives the same report as its file
    from_record = bamudi.close_loop(gate, rec, seed=4, **args)
    assert from_record["theta_after"] == py_report["theta_after"]


REALITY = """# the gate as built departs from the drawing the calibration uses
[as_built.skin_plate]
thickness = 0.55
[as_built.gauges.SG3]
direction = [0.9962, 0.0872, 0.0]
[[sensors]]
gauge = "SG5"
drift_microstrain = 6.0
"""


def test_data_from_a_reality_and_their_calibration_equal_the_cli(gate, experiments, cli, tmp_path):
    # the truth is not the calibration's model here: an as-built skin, a turned gauge and a
    # drifting one; Python and the command line must still agree to the last digit
    (tmp_path / "reality.toml").write_text(REALITY)
    (tmp_path / "cal.toml").write_text(CONFIG_TOML)
    real = bamudi.simulate_experiments(gate, scenario=1, n=60, seed=1, reality=tmp_path / "reality.toml")
    assert not np.array_equal(real.data[:, 2:], experiments.data[:, 2:]), "the reality changed nothing"
    done = cli("--seed", 1, "simulate", "experiments", "--scenario", 1, "--n", 60,
               "--reality", "reality.toml", "--out", "real.csv", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "real.csv").read_text() == real.to_csv()
    done = cli("calibrate", "--config", "cal.toml", "--data", "real.csv", "--out", "res", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    results = json.loads((tmp_path / "res" / "results.json").read_text())
    cal = bamudi.calibrate(gate, real, str(tmp_path / "cal.toml"))
    post = results["theta"]["with_discrepancy"]
    assert (cal.theta_mean, cal.theta_sd) == (post["mean"][0], post["sd"][0])
    assert cal.adequacy == results["adequacy"]
