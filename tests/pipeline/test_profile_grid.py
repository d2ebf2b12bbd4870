"""A profile that runs a part of a grid (``profile_grid``): the other points do not run there, its aggregate step
reads only the points it ran, and the other profiles run the whole grid."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from fnnbook import PipelineError, check, load_spec, run
from fnnbook.cli import main
from fnnbook.runner import decide
from fnnbook.outcome import Action

from .nbfactory import CHILD_PARAMS, MakePipeline, leaf_task, write_notebook

AGG_BODY = """\
import pathlib
values = sorted(float((pathlib.Path(d) / "value.txt").read_text()) for d in upstream_dirs.values())
(pathlib.Path(out_dir) / "total.txt").write_text(" ".join(f"{v:g}" for v in values))
"""


def _tasks(tmp_path: Path, profile_grid: Any) -> dict[str, Any]:
    write_notebook(tmp_path / "notebooks" / "agg.ipynb", CHILD_PARAMS, AGG_BODY)
    point = {**leaf_task(), "claims": [], "grid": {"value": [1, 2, 3]}}
    if profile_grid is not None:
        point["profile_grid"] = profile_grid
    return {"pt": point,
            "agg": {"title": "Aggregate", "notebook": "notebooks/agg.ipynb", "upstream": ["pt"],
                    "products": ["total.txt"], "parameters": {"smoke": {}, "paper": {}}}}


def _spec(make_pipeline: MakePipeline, tmp_path: Path, profile_grid: Any = None, **top: Any):
    tasks = _tasks(tmp_path, profile_grid)
    return load_spec(make_pipeline(tasks, parts=[{"title": "P", "tasks": list(tasks)}], **top))


def test_the_profile_runs_its_part_of_the_grid_and_the_other_runs_all(make_pipeline: MakePipeline,
                                                                      tmp_path: Path) -> None:
    spec = _spec(make_pipeline, tmp_path, {"smoke": {"value": [1, 3]}})
    assert spec.grids["pt"] == ("pt__value_1", "pt__value_2", "pt__value_3")  # the grid as written
    assert spec.tasks["pt__value_2"].left_out == {"smoke"}
    assert spec.declares("smoke") == ["pt__value_1", "pt__value_3", "agg"]
    assert spec.declares("paper") == ["pt__value_1", "pt__value_2", "pt__value_3", "agg"]
    smoke = spec.for_profile("smoke")
    assert smoke.grids["pt"] == ("pt__value_1", "pt__value_3") and smoke.narrowed == ("pt__value_2",)
    assert smoke.tasks["agg"].upstream == ("pt__value_1", "pt__value_3")
    assert spec.for_profile("paper") is spec and smoke.for_profile("smoke") is smoke

    lines: list[str] = []
    report = run(spec, "smoke", progress_bar=False, echo=lines.append)
    assert report.ok, lines
    assert [o.task for o in report.outcomes] == ["pt__value_1", "pt__value_3", "agg"]
    assert (spec.output_dir("smoke", "agg") / "total.txt").read_text() == "1 3"  # the points it ran, no others
    assert not spec.output_dir("smoke", "pt__value_2").exists()
    # the next run finds it all up to date: the aggregate's record names the points the profile runs
    assert {d.action for d in decide(spec, check(spec, "smoke")).values()} == {Action.SKIP}
    report = run(spec, "smoke", progress_bar=False, echo=lines.append)
    assert {o.status for o in report.outcomes} == {"skipped"}

    report = run(spec, "paper", ["agg"], progress_bar=False, echo=lines.append)
    assert report.ok, lines
    assert (spec.output_dir("paper", "agg") / "total.txt").read_text() == "1 2 3"

    with pytest.raises(PipelineError, match=r"grid point 'pt__value_2' is not run in this profile"):
        check(spec, "smoke", ["pt__value_2"])
    assert check(spec, "paper", ["pt__value_2"]).order == ("pt__value_2",)


def test_list_says_which_points_a_profile_leaves_out(make_pipeline: MakePipeline, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    spec = _spec(make_pipeline, tmp_path, {"smoke": {"value": [1, 3]}})
    assert main(["list", "--pipeline", str(spec.path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    said = {lines[i].split()[0]: lines[i + 1] for i in range(len(lines) - 1) if lines[i].startswith("  pt__")}
    assert "smoke: not in its profile_grid" in said["pt__value_2"] and "paper: not run" in said["pt__value_2"]
    assert "smoke: not run" in said["pt__value_1"] and "profile_grid" not in said["pt__value_1"]


def test_a_profile_grid_that_leaves_nothing_out_changes_nothing(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    spec = _spec(make_pipeline, tmp_path, {"smoke": {"value": [3, 2, 1]}})
    assert spec.for_profile("smoke") is spec and not any(t.left_out for t in spec.tasks.values())


@pytest.mark.parametrize(("profile_grid", "message"), [
    ({"smok": {"value": [1]}}, r"profile_grid.smok: the task declares no profile 'smok' \(did you mean 'smoke'"),
    ({"smoke": {"valu": [1]}}, r"profile_grid.smoke: 'valu' is not a parameter of the grid \(did you mean 'value'"),
    ({"smoke": {"value": [4]}}, r"profile_grid.smoke.value: 4 is not a value of the grid \(\[1, 2, 3\]\)"),
    ({"smoke": {"value": [1.5, 1]}}, r"1.5 is not a value of the grid"),
    ({"smoke": {"value": []}}, r"profile_grid.smoke.value must be a non-empty list"),
    ({"smoke": {"value": [1, 1]}}, r"profile_grid.smoke.value lists a value twice"),
    ({"smoke": {}}, r"profile_grid.smoke must name at least one parameter"),
    ({"smoke": [1]}, r"profile_grid.smoke must be a mapping"),
])
def test_a_bad_profile_grid_is_refused_at_load(make_pipeline: MakePipeline, tmp_path: Path, profile_grid: Any,
                                               message: str) -> None:
    with pytest.raises(PipelineError, match=message):
        _spec(make_pipeline, tmp_path, profile_grid)


def test_a_profile_grid_without_a_grid_is_refused(make_pipeline: MakePipeline) -> None:
    with pytest.raises(PipelineError, match="task 'leaf': profile_grid narrows a grid, and the task has none"):
        load_spec(make_pipeline({"leaf": {**leaf_task(), "profile_grid": {"smoke": {"value": [2]}}}}))


@pytest.mark.parametrize("narrowed", ["paper", "why"])
def test_a_profile_that_shares_outputs_with_another_runs_the_whole_grid(make_pipeline: MakePipeline,
                                                                        tmp_path: Path, narrowed: str) -> None:
    tasks = _tasks(tmp_path, {narrowed: {"value": [1]}})
    tasks["pt"]["parameters"]["why"] = {"value": 2}
    with pytest.raises(PipelineError, match=rf"task 'pt': profile_grid narrows profile '{narrowed}', which extends "
                                            "another or is extended"):
        load_spec(make_pipeline(tasks, parts=[{"title": "P", "tasks": list(tasks)}],
                                profiles={"why": {"extends": "paper"}}))
