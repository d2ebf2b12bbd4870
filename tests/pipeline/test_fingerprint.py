"""The fingerprint covers everything that can change a task's result, and no more; a rerun names its trigger.

Code: the modules of the packages searched that the notebook imports, transitively, without docstrings and
comments. Environment: the installed distributions. Data: the files the task declares, through symlinks, empty
folders counted. Each test would have failed with the earlier fingerprint (fnnlib's ``*.py`` bytes only, no
environment, every file of the data directory, no symlinks followed, no folders).
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest
import yaml

import fnnbook
import fnnlib
from fnnbook import check, load_spec, run
from fnnbook.fingerprint import code_digest, imported_modules, notebook_code, package_roots, trigger
from fnnbook.outcome import Action
from fnnbook.runner import decide

from .nbfactory import CHILD_BODY, CHILD_PARAMS, LEAF_BODY, LEAF_PARAMS, MakePipeline, child_task, leaf_task, write_notebook

REPO = Path(__file__).resolve().parents[2]

RULES = '''"""The package's rules."""
# a comment
FACTOR = 2.0


def rule(x):
    """Whether x passes."""
    return x > FACTOR
'''


def _reruns(spec: Any, profile: str = "smoke", **kw: Any) -> dict[str, str]:
    """Task -> trigger, for every task the next run would run."""
    plan = check(spec, profile, **kw)
    return {n: d.reason for n, d in decide(spec, plan).items() if d.action is Action.RUN}


@pytest.fixture
def package_pipeline(make_pipeline: MakePipeline, tmp_path: Path) -> tuple[Any, Path]:
    """leaf imports ``pkgx.rules``, child (upstream leaf) imports ``pkgx.other``; both ran once."""
    pkg = tmp_path / "pkgx"
    pkg.mkdir()
    (pkg / "__init__.py").write_text('"""A package."""\n')
    (pkg / "rules.py").write_text(RULES)
    (pkg / "other.py").write_text("from . import helpers\nVALUE = 1\n")
    (pkg / "helpers.py").write_text("HELP = 1\n")
    write_notebook(tmp_path / "notebooks" / "leaf.ipynb", LEAF_PARAMS, "import pkgx.rules\n" + LEAF_BODY)
    write_notebook(tmp_path / "notebooks" / "child.ipynb", CHILD_PARAMS, "from pkgx import other\n" + CHILD_BODY)
    spec = load_spec(make_pipeline({"leaf": leaf_task(), "child": child_task()}))
    assert run(spec, "smoke", progress_bar=False, echo=lambda _: None, sources=[pkg]).ok
    assert _reruns(spec, sources=[pkg]) == {}
    return spec, pkg


def test_a_module_change_reruns_exactly_its_importers(package_pipeline: tuple[Any, Path]) -> None:
    spec, pkg = package_pipeline
    (pkg / "helpers.py").write_text("HELP = 2\n")  # imported by other (a relative import), which child imports
    assert _reruns(spec, sources=[pkg]) == {"child": "code: pkgx.helpers"}
    (pkg / "helpers.py").write_text("HELP = 1\n")
    (pkg / "rules.py").write_text(RULES.replace("FACTOR = 2.0", "FACTOR = 1.5"))  # the rule made stricter
    assert _reruns(spec, sources=[pkg]) == {"leaf": "code: pkgx.rules", "child": "upstream: leaf reruns"}


def test_a_docstring_or_comment_edit_reruns_nothing(package_pipeline: tuple[Any, Path]) -> None:
    spec, pkg = package_pipeline
    (pkg / "rules.py").write_text(RULES.replace("Whether x passes.", "Whether x passes the bar (Eq. (9)).")
                                  .replace("# a comment", "# another comment\n# and one more"))
    (pkg / "__init__.py").write_text('"""The package, described anew."""\n')
    assert _reruns(spec, sources=[pkg]) == {}


def test_an_environment_change_reruns_everything(package_pipeline: tuple[Any, Path],
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    spec, pkg = package_pipeline
    import fnnbook.runner as runner  # noqa: PLC0415

    env = runner.environment()
    monkeypatch.setattr(runner, "environment", lambda: {**env, "numpy": "0.0.1"})  # another numpy installed
    assert _reruns(spec, sources=[pkg]) == {"leaf": "environment: numpy", "child": "upstream: leaf reruns"}


def test_run_and_list_name_the_trigger(package_pipeline: tuple[Any, Path], capsys: pytest.CaptureFixture[str],
                                       monkeypatch: pytest.MonkeyPatch) -> None:
    spec, pkg = package_pipeline
    (pkg / "other.py").write_text("from . import helpers\nVALUE = 2\n")
    lines: list[str] = []
    report = run(spec, "smoke", progress_bar=False, echo=lines.append, sources=[pkg])
    assert report.outcome("child").status == "ok" and report.outcome("leaf").status == "skipped"
    assert "child reruns: code: pkgx.other" in lines
    # list (it searches the default packages, fnnlib and fnnbook: pkgx's modules leave leaf's code)
    from fnnbook.cli import main  # noqa: PLC0415

    import fnnbook.runner as runner  # noqa: PLC0415

    env = runner.environment()
    monkeypatch.setattr(runner, "environment", lambda: {**env, "numpy": "0.0.1"})
    assert main(["list", "--pipeline", str(spec.path)]) == 0
    out = capsys.readouterr().out
    leaf = next(line for line in out.splitlines() if "claims S1" in line)
    assert "smoke: stale (code: pkgx, pkgx.rules; environment: numpy)" in leaf
    assert "smoke: stale (upstream: leaf reruns)" in out


def _data_pipeline(make_pipeline: MakePipeline, tmp_path: Path, **task: Any) -> Any:
    write_notebook(tmp_path / "notebooks" / "leaf.ipynb",
                   'profile = ""\nout_dir = ""\ndata_dir = ""\nvalue = 1\n', "pass")
    return load_spec(make_pipeline({"leaf": {**leaf_task(), "products": [], **task}}))


def test_an_unrelated_data_folder_reruns_nothing(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    spec = _data_pipeline(make_pipeline, tmp_path, data=["bottle/"])
    (tmp_path / "data" / "bottle").mkdir(parents=True)
    (tmp_path / "data" / "bottle" / "throws.mat").write_bytes(b"abc")
    assert run(spec, "smoke", progress_bar=False, echo=lambda _: None).ok
    (tmp_path / "data" / "cascaded_tanks").mkdir()
    (tmp_path / "data" / "cascaded_tanks" / "tanks.mat").write_bytes(b"unrelated")
    (tmp_path / "data" / "notes.txt").write_text("unrelated")
    assert _reruns(spec) == {}
    (tmp_path / "data" / "bottle" / "throws.mat").write_bytes(b"abd")
    assert _reruns(spec) == {"leaf": "data: bottle/throws.mat"}


def test_a_file_behind_a_data_symlink_and_an_empty_folder_count(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    spec = _data_pipeline(make_pipeline, tmp_path, data=["release/"])
    elsewhere = tmp_path / "elsewhere"
    (elsewhere / "spiral_curve").mkdir(parents=True)
    (elsewhere / "spiral_curve" / "net.pt").write_bytes(b"weights")
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "release").symlink_to(elsewhere, target_is_directory=True)
    assert run(spec, "smoke", progress_bar=False, echo=lambda _: None).ok
    assert _reruns(spec) == {}
    (elsewhere / "spiral_curve" / "net.pt").write_bytes(b"other weights")  # changed behind the symlink
    assert _reruns(spec) == {"leaf": "data: release/spiral_curve/net.pt"}
    (elsewhere / "spiral_curve" / "net.pt").write_bytes(b"weights")
    (elsewhere / "quadrotor").mkdir()  # an empty folder: it changes what a notebook finds
    assert _reruns(spec) == {"leaf": "data: release/quadrotor/"}


# ---------------------------------------------------------------- the repository's own notebooks
def _closure(notebook: str, roots: dict[str, Path] | None = None) -> dict[str, str]:
    return imported_modules(notebook_code(REPO / "notebooks" / f"{notebook}.ipynb"), roots or package_roots())


def test_the_notebooks_depend_on_the_fnnbook_modules_they_import() -> None:
    observers, bottle = _closure("04_observers"), _closure("06_bottle")
    assert {"fnnbook.rules.sec3", "fnnbook.tasks.observers", "fnnbook.tasks._spiral", "fnnlib.feedback.layer",
            "fnnlib.observers"} <= set(observers)
    assert "fnnbook.tasks.bottle" in bottle and "fnnbook.tasks.observers" not in bottle
    assert "fnnbook.rules.sec3" not in bottle and "fnnbook.rules.bottle" in bottle
    assert {"fnnbook.feedback_eval", "fnnlib.paper.feedback_eval"} <= set(_closure("14_why_feedback"))
    assert "fnnbook.feedback_eval" not in observers and "fnnlib.paper.feedback_eval" not in observers
    for name in ("fnnbook.runner", "fnnbook.executor", "fnnbook.book"):  # the machinery is no input
        assert name not in observers


def _copy_packages(tmp_path: Path) -> list[Path]:
    dest = []
    for pkg in (fnnlib, fnnbook):
        src = Path(pkg.__file__).resolve().parent
        shutil.copytree(src, tmp_path / src.name, ignore=shutil.ignore_patterns("__pycache__"))
        dest.append(tmp_path / src.name)
    return dest


def test_a_stricter_rule_changes_the_fingerprints_of_its_tasks_only(tmp_path: Path) -> None:
    """The red team's case: sec3's S11 rival factor 2.0 -> 1.5 (and a feedback_eval edit), on the real pipeline."""
    spec = load_spec(REPO / "pipeline.yaml").with_paths(data_dir=tmp_path / "data", output_root=tmp_path / "out")
    (tmp_path / "data").mkdir()
    packages = _copy_packages(tmp_path)
    before = check(spec, "smoke", sources=packages)
    sec3 = tmp_path / "fnnbook" / "rules" / "sec3.py"
    text = sec3.read_text()
    assert text.count("rival_factor: float = 2.0") == 1, "the S11 rule's signature moved: update this test"
    sec3.write_text(text.replace("rival_factor: float = 2.0", "rival_factor: float = 1.5"))
    after = check(spec, "smoke", sources=packages)
    changed = {n for n in before.order if before.fingerprints[n] != after.fingerprints[n]}
    importers = {n for n in before.order if "fnnbook.rules.sec3" in before.inputs[n]["code"]}
    assert {"spiral", "theory", "ablations", "observers"} <= importers and "bottle" not in importers
    downstream = {n for n in before.order if set(spec.closure([n])) & importers}
    assert changed == downstream
    for name in importers:  # (one downstream of another importer names its upstream too)
        assert trigger(before.inputs[name], after.inputs[name]).startswith("code: fnnbook.rules.sec3")
    assert trigger(before.inputs["spiral"], after.inputs["spiral"]) == "code: fnnbook.rules.sec3"
    # a docstring of the library's Eq. (7)-(8) kernel reworded, a comment added: no fingerprint moves
    layer = tmp_path / "fnnlib" / "feedback" / "layer.py"
    layer.write_text(layer.read_text().replace('"""', '"""Reworded. ', 1) + "\n# a comment\n")
    assert check(spec, "smoke", sources=packages).fingerprints == after.fingerprints
    evaluation = tmp_path / "fnnbook" / "feedback_eval.py"
    evaluation.write_text(evaluation.read_text() + "\nEXTRA = 1\n")
    moved = check(spec, "smoke", sources=packages)
    assert trigger(after.inputs["why_feedback"], moved.inputs["why_feedback"]).startswith("code: fnnbook.feedback_eval")
    assert moved.fingerprints["observers"] == after.fingerprints["observers"]
    science = tmp_path / "fnnlib" / "paper" / "feedback_eval.py"  # the evaluation itself, in the library
    science.write_text(science.read_text() + "\nEXTRA = 1\n")
    again = check(spec, "smoke", sources=packages)
    assert trigger(moved.inputs["why_feedback"], again.inputs["why_feedback"]).startswith(
        "code: fnnlib.paper.feedback_eval")
    assert again.fingerprints["observers"] == moved.fingerprints["observers"]


def test_a_changed_setting_default_or_check_reruns_its_tasks_only(tmp_path: Path) -> None:
    """A task's settings home (its module in fnnbook.tasks, and the groups it shares) is code it imports: a changed
    paper value or check there changes its fingerprint, and its downstream tasks', no other."""
    spec = load_spec(REPO / "pipeline.yaml").with_paths(data_dir=tmp_path / "data", output_root=tmp_path / "out")
    (tmp_path / "data").mkdir()
    packages = _copy_packages(tmp_path)
    before = check(spec, "smoke", sources=packages)
    home = tmp_path / "fnnbook" / "tasks" / "quick_start.py"
    text = home.read_text()
    assert text.count("setting(300, N2)") == 1, "quick_start's T moved: update this test"
    home.write_text(text.replace("setting(300, N2)", "setting(301, N2)"))  # a paper value
    after = check(spec, "smoke", sources=packages)
    changed = {n for n in before.order if before.fingerprints[n] != after.fingerprints[n]}
    assert changed == {n for n in before.order if "quick_start" in spec.closure([n])}
    assert trigger(before.inputs["quick_start"], after.inputs["quick_start"]) == "code: fnnbook.tasks.quick_start"
    shared = tmp_path / "fnnbook" / "tasks" / "_spiral.py"
    text = shared.read_text()
    assert text.count("w < self.t_switch < end - w") == 1, "the switch check moved: update this test"
    shared.write_text(text.replace("w < self.t_switch < end - w", "w <= self.t_switch < end - w"))  # a check
    moved = check(spec, "smoke", sources=packages)
    changed = {n for n in before.order if after.fingerprints[n] != moved.fingerprints[n]}
    assert {"spiral", "ablations", "why_sec3"} <= changed and not changed & {"bottle", "quadrotor_mpc", "quick_start"}
    assert trigger(after.inputs["spiral"], moved.inputs["spiral"]) == "code: fnnbook.tasks._spiral"


def test_code_digest_ignores_docstrings_and_comments_only() -> None:
    base = code_digest(RULES)
    assert code_digest(RULES.replace("Whether x passes.", "Reworded.").replace("# a comment", "")) == base
    assert code_digest(RULES.replace("x > FACTOR", "x >= FACTOR")) != base
    assert code_digest("def f():\n    '''doc'''\n") == code_digest("def f():\n    pass\n")


def _dist_info(folder: Path, name: str, version: str) -> None:
    info = folder / f"{name}-{version}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n", encoding="utf-8")


def test_the_environment_is_read_again_exactly_when_an_install_changes_a_path_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The environment is cached (reading every distribution's metadata costs ~0.2 s per run): an install,
    an upgrade or a removal in a folder of sys.path is seen at the next call, and nothing else rereads it."""
    from importlib import metadata  # noqa: PLC0415

    from fnnbook import fingerprint  # noqa: PLC0415

    site = tmp_path / "site"
    site.mkdir()
    _dist_info(site, "pkg-one", "1.0")
    monkeypatch.syspath_prepend(str(site))
    reads = []
    real = metadata.distributions
    monkeypatch.setattr(metadata, "distributions", lambda: reads.append(1) or real())
    first = fingerprint.environment()
    assert first["pkg-one"] == "1.0" and len(reads) == 1
    assert fingerprint.environment() == first and len(reads) == 1  # nothing changed: not read again
    shutil.rmtree(site / "pkg-one-1.0.dist-info")  # an upgrade
    _dist_info(site, "pkg-one", "2.0")
    _dist_info(site, "pkg-two", "0.1")  # an install
    second = fingerprint.environment()
    assert len(reads) == 2 and second["pkg-one"] == "2.0" and second["pkg-two"] == "0.1"
    shutil.rmtree(site / "pkg-two-0.1.dist-info")  # a removal
    assert "pkg-two" not in fingerprint.environment() and len(reads) == 3
