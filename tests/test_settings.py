"""fnnlib.check_notebook_settings: every notebook's value checks, run before any work."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import fnnlib as F
from fnnbook import read_parameters
from types import MappingProxyType

from fnnlib.settings import NOTEBOOK_PRESETS, MissingDataError, notebook_presets

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


def _name(notebook: Path) -> str:
    return re.sub(r"^\d+_", "", notebook.stem)  # 01_spiral -> spiral


def _defaults(name: str) -> dict:
    params = read_parameters(next(p for p in NOTEBOOKS if _name(p) == name))
    synthetic = {"bottle": {"data": "synthetic"}}  # CI has no throws
    return {**params, **synthetic.get(name, {})}


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_the_paper_values_pass(notebook: Path) -> None:
    F.check_notebook_settings(notebook.stem, _defaults(_name(notebook)))


@pytest.mark.parametrize(("notebook", "change", "message"), [
    ("spiral", {"L": -1.0}, "not positive definite"),
    ("spiral", {"L": 250.0}, "unstable"),
    ("spiral", {"N": 0}, "N"),
    ("spiral", {"iterations": 0}, "iterations must be an integer >= 1"),
    ("spiral", {"hidden": [50, 0]}, "layer widths"),
    ("theory", {"L_sweep": [5.0, -1.0]}, "not positive definite"),
    ("ablations", {"omega_range": [0.8, -0.4, 4.4]}, "empty"),
    ("observers", {"N": 1000}, "need 1 <= N < n_samples"),
    ("neural_feedback", {"fb_iterations": 0}, "fb_iterations"),
    ("neural_feedback", {"beta": -0.1}, "beta"),
    ("bottle", {"data": "fake"}, "data must be 'real' or 'synthetic'"),
    ("quadrotor_learning", {"seeds": [0, 0]}, "distinct"),
    ("quadrotor_learning", {"segment_length": 0}, "segment_length"),
    ("quadrotor_mpc", {"u_max": [0.0]}, "positive thrust"),
    ("tuned_gains", {"bottle_tune_iterations": 0}, "bottle_tune_iterations must be an integer >= 1"),
    ("tuned_gains", {"quad_tune_flights": 0}, "quad_tune_flights"),
    ("tuned_gains", {"quad_tune_lr": 0.0}, "quad_tune_lr must be > 0"),
    ("tuned_gains", {"bottle_tune_throws": 0}, "bottle_tune_throws must be an integer >= 1"),
])
def test_bad_values_are_refused(notebook: str, change: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        F.check_notebook_settings(notebook, {**_defaults(notebook), **change})


def test_missing_data_and_unknown_notebooks(tmp_path: Path) -> None:
    with pytest.raises(MissingDataError, match="data missing: Training_dataset.mat, Testing_dataset.mat"):
        F.check_notebook_settings("05_bottle.ipynb", {**_defaults("bottle"), "data": "real",
                                                      "data_dir": str(tmp_path)})
    with pytest.raises(ValueError, match="setting 'N_max' is missing"):  # Ts, N, ... come from the presets
        F.check_notebook_settings("spiral", {"L": 20.0})
    F.check_notebook_settings("my_own_notebook", {"L": -1.0})  # no checks declared: passes


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_a_shared_paper_value_is_left_to_its_preset(notebook: Path) -> None:
    """Issue 13: every preset parameter is ``None`` in the cell (the value is written once, in the presets)."""
    declared, presets = read_parameters(notebook), notebook_presets(notebook.stem)
    assert set(presets) <= set(declared), f"presets for parameters {notebook.name} does not declare"
    written = {k: declared[k] for k in presets if declared[k] is not None}
    assert not written, f"{notebook.name} writes preset values again: {written}"


def test_presets_fill_none_in_place_and_print(capsys: pytest.CaptureFixture[str]) -> None:
    settings = {**_defaults("theory"), "L": 10.0}
    F.check_notebook_settings("02_theory", settings)
    assert settings["Ts"] == 0.01 and settings["n_samples"] == 1000 and settings["test"] == [3.0, 0.05, 10.0]
    assert settings["L"] == 10.0  # an override is kept
    out = capsys.readouterr().out
    assert "Ts = 0.01" in out and "L =" not in out
    F.check_notebook_settings("02_theory", settings)  # nothing left to fill: silent
    assert capsys.readouterr().out == ""


def test_a_read_only_mapping_is_checked_with_its_presets() -> None:
    frozen = MappingProxyType(_defaults("observers"))
    F.check_notebook_settings("observers", frozen)
    with pytest.raises(ValueError, match="not positive definite"):
        F.check_notebook_settings("observers", MappingProxyType({**frozen, "L": -1.0}))
    assert frozen["L"] is None  # untouched


def test_preset_values_are_plain_and_one_source() -> None:
    """Tuples become lists; the same paper value reaches every notebook that shares it."""
    from fnnlib import spiral_presets as SP
    assert all(not isinstance(v, tuple) for name in NOTEBOOK_PRESETS for v in notebook_presets(name).values())
    for name in ("spiral", "theory", "ablations", "observers", "neural_feedback"):
        assert notebook_presets(name)["Ts"] == SP.SPIRAL_TS
    assert notebook_presets("own_system")["spiral_L"] == notebook_presets("spiral")["L"] == SP.PAPER_SPIRAL_L
