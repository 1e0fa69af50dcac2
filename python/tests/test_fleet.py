"""The Dask fleet example on a small fleet: every gate is a row, the broken one with its
error, the others calibrated; gates and calibrations pickle (what Dask sends)."""

import pathlib
import pickle
import sys

import numpy as np
import pytest

import bamudi

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "examples"))


def test_gates_and_calibrations_pickle(gate, calibration):
    g = pickle.loads(pickle.dumps(gate))
    assert g.gauge_names == gate.gauge_names and g.n_dofs == gate.n_dofs
    c = pickle.loads(pickle.dumps(calibration))
    assert c.theta_mean == calibration.theta_mean
    for k, v in c.predict(700.0, 100.0).items():
        assert np.array_equal(v, calibration.predict(700.0, 100.0)[k]), k


def test_a_fleet_on_two_dask_workers_reports_every_gate(gate, tmp_path):
    pytest.importorskip("distributed")
    import fleet_dask

    jobs = fleet_dask.simulate_fleet(gate, 3, str(tmp_path), days=20.0)
    table, _ = fleet_dask.timed_run(gate, jobs, workers=2, scheduler=None)
    assert list(table["gate"]) == ["gate-01", "gate-02", "gate-03"]
    broken = table.iloc[2]
    assert broken["verdict"] == "failed"
    assert "SG4" in broken["error"] and "gate-03.csv" in broken["error"], broken["error"]
    for _, row in table.iloc[:2].iterrows():
        assert row["error"] == "" and row["verdict"] in ("adequate", "inadequate")
        # 1 in: twenty times the posterior sd these records give (about 0.05 in), a gross
        # failure detector; the data come from the calibration's own model here
        assert abs(row["gap_in"] - row["true_gap_in"]) < 1.0, row
