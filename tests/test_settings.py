"""fnnbook.tasks: every notebook's settings in one frozen dataclass, paper values and checks together, checked
before any work; fnnlib.checks underneath."""

from __future__ import annotations

import dataclasses
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from fnnbook import read_parameters
from fnnbook.params import INJECTED, SETTINGS_MARK, parameters_cell, resolve_parameters, task_defaults
from fnnbook.spec import load_spec
from fnnbook.tasks import NOTEBOOKS, notebook_name, settings_class
from fnnbook.tasks import _checks as K
from fnnbook.tasks._base import TaskSettings, setting
from fnnlib import checks as C
from fnnlib.checks import MissingDataError
from fnnlib.data.bottle import BOTTLE_FILES, DataError

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK_FILES = sorted((ROOT / "notebooks").glob("*.ipynb"))
SYNTHETIC = {"bottle": {"data": "synthetic"}, "cascaded_tanks": {"data": "synthetic"}}  # CI has no real data


def _name(notebook: Path) -> str:
    return re.sub(r"^\d+_", "", notebook.stem)  # 01_spiral -> spiral


def make(notebook: str, **change: Any) -> TaskSettings:
    """The notebook's settings with ``change`` (and synthetic data where it reads data files), checked."""
    return settings_class(notebook).from_mapping({**SYNTHETIC.get(notebook, {}), **change})


def test_every_notebook_has_its_settings() -> None:
    assert sorted(_name(p) for p in NOTEBOOK_FILES) == list(NOTEBOOKS)
    for path in NOTEBOOK_FILES:
        assert notebook_name(path) == _name(path)
        assert settings_class(path.name).notebook == _name(path)


@pytest.mark.parametrize("notebook", NOTEBOOKS)
def test_the_paper_values_pass(notebook: str) -> None:
    settings = make(notebook)
    assert dataclasses.is_dataclass(settings)
    with pytest.raises(dataclasses.FrozenInstanceError):
        settings.anything = 1  # type: ignore[attr-defined]


@pytest.mark.parametrize("notebook", NOTEBOOKS)
def test_every_setting_has_a_check(notebook: str) -> None:
    for f in dataclasses.fields(settings_class(notebook)):
        assert callable(f.metadata.get("check")), f"{notebook}.{f.name} has no check"


@pytest.mark.parametrize("path", NOTEBOOK_FILES, ids=[p.stem for p in NOTEBOOK_FILES])
def test_the_parameters_cell_is_written_from_the_settings(path: Path) -> None:
    """The cell lists the injected names and then every setting with its paper value, as the dataclass has them
    (``make notebooks`` writes it): no value of the cell is written by hand, and no ``None`` placeholder."""
    cls = settings_class(_name(path))
    declared = read_parameters(path)
    assert {k: v for k, v in declared.items() if k not in INJECTED} == cls.defaults()
    assert None not in [v for k, v in declared.items() if k not in INJECTED]
    source = next(c for c in __import__("nbformat").read(path, as_version=4).cells
                  if "parameters" in c.metadata.get("tags", [])).source
    assert SETTINGS_MARK.format(name=cls.notebook) in source
    assert parameters_cell(cls.notebook, source) == source + "\n" * (not source.endswith("\n"))


def test_the_cell_writer_follows_a_changed_default(monkeypatch: pytest.MonkeyPatch) -> None:
    cls = settings_class("quick_start")
    source = parameters_cell("quick_start", 'profile = "paper"\nout_dir = "x"\nT = None\n')
    assert source.splitlines()[:3] == ['profile = "paper"', 'out_dir = "x"', SETTINGS_MARK.format(name="quick_start")]
    assert "T = 300" in source and "None" not in source
    monkeypatch.setattr(cls, "defaults", classmethod(lambda c: {"T": 400}))
    assert parameters_cell("quick_start", source).endswith(SETTINGS_MARK.format(name="quick_start") + "\nT = 400\n")


def test_the_sources_cells_are_current() -> None:
    """``tools/write_parameters_cells.py --check``: every notebooks/src cell is its dataclass's."""
    done = subprocess.run([sys.executable, str(ROOT / "tools" / "write_parameters_cells.py"), "--check"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def _kind_bad_values() -> dict[Any, Any]:
    """A value each shared check refuses: the bound it checks, just crossed."""
    return {K.N1: 0, K.N0: -1, K.N2: 1, K.POS: 0.0, K.NONNEG: -0.5, K.SEED: -1, K.SEEDS2: [3], K.SEEDS1: [],
            K.BOOL: "yes", K.WIDTHS: [16, 0], K.GRID: [1.0, -0.5, 2.0], K.SPIRAL3: [2.0, 0.1], K.X0: [9.0],
            K.ACT: "sigmoid", K.METHOD: "rk45", K.OPTIMIZER: "sgd", K.SWEEP0: [], K.GAINS: [],
            K.GAIN: float("nan"), K.synthetic_sizes: [21, 9, 0], K.GRID0: [-1.0]}


CASES = [(name, f.name, f.metadata["check"]) for name in NOTEBOOKS
         for f in dataclasses.fields(settings_class(name))]


@pytest.mark.parametrize(("notebook", "param", "check"), CASES, ids=[f"{n}.{p}" for n, p, _ in CASES])
def test_each_bad_value_is_refused_naming_its_parameter(notebook: str, param: str, check: Any) -> None:
    default = settings_class(notebook).defaults()[param]
    bad = _kind_bad_values().get(check, [] if isinstance(default, list) else "bogus")
    with pytest.raises(ValueError, match=rf"^{re.escape(param)}( \(.*\))?( must |: )"):  # its own check, first
        make(notebook, **{param: bad})


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
        make(notebook, **change)


@pytest.mark.parametrize(("notebook", "change", "message"), [
    ("ablations", {"gain_range": [0.0, 100.0, 300.0]}, "gain_range: .*unstable"),
    ("ablations", {"gain_range": [0.0, 5.0, 45.0], "Ts": 0.05}, "gain_range: .*unstable"),
    ("why_beyond", {"objectives": ["one_step", "multi_step"]}, "objectives must hold 'judged'"),
])
def test_checks_the_notebooks_made_themselves_are_the_settings_now(notebook: str, change: dict[str, Any],
                                                                   message: str) -> None:
    """Checks a notebook ran in its own cells, moved into its dataclass (each check written once)."""
    with pytest.raises(ValueError, match=message):
        make(notebook, **change)


def test_no_notebook_repeats_a_check_of_its_settings() -> None:
    """The gain, horizon and switch checks live in the dataclasses: no notebook source runs them again on its own
    settings (``F.check_gain(L, 2, Ts)``, ``need 1 <= N``; a check against an upstream run's values stays)."""
    for src in sorted((ROOT / "notebooks" / "src").glob("*.py")):
        text = src.read_text(encoding="utf-8")
        assert not re.search(r"check_gain\((L|g), \d, Ts\)", text), src.name
        assert "need 1 <= N" not in text and "check_notebook_settings" not in text, src.name


def test_missing_and_corrupt_data(tmp_path: Path) -> None:
    with pytest.raises(MissingDataError, match="data missing: Training_dataset.mat, Testing_dataset.mat"):
        settings_class("06_bottle.ipynb")(data="real", data_dir=str(tmp_path))
    (tmp_path / "bottle").mkdir()
    for name in BOTTLE_FILES:
        (tmp_path / "bottle" / name).write_bytes(b"not the published throws")
    with pytest.raises(DataError, match=r"Training_dataset.mat has SHA-256 [0-9a-f]{64}, not the pinned") as err:
        settings_class("bottle").from_mapping({"data": "real"}, data_dir=str(tmp_path))
    assert not isinstance(err.value, MissingDataError)  # the runner tells the two apart by type
    settings_class("bottle")(data="synthetic", data_dir=str(tmp_path))  # synthetic throws read no file
    settings_class("bottle")(data="real")  # no data directory given: the files are not looked for


def test_pinned_files_pass(tmp_path: Path) -> None:
    (tmp_path / "a.bin").write_bytes(b"abc")
    digest = "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"  # SHA-256 of b"abc"
    assert C.data_files(tmp_path, {"a.bin": digest}) == [tmp_path / "a.bin"]


def test_unknown_notebooks_and_unknown_settings_are_errors() -> None:
    with pytest.raises(ValueError, match="no notebook of the book is named 'my_own_notebook'; the notebooks are "
                                         "ablations"):
        settings_class("my_own_notebook")
    with pytest.raises(ValueError, match="no notebook of the book is named '01_spirals.ipynb'"):
        settings_class("01_spirals.ipynb")
    with pytest.raises(ValueError, match="notebook 'spiral' has no setting 'N_mx'; did you mean 'N_max'"):
        make("spiral", N_mx=20)


def test_a_notebook_is_the_books_by_the_settings_it_imports(tmp_path: Path) -> None:
    import nbformat

    def notebook(source: str) -> Path:
        nb = nbformat.v4.new_notebook()
        nb.cells.append(nbformat.v4.new_code_cell(source))
        path = tmp_path / f"nb{len(list(tmp_path.iterdir()))}.ipynb"
        nbformat.write(nb, path)
        return path

    assert notebook_name(notebook("from fnnbook.tasks.bottle import BottleSettings")) == "bottle"
    assert notebook_name(notebook("x = 1")) is None  # one of your own: no settings class, no value checks
    with pytest.raises(ValueError, match="no notebook of the book is named 'botle'"):
        notebook_name(notebook("from fnnbook.tasks.botle import BottleSettings"))


def test_a_notebook_builds_its_settings_from_its_variables(tmp_path: Path) -> None:
    """What the kernel does after the parameters cell (and papermill's injected values): its variables, checked;
    a setting it does not hold keeps its paper value; ``data_dir`` checks the data files."""
    names = {"profile": "paper", "out_dir": "x", "L": 10.0, "Ts": 0.01, "unrelated": object()}
    settings = settings_class("theory").from_namespace(names)
    assert settings.L == 10.0 and settings.n_samples == 1000 and settings.test == [3.0, 0.05, 10.0]
    with pytest.raises(ValueError, match="not positive definite"):
        settings_class("observers").from_namespace({"L": -1.0})
    with pytest.raises(MissingDataError):
        settings_class("cascaded_tanks").from_namespace({"data": "real", "data_dir": str(tmp_path)})


def test_a_settings_class_checks_itself_when_made() -> None:
    """A subclass's defaults pass through the same checks: a bad paper value cannot be written."""

    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Bad(TaskSettings):
        rate: float = setting(-1.0, K.POS)

    with pytest.raises(ValueError, match="rate must be a finite number > 0"):
        Bad()


def test_shared_values_are_plain_and_one_source() -> None:
    """Tuples become lists; the same paper value reaches every notebook that shares it."""
    from fnnlib.paper import spiral_presets as SP
    for name in NOTEBOOKS:
        for value in settings_class(name).defaults().values():
            assert not isinstance(value, tuple)
    for name in ("spiral", "theory", "ablations", "observers", "neural_feedback", "why_sec3"):
        assert settings_class(name).defaults()["Ts"] == SP.SPIRAL_TS
    assert settings_class("own_system").defaults()["spiral_L"] == settings_class("spiral").defaults()["L"] \
        == SP.PAPER_SPIRAL_L
    feedback, observers = settings_class("neural_feedback").defaults(), settings_class("observers").defaults()
    assert feedback["dr_omega_range"] == settings_class("why_feedback").defaults()["dr_omega_range"]
    ranges = [feedback[f"dr_{k}_range"] for k in ("omega", "eta", "eps")]  # S11's Kalman tuning: Alg. 1's range
    assert observers["kf_tuning_low"] == [r[0] for r in ranges] and observers["kf_tuning_high"] == [r[2] for r in ranges]


def _paper_profile_cases() -> list[tuple[str, str]]:
    spec = load_spec(ROOT / "pipeline.yaml")
    return [(profile, name) for profile in ("paper", "why") for name in spec.declares(profile)
            if spec.home(profile, name) == profile]


@pytest.mark.parametrize(("profile", "task"), _paper_profile_cases(), ids="/".join)
def test_the_paper_profile_runs_each_dataclass_defaults(profile: str, task: str, tmp_path: Path) -> None:
    """Where pipeline.yaml gives the paper (or why) profile no values, the task runs with its dataclass's
    defaults, each of them; a value the profile sets (a grid point's) is the only change."""
    spec = load_spec(ROOT / "pipeline.yaml")
    t = spec.tasks[task]
    declared = {k: v for k, v in read_parameters(t.notebook).items() if k != "data_dir"}
    params = resolve_parameters(spec, t, profile, declared, out_dir=tmp_path)
    defaults = settings_class(notebook_name(t.notebook) or "").defaults()
    overrides = dict(t.parameters[profile])
    raw = yaml.safe_load((ROOT / "pipeline.yaml").read_text(encoding="utf-8"))["tasks"]
    base = max((b for b in raw if task == b or task.startswith(b)), key=len)  # a grid point's task
    assert raw[base]["parameters"][profile] == {}  # pipeline.yaml: the paper values are the dataclass's
    assert set(overrides) <= set(raw[base].get("grid", {})) and set(overrides) <= set(defaults)
    assert {k: v for k, v in params.items() if k not in INJECTED} == {**defaults, **overrides}
    assert task_defaults(t, declared).keys() - set(INJECTED) == defaults.keys()


def test_a_changed_default_changes_what_the_paper_profile_runs(monkeypatch: pytest.MonkeyPatch,
                                                               tmp_path: Path) -> None:
    spec = load_spec(ROOT / "pipeline.yaml")
    t = spec.tasks["quick_start"]
    cls = settings_class("quick_start")
    monkeypatch.setattr(cls, "defaults", classmethod(lambda c: {"T": 400}))
    declared = read_parameters(t.notebook)
    assert resolve_parameters(spec, t, "paper", declared, out_dir=tmp_path)["T"] == 400


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
