"""Shared fixtures: a coarse gate (60 in elements, as the command line's documentation tests
use) and the `bamudi` command-line binary that the round-trip tests compare against."""

import os
import pathlib
import subprocess

import pytest

import bamudi

REPO = pathlib.Path(__file__).resolve().parents[2]
ELEMENT_SIZE = 60.0
CONFIG = {
    "gap_prior": [81.0, 105.0],
    "calibration": {"estimator": {"kind": "exact_linear"}, "sampling": {"noise_sd": 1.0}},
}
CONFIG_TOML = """gap_prior = [81.0, 105.0]
[calibration.estimator]
kind = "exact_linear"
[calibration.sampling]
noise_sd = 1.0
"""


@pytest.fixture(scope="session")
def gate():
    return bamudi.Gate(element_size=ELEMENT_SIZE)


@pytest.fixture(scope="session")
def experiments(gate):
    return bamudi.simulate_experiments(gate, scenario=1, n=60, seed=1)


@pytest.fixture(scope="session")
def calibration(gate, experiments):
    return bamudi.calibrate(gate, experiments, CONFIG)


@pytest.fixture(scope="session")
def cli():
    """Runs the `bamudi` binary (BAMUDI_CLI, else the workspace's debug build, which
    `cargo test --workspace` builds before CI runs this suite) with the coarse gate."""
    exe = os.environ.get("BAMUDI_CLI") or str(REPO / "target" / "debug" / "bamudi")
    if not os.path.isfile(exe):
        pytest.fail(f"no bamudi binary at {exe}: run `cargo build -p bamudi-gate` or set BAMUDI_CLI")

    def run(*args, cwd, coarse=True):
        """`coarse`: add `--element-size 60` (`predict` refuses it: its gate is saved)."""
        flags = ["--element-size", str(ELEMENT_SIZE)] if coarse else []
        return subprocess.run([exe, *flags, *map(str, args)], cwd=cwd, capture_output=True, text=True)

    return run
