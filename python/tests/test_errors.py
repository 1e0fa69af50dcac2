"""Every refused input raises BamudiError (or TypeError for a wrong Python type) with a
message naming the culprit: the command line's message where the command line has one."""

import pathlib

import numpy as np
import pytest

import bamudi
from conftest import CONFIG, REPO


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


# --- issue 62: the last rough edges of bad input, one test per class ---------------------

def _record_file(tmp_path, rec, name, edit):
    """The record's CSV with `edit(rows)` applied to its rows (lists of cells; the header is
    rows[0], file line i + 1), written to `name`."""
    rows = [line.split(",") for line in rec.csv.splitlines()]
    edit(rows)
    path = tmp_path / name
    path.write_text("\n".join(",".join(r) for r in rows) + "\n")
    return path


def test_absurd_readings_are_refused_naming_line_and_column(gate, experiments, tmp_path):
    cols, data = list(experiments.columns), experiments.data.copy()
    data[2, 4] = 1e300  # row 2 = line 4, column SG3
    msg = expect("line 4, column `SG3`", bamudi.calibrate, gate, data, CONFIG, columns=cols)
    assert "100000" in msg, msg
    rec = bamudi.simulate_field(gate, days=2.0, seed=1)

    def absurd(rows):
        rows[9][rows[0].index("SG2")] = "-2e5"

    path = _record_file(tmp_path, rec, "absurd.csv", absurd)
    msg = expect("line 10, column `SG2`", bamudi.close_loop, gate, path)
    assert "100000" in msg, msg

    def fault_code(rows):
        rows[6][rows[0].index("air_temp_f")] = "-999"

    path = _record_file(tmp_path, rec, "fault.csv", fault_code)
    msg = expect("line 7, column `air_temp_f`", bamudi.close_loop, gate, path)
    assert "degF" in msg, msg


def test_limits_hold_on_every_path(tmp_path):
    text = (REPO / "crates/mitergate/data/default_gate.toml").read_text()
    coarse = tmp_path / "coarse.toml"
    coarse.write_text(text.replace("element_size = 12.0", "element_size = 1e6"))
    msg = expect("mesh.element_size", bamudi.Gate, path=str(coarse))
    assert "240" in msg, msg
    msg = expect("mesh.element_size", bamudi.Gate.from_toml, coarse.read_text())
    assert "240" in msg, msg
    expect("element_size must be in (0, 240]", bamudi.Gate, element_size=1e6)


def test_contradictory_effects_are_refused(gate):
    expect("`none` cannot be combined", bamudi.simulate_field, gate, effects=["none", "thermal"])
    expect("`thermal` is named twice", bamudi.simulate_field, gate, effects=["thermal", "thermal"])
    expect("final_gap: the final gap is used only by the `gap-growth` effect",
           bamudi.simulate_field, gate, effects=["thermal"], final_gap=120.0)


def test_messages_name_the_culprit(gate, experiments, tmp_path):
    rec = bamudi.simulate_field(gate, days=2.0, seed=1)

    def stuck(rows):
        for r in rows[1:]:
            r[rows[0].index("SG1")] = "5.0"

    expect("column `SG1` is constant", bamudi.close_loop, gate,
           _record_file(tmp_path, rec, "stuck.csv", stuck))

    def open_gate(rows):
        up, down = rows[0].index("h_up"), rows[0].index("h_down")
        for r in rows[1:]:
            r[down] = r[up]

    expect("every row has the gate open", bamudi.close_loop, gate,
           _record_file(tmp_path, rec, "open.csv", open_gate))

    def never_read(rows):
        for r in rows[1:]:
            r[rows[0].index("SG4")] = ""

    expect("column `SG4`: every value is missing", bamudi.close_loop, gate,
           _record_file(tmp_path, rec, "empty.csv", never_read))
    latin1 = tmp_path / "latin1.csv"
    lines = rec.csv.encode().split(b"\n")
    lines[4] = lines[4] + b"\xb5"
    latin1.write_bytes(b"\n".join(lines))
    msg = expect("line 5", bamudi.close_loop, gate, latin1)
    assert "0xB5 is not UTF-8" in msg and msg.count("UTF-8") <= 2, msg
    toml = tmp_path / "cal.toml"
    toml.write_bytes(b"gap_prior = [81.0, 105.0]\n# 20 \xb0F\n")
    expect("line 2: byte 0xB0 is not UTF-8", bamudi.calibrate, gate, experiments, toml)
    loop = tmp_path / "loop.csv"
    loop.symlink_to(tmp_path / "loop2.csv")
    (tmp_path / "loop2.csv").symlink_to(loop)
    expect("symbolic links", bamudi.close_loop, gate, loop)
    deck = tmp_path / "gate.inp"
    deck.write_text("*HEADING\nexported gate\n")
    expect("Gate.from_inp", bamudi.Gate, path=str(deck))
    msg = expect("nope.toml", bamudi.Gate, path=str(tmp_path / "nope.toml"))
    assert msg.count("(os error") <= 1, msg


def test_a_prior_that_excludes_the_data_warns_which_bound_to_widen(gate, experiments):
    narrow = cfg(gap_prior=[81.0, 85.0])  # the data's gap is 90 in
    cal = bamudi.calibrate(gate, experiments, narrow)
    assert any("gap_prior" in w and "raise the upper bound above 85" in w for w in cal.warnings), cal.warnings
    rec = bamudi.simulate_field(gate, days=7.0, seed=1)
    out = bamudi.close_loop(gate, rec, gap_prior=(60.0, 80.0), max_experiments=30)
    warnings = out.get("warnings", [])
    assert any("gap_prior (60, 80)" in w and "raise the upper bound above 80" in w for w in warnings), warnings
