"""fnnbook.settings: every notebook's presets and value checks, run before any work; fnnlib.checks underneath."""

from __future__ import annotations

import copy
import functools
import re
from pathlib import Path
from types import MappingProxyType
from typing import Any

import pytest

import fnnbook.settings as S
from fnnbook import read_parameters
from fnnbook.params import INJECTED
from fnnbook.settings import NOTEBOOK_PRESETS, VALUE_CHECKS, MissingDataError, check_notebook_settings, notebook_presets
from fnnlib import checks as C
from fnnlib.data.bottle import BOTTLE_FILES, DataError

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


def _name(notebook: Path) -> str:
    return re.sub(r"^\d+_", "", notebook.stem)  # 01_spiral -> spiral


@functools.cache
def _declared(name: str) -> MappingProxyType[str, Any]:
    return MappingProxyType(read_parameters(next(p for p in NOTEBOOKS if _name(p) == name)))


def _defaults(name: str) -> dict[str, Any]:
    params = copy.deepcopy(dict(_declared(name)))
    synthetic = {"bottle": {"data": "synthetic"}, "cascaded_tanks": {"data": "synthetic"}}  # CI has no real data
    return {**params, **synthetic.get(name, {})}


def _filled(name: str) -> dict[str, Any]:
    """The defaults with the presets filled: every value a task of the book gets in the paper profile."""
    settings = _defaults(name)
    S.fill_presets(name, settings)
    return settings


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_the_paper_values_pass(notebook: Path) -> None:
    check_notebook_settings(notebook.stem, _defaults(_name(notebook)))


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_every_parameter_has_a_check(notebook: Path) -> None:
    """Each name of each parameters cell (but the injected ones) has a check, and no check names another."""
    declared = {k for k in read_parameters(notebook) if k not in INJECTED}
    checked = set(VALUE_CHECKS[_name(notebook)])
    assert declared - checked == set(), f"{notebook.name}: parameters without a check"
    assert checked - declared == set(), f"{notebook.name}: checks of parameters it does not declare"


def _kind_bad_values() -> dict[Any, Any]:
    """A value each shared check refuses: the bound it checks, just crossed."""
    return {S._N1: 0, S._N0: -1, S._N2: 1, S._POS: 0.0, S._NONNEG: -0.5, S._SEED: -1, S._SEEDS2: [3],
            S._SEEDS1: [], S._BOOL: "yes", S._WIDTHS: [16, 0], S._GRID: [1.0, -0.5, 2.0], S._SPIRAL3: [2.0, 0.1],
            S._X0: [9.0], S._ACT: "sigmoid", S._METHOD: "rk45", S._OPTIMIZER: "sgd", S._SWEEP0: [],
            S._GAINS: [], S._GAIN: float("nan"), S._synthetic_sizes: [21, 9, 0]}


CASES = [(name, param) for name, checks in VALUE_CHECKS.items() for param in checks]


@pytest.mark.parametrize(("notebook", "param"), CASES, ids=[f"{n}.{p}" for n, p in CASES])
def test_each_bad_value_is_refused_naming_its_parameter(notebook: str, param: str) -> None:
    check = VALUE_CHECKS[notebook][param]
    default = _filled(notebook)[param]
    bad = _kind_bad_values().get(check, [] if isinstance(default, list) else "bogus")
    with pytest.raises(ValueError, match=rf"^{re.escape(param)}( \(.*\))?( must |: )"):  # its own check, first
        check_notebook_settings(notebook, {**_defaults(notebook), param: bad})


@pytest.mark.parametrize(("notebook", "change", "message"), [
    # the values the red team fed (each failed inside the notebook, 4-46 s later)
    ("spiral", {"method": "rk45"}, "method must be one of .*dopri5"),
    ("bottle", {"method": "euler2"}, "method must be one of"),
    ("spiral", {"activation": "sigmoid"}, "activation must be one of .*relu"),
    ("quadrotor_learning", {"activation": "swish"}, "activation must be one of"),
    ("spiral", {"lr": 0.0}, "lr must be a finite number > 0"),
    ("quadrotor_learning", {"lr": -1e-3}, "lr must be a finite number > 0"),
    ("theory", {"seed": -1}, "seed must be an integer >= 0"),
    ("spiral", {"seeds": [0, -1]}, "seeds must list at least 2 distinct integers >= 0"),
    ("bottle", {"synthetic_sizes": [3, 2, 0]}, r"synthetic_sizes \(samples per throw\) must be an integer >= 2"),
    ("bottle", {"synthetic_sizes": [0, 2, 160]}, r"synthetic_sizes \(training throws\)"),
    ("theory", {"L_sweep": []}, "L_sweep must list at least one finite number"),
    ("quadrotor_learning", {"Ts": 0.0}, "Ts must be a finite number > 0"),
    ("quadrotor_mpc", {"Ts": -0.02}, "Ts must be a finite number > 0"),
    ("quadrotor_learning", {"n_waypoints": 0}, "n_waypoints must be an integer >= 2"),
    # values that depend on each other
    ("spiral", {"L": -1.0}, "L: .*not positive definite"),
    ("spiral", {"L": 250.0}, "unstable"),
    ("spiral", {"N": 0}, "N"),
    ("spiral", {"N": 101}, "need 1 <= N <= N_max < n_samples"),
    ("spiral", {"noise_std": 0.02}, "noise_sweep must hold 0 and the judged level"),
    ("theory", {"L_sweep": [5.0, -1.0]}, "L_sweep: .*not positive definite"),
    ("ablations", {"omega_range": [0.8, -0.4, 4.4]}, "empty"),
    ("ablations", {"t_switch": 9.5}, "need steady_window < t_switch"),
    ("observers", {"N": 1000}, "N must be an integer with 1 <= N < n_samples"),
    ("observers", {"settle": 1000}, "settle must be < n_samples"),
    ("observers", {"kf_tuning_low": [4.0, 0.04, -24.0]}, "kf_tuning_low must be <= kf_tuning_high"),
    ("neural_feedback", {"beta": -0.1}, "beta"),
    ("bottle", {"data": "fake"}, "data must be one of real, synthetic"),
    ("bottle", {"N": 160, "synthetic_sizes": [3, 2, 160]}, "N must be an integer with 1 <= N < the samples"),
    ("bottle", {"batch_time": 2000}, "batch_time must be <= 1058"),
    ("quadrotor_learning", {"seeds": [0, 0]}, "distinct"),
    ("quadrotor_learning", {"segment_length": 201}, "segment_length must be in 1..200"),
    ("quadrotor_mpc", {"u_max": [0.0]}, "positive thrust"),
    ("quadrotor_mpc", {"u_max_judged": 5.0}, "u_max_judged"),
    ("quadrotor_mpc", {"costs": ["paper"]}, "costs"),
    ("quadrotor_mpc", {"costs": ["as_flown", "as_flown"]}, "costs"),
    ("quadrotor_mpc", {"validation_flights": 0}, "validation_flights"),
    ("quadrotor_mpc", {"validation_vehicles": 0}, "validation_vehicles"),
    ("quadrotor_mpc", {"Gamma_adapnn_grid": [0.16, 0.16]}, "Gamma_adapnn_grid"),
    ("quadrotor_mpc", {"Gamma_adapnn_grid": [0.0]}, "Gamma_adapnn_grid"),
    ("quadrotor_mpc", {"Gamma_rtol": -0.01}, "Gamma_rtol"),
    ("quadrotor_mpc", {"R": [1.0, 1.0, 0.0, 1.0]}, "R must be positive definite"),
    ("quadrotor_mpc", {"L": -3.0}, "L: .*not positive definite"),
    ("quadrotor_mpc", {"transient_s": 6.0}, "transient_s must be shorter than the flight"),
    ("quadrotor_mpc", {"backend": "jax"}, "backend must be one of numba, torch"),
    ("quadrotor_mpc", {"qp": "gurobi"}, "qp must be one of cvxpy, osqp"),
    ("quadrotor_mpc", {"linearize_method": "backward"}, "linearize_method must be one of"),
    ("quadrotor_mpc", {"solver": "NOPE"}, "solver must be one of .*OSQP"),
    ("quadrotor_mpc", {"solver": "SCS"}, "qp 'osqp' solves with solver 'OSQP' only"),
    ("own_system", {"N": 500}, "N must be an integer with 1 <= N < n_test"),
    ("own_system", {"spiral_tune_samples": 2000}, "spiral_tune_samples <= spiral_n_samples"),
    ("own_system", {"L0": -5.0}, "L0: .*not positive definite"),
    ("own_system", {"hand_L_grid": [2.0, 150.0]}, "hand_L_grid"),
    ("own_system", {"tune_iterations": 60}, "the same budget"),  # 60 Adam steps against a 36-point sweep
    ("own_system", {"hand_L_grid": [2.0, 5.0, 20.0], "hand_beta_grid": [0.02, 0.1, 0.5]}, "the same budget"),
    ("tuned_gains", {"bottle_tune_iterations": 9}, "the same budget"),
    ("tuned_gains", {"quad_hand_L_grid": [1.5, 3.0]}, "the same budget"),
    ("tuned_gains", {"bottle_tune_iterations": 0}, "bottle_tune_iterations must be an integer >= 1"),
    ("tuned_gains", {"quad_tune_cases": 0}, "quad_tune_cases"),
    ("tuned_gains", {"quad_L_grid": [0.0, 3.0]}, "quad_L_grid must list gains > 0"),
    ("tuned_gains", {"bottle_tune_throws": 0}, "bottle_tune_throws must be an integer >= 1"),
    ("why_feedback_point", {"change": {"batch_size": 10}}, "change must be a mapping with keys among optimizer"),
    ("why_feedback_point", {"change": {"optimizer": "sgd"}}, "change.optimizer must be one of"),
    ("why_feedback_point", {"change": {"lr_times": 0.0}}, "change.lr_times"),
    ("why_feedback_point", {"change": [1]}, "change must be a mapping"),
    ("why_feedback", {"authors_feedback": "FeedbackNN_nope.pt"}, "authors_feedback must be one of"),
    ("why_quadrotor_point", {"u_max": 0.0}, "u_max must be a finite number > 0"),
    ("why_quadrotor_point", {"Gamma_grid": [0.0, 8.0]}, "Gamma_grid must list at least 2 gains > 0"),
    ("why_quadrotor_point", {"Gamma_adapnn_grid": [0.16]}, "Gamma_adapnn_grid must list at least 2 gains > 0"),
    ("why_quadrotor_point", {"Gamma_grid": [8.0, 8.0]}, "Gamma_grid"),
])
def test_bad_values_are_refused(notebook: str, change: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        check_notebook_settings(notebook, {**_defaults(notebook), **change})


def test_missing_and_corrupt_data(tmp_path: Path) -> None:
    real = {**_defaults("bottle"), "data": "real", "data_dir": str(tmp_path)}
    with pytest.raises(MissingDataError, match="data missing: Training_dataset.mat, Testing_dataset.mat"):
        check_notebook_settings("06_bottle.ipynb", real)
    (tmp_path / "bottle").mkdir()
    for name in BOTTLE_FILES:
        (tmp_path / "bottle" / name).write_bytes(b"not the published throws")
    with pytest.raises(DataError, match=r"Training_dataset.mat has SHA-256 [0-9a-f]{64}, not the pinned") as err:
        check_notebook_settings("bottle", real)
    assert not isinstance(err.value, MissingDataError)  # the runner tells the two apart by type
    check_notebook_settings("bottle", {**real, "data": "synthetic"})  # synthetic throws read no file


def test_pinned_files_pass(tmp_path: Path) -> None:
    (tmp_path / "a.bin").write_bytes(b"abc")
    digest = "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"  # SHA-256 of b"abc"
    assert C.data_files(tmp_path, {"a.bin": digest}) == [tmp_path / "a.bin"]


def test_unknown_notebooks_and_missing_settings_are_errors() -> None:
    with pytest.raises(ValueError, match="no notebook of the book is named 'my_own_notebook'; the notebooks are spiral"):
        check_notebook_settings("my_own_notebook", {"L": -1.0})
    with pytest.raises(ValueError, match="no notebook of the book is named '01_spirals.ipynb'"):
        notebook_presets("01_spirals.ipynb")
    with pytest.raises(ValueError, match="setting.* missing: .*N_max"):  # Ts, N, ... come from the presets
        check_notebook_settings("spiral", {"L": 20.0})


def test_a_notebook_is_the_books_by_the_name_it_checks_with(tmp_path: Path) -> None:
    import nbformat

    def notebook(source: str) -> Path:
        nb = nbformat.v4.new_notebook()
        nb.cells.append(nbformat.v4.new_code_cell(source))
        path = tmp_path / f"nb{len(list(tmp_path.iterdir()))}.ipynb"
        nbformat.write(nb, path)
        return path

    assert S.notebook_name(notebook('check_notebook_settings("bottle", globals())')) == "bottle"
    assert S.notebook_name(notebook("x = 1")) is None  # one of your own: no presets, no value checks
    with pytest.raises(ValueError, match="no notebook of the book is named 'botle'"):
        S.notebook_name(notebook('F.check_notebook_settings("botle", globals())'))
    for path in NOTEBOOKS:
        assert S.notebook_name(path) == _name(path)


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_a_shared_paper_value_is_left_to_its_preset(notebook: Path) -> None:
    """Every preset parameter is ``None`` in the cell (the value is written once, in the presets)."""
    declared, presets = read_parameters(notebook), notebook_presets(notebook.stem)
    assert set(presets) <= set(declared), f"presets for parameters {notebook.name} does not declare"
    written = {k: declared[k] for k in presets if declared[k] is not None}
    assert not written, f"{notebook.name} writes preset values again: {written}"


def test_presets_fill_none_in_place_and_print(capsys: pytest.CaptureFixture[str]) -> None:
    settings = {**_defaults("theory"), "L": 10.0}
    check_notebook_settings("02_theory", settings)
    assert settings["Ts"] == 0.01 and settings["n_samples"] == 1000 and settings["test"] == [3.0, 0.05, 10.0]
    assert settings["L"] == 10.0  # an override is kept
    out = capsys.readouterr().out
    assert "Ts = 0.01" in out and "L =" not in out
    check_notebook_settings("02_theory", settings)  # nothing left to fill: silent
    assert capsys.readouterr().out == ""


def test_a_read_only_mapping_is_checked_with_its_presets() -> None:
    frozen = MappingProxyType(_defaults("observers"))
    check_notebook_settings("observers", frozen)
    with pytest.raises(ValueError, match="not positive definite"):
        check_notebook_settings("observers", MappingProxyType({**frozen, "L": -1.0}))
    assert frozen["L"] is None  # untouched


def test_preset_values_are_plain_and_one_source() -> None:
    """Tuples become lists; the same paper value reaches every notebook that shares it."""
    from fnnlib import spiral_presets as SP
    assert all(not isinstance(v, tuple) for name in NOTEBOOK_PRESETS for v in notebook_presets(name).values())
    for name in ("spiral", "theory", "ablations", "observers", "neural_feedback"):
        assert notebook_presets(name)["Ts"] == SP.SPIRAL_TS
    assert notebook_presets("own_system")["spiral_L"] == notebook_presets("spiral")["L"] == SP.PAPER_SPIRAL_L


@pytest.mark.parametrize(("check", "args", "message"), [
    (C.integer, ("iterations", True), "iterations must be an integer >= 0, got True"),
    (C.positive, ("lr", float("inf")), "lr must be a finite number > 0"),
    (C.nonnegative, ("beta", "0.1"), "beta must be a finite number >= 0"),
    (C.numbers, ("x0", [9.0, float("nan")], 2), "x0 must list 2 finite numbers"),
    (C.some_of, ("costs", [], ("a", "b")), "costs must list one or more of a, b"),
    (C.horizon, ("N", 50), "N must be an integer with 1 <= N < n_samples = 50"),
])
def test_the_plain_checks_name_the_setting(check: Any, args: tuple[Any, ...], message: str) -> None:
    kwargs = {"below": 50, "below_name": "n_samples"} if check is C.horizon else {}
    with pytest.raises(ValueError, match=re.escape(message)):
        check(*args, **kwargs)
