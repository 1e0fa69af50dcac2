"""A gate from a finite-element deck: the coarse default gate exported and read back
calibrates as the gate it came from (the same model to round-off)."""

import pickle

import pytest

import bamudi
from conftest import CONFIG


@pytest.fixture(scope="module")
def deck(gate, tmp_path_factory):
    d = tmp_path_factory.mktemp("deck")
    gate.export_inp(d / "g.inp")
    return bamudi.Gate.from_inp(d / "g.inp", d / "g.spec.toml")


def test_a_deck_gate_calibrates_as_its_source(deck, gate, experiments, calibration):
    assert deck.gauge_names == gate.gauge_names and deck.element_size is None
    assert deck.quoin_height == gate.quoin_height and "g.inp" in deck.source
    cal = bamudi.calibrate(deck, experiments, CONFIG)
    # the same model to ~1e-15; the noise-sd search and ML-II fits stop at their own
    # tolerances: a hundredth of the posterior sd (the command line's test measures 2e-4 sd)
    assert abs(cal.theta_mean - calibration.theta_mean) <= 1e-2 * calibration.theta_sd
    assert pickle.loads(pickle.dumps(deck)).gauge_names == deck.gauge_names


def test_deck_errors(deck, tmp_path):
    with pytest.raises(bamudi.BamudiError, match="is a deck already"):
        deck.export_inp(tmp_path / "again.inp")
    with pytest.raises(bamudi.BamudiError, match="gate configuration"):
        bamudi.simulate_experiments(deck, 1, n=5, reality=tmp_path / "r.toml")
    with pytest.raises(bamudi.BamudiError, match="missing.spec.toml"):
        bamudi.Gate.from_inp(tmp_path / "missing.inp", tmp_path / "missing.spec.toml")
