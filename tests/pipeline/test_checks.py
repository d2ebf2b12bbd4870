"""What `fnn-pipeline check` (and the start of `run`) refuses before any work: duplicate YAML keys, a grid
read by name, bad notebook values, data files that are not the published ones. One line, exit code 2."""

from __future__ import annotations

import copy
import functools
from pathlib import Path
from typing import Any

import pytest
import yaml

from fnnbook import PipelineError, check, load_spec
from fnnbook.cli import main
from fnnlib.data.bottle import BOTTLE_FILES

from .nbfactory import CHILD_PARAMS, MakePipeline, child_task, leaf_task, write_notebook

REPO = Path(__file__).resolve().parents[2]


# -- duplicate keys
@pytest.mark.parametrize("text", [
    "tasks: {}\ntasks: {}\n",
    "tasks:\n  leaf:\n    title: a\n    title: b\n",
    "tasks:\n  leaf:\n    parameters:\n      smoke: {value: 1, value: 2}\n",
])
def test_a_key_written_twice_is_refused(tmp_path: Path, text: str) -> None:
    (tmp_path / "pipeline.yaml").write_text(text)
    with pytest.raises(PipelineError, match=r"pipeline.yaml, line \d+: key '(tasks|title|value)' is written twice"):
        load_spec(tmp_path / "pipeline.yaml")


def test_a_merged_key_may_still_be_overridden(make_pipeline: MakePipeline) -> None:
    """YAML's merge rule: the mapping's own key wins over one merged in with ``<<``, as pipeline.yaml uses it."""
    path = make_pipeline()
    text = path.read_text().replace("\ntasks:\n", "\nshared:\n  base: &base {value: 1, scale: 2.0}\ntasks:\n", 1)
    text = text.replace("      smoke:\n", "      smoke:\n        <<: *base\n", 1)  # smoke also sets value: 2
    path.write_text(text)
    assert load_spec(path).tasks["leaf"].parameters["smoke"] == {"value": 2, "scale": 2.0}


# -- a grid upstream is for aggregate steps only
AGG_BODY = "total = sum(1 for d in upstream_dirs.values())\n"


def test_a_grid_read_by_its_name_is_refused(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    """child reads upstream_dirs["leaf"]: with leaf a grid, it would fail with a KeyError after leaf ran."""
    spec = load_spec(make_pipeline({"leaf": {**leaf_task(), "grid": {"value": [1, 2]}}, "child": child_task()}))
    with pytest.raises(PipelineError, match=r"task 'child' lists the grid 'leaf' upstream but its notebook "
                                            r"child.ipynb reads upstream_dirs\['leaf'\]; .*'leaf__value_1'"):
        check(spec, "smoke")
    assert not (tmp_path / "outputs").exists()
    check(spec, "smoke", ["leaf"])  # the grid alone is fine


def test_a_default_that_names_the_grid_is_refused_and_an_aggregate_passes(make_pipeline: MakePipeline,
                                                                           tmp_path: Path) -> None:
    write_notebook(tmp_path / "notebooks" / "named.ipynb",
                   'profile = ""\nout_dir = ""\nupstream_dirs = {"leaf": "outputs/leaf"}\n', AGG_BODY)
    write_notebook(tmp_path / "notebooks" / "agg.ipynb", CHILD_PARAMS, AGG_BODY)
    grid = {**leaf_task(), "grid": {"value": [1, 2]}}
    named = {**child_task(), "notebook": "notebooks/named.ipynb", "products": []}
    spec = load_spec(make_pipeline({"leaf": grid, "named": named}))
    with pytest.raises(PipelineError, match="task 'named' lists the grid 'leaf' upstream"):
        check(spec, "smoke")
    agg = {**child_task(), "notebook": "notebooks/agg.ipynb", "products": []}
    assert check(load_spec(make_pipeline({"leaf": grid, "agg": agg})), "smoke").order[-1] == "agg"


# -- the book's pipeline with one bad value, through the command line
@functools.cache
def _repository_pipeline() -> dict[str, Any]:
    doc = yaml.safe_load((REPO / "pipeline.yaml").read_text())
    doc["claims_file"] = str(REPO / "claims.yaml")  # the registry; no claim IDs are needed here
    for task in doc["tasks"].values():
        task["notebook"] = str(REPO / task["notebook"])
        task["claims"] = []
    return doc


def _cli_check(tmp_path: Path, capsys: pytest.CaptureFixture[str], doc: dict[str, Any] | str,
               *tasks: str) -> tuple[int, str]:
    (tmp_path / "data").mkdir(exist_ok=True)
    path = tmp_path / "pipeline.yaml"
    path.write_text(doc if isinstance(doc, str) else yaml.safe_dump(doc))
    code = main(["check", "--pipeline", str(path), "--profile", "smoke", *tasks])
    return code, capsys.readouterr().err


BAD = [  # task, parameter, value, what the one line says
    ("spiral", "method", "rk45", "method must be one of"),
    ("spiral", "activation", "sigmoid", "activation must be one of"),
    ("spiral", "lr", 0.0, "lr must be a finite number > 0"),
    ("theory", "seed", -1, "seed must be an integer >= 0"),
    ("bottle", "synthetic_sizes", [3, 2, 0], r"synthetic_sizes \(samples per throw\) must be an integer >= 2"),
    ("theory", "L_sweep", [], "L_sweep must list at least one finite number"),
    ("quadrotor_learning", "Ts", 0.0, "Ts must be a finite number > 0"),
    ("quadrotor_mpc", "Ts", -0.02, "Ts must be a finite number > 0"),
    ("quadrotor_learning", "n_waypoints", 0, "n_waypoints must be an integer >= 2"),
]


@pytest.mark.parametrize(("task", "name", "value", "message"), BAD, ids=[f"{t}.{n}" for t, n, _, _ in BAD])
def test_a_bad_value_is_one_line_and_exit_code_2(tmp_path: Path, capsys: pytest.CaptureFixture[str], task: str,
                                                 name: str, value: Any, message: str) -> None:
    doc = copy.deepcopy(_repository_pipeline())
    doc["tasks"][task]["parameters"]["smoke"][name] = value
    code, err = _cli_check(tmp_path, capsys, doc, task)
    assert code == 2
    assert err.count("\n") == 1, err
    assert err.startswith(f"error: task {task!r}, profile 'smoke': ")
    assert __import__("re").search(message, err), err
    assert not (tmp_path / "outputs").exists()


def test_a_duplicate_key_and_a_grid_read_by_name_through_the_cli(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    text = yaml.safe_dump(_repository_pipeline(), sort_keys=False).replace(
        "output_root: outputs\n", "output_root: outputs\noutput_root: elsewhere\n", 1)
    code, err = _cli_check(tmp_path, capsys, text)
    assert (code, err.count("\n")) == (2, 1) and "key 'output_root' is written twice" in err, err
    doc = copy.deepcopy(_repository_pipeline())
    doc["tasks"]["spiral"]["grid"] = {"seeds": [[0, 1], [2, 3]]}
    code, err = _cli_check(tmp_path, capsys, doc, "theory")
    assert (code, err.count("\n")) == (2, 1) and "task 'theory' lists the grid 'spiral' upstream" in err, err


def test_data_files_that_are_not_the_published_ones(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    doc = copy.deepcopy(_repository_pipeline())
    doc["tasks"]["bottle"]["parameters"]["smoke"]["data"] = "real"
    (tmp_path / "data" / "bottle").mkdir(parents=True)
    code, out = main(["check", "--pipeline", str(_write(tmp_path, doc)), "--profile", "smoke", "bottle"]), \
        capsys.readouterr().out
    assert code == 0 and "note: bottle will not run: data missing: Training_dataset.mat" in out  # missing: not run
    for name in BOTTLE_FILES:
        (tmp_path / "data" / "bottle" / name).write_bytes(b"truncated")
    code, err = _cli_check(tmp_path, capsys, doc, "bottle")
    assert (code, err.count("\n")) == (2, 1), err
    assert "Training_dataset.mat has SHA-256" in err and "not the pinned" in err


def _write(tmp_path: Path, doc: dict[str, Any]) -> Path:
    path = tmp_path / "pipeline.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_the_tanks_chapter_without_its_data_file_is_not_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    doc = copy.deepcopy(_repository_pipeline())
    (tmp_path / "data").mkdir()
    code, out = main(["check", "--pipeline", str(_write(tmp_path, doc)), "--profile", "paper", "cascaded_tanks"]), \
        capsys.readouterr().out
    assert code == 0 and "note: cascaded_tanks will not run: data missing: dataBenchmark.mat" in out
    assert "fnn-pipeline data fetch --tanks" in out
