"""``make why`` without network: the release fetch left only empty folders behind, and every why task judges our
networks only and says so (before: ``14_why_feedback`` and ``17_why_quadrotor_point`` tested only
``release.is_dir()`` and failed with ``ReleaseError: missing ...``, and ``why_quadrotor`` never ran)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from conftest import SMOKE, SmokeOutputs

from fnnbook import run
from fnnbook.why import WHYS_FILENAME, read_whys

#: what `data fetch --optional --release` used to leave without network: the release's folders, empty
EMPTY_RELEASE = ("release/spiral_curve/trained_model", "release/irregular_object/trained_model",
                 "release/quadrotor/learning_NODE/learned_models", "release/quadrotor/learning_MLP/learned_models")
WHY_TASKS = ["why_feedback", "why_quadrotor"]  # the two that failed, and the aggregate that then never ran


@pytest.mark.notebook
def test_the_why_tasks_judge_ours_only_without_the_release(smoke_outputs: SmokeOutputs, tmp_path: Path) -> None:
    report = smoke_outputs.run(WHY_TASKS)  # the shared smoke run (their upstream tasks too)
    assert report.ok, [(o.task, o.status, o.message) for o in report.outcomes]
    spec = smoke_outputs.spec.with_paths(output_root=tmp_path / "outputs", data_dir=tmp_path / "data")
    points = spec.for_profile(SMOKE).grids["why_quadrotor_point"]  # the thrust bounds the smoke profile flies
    shutil.copytree(smoke_outputs.spec.output_root / SMOKE, tmp_path / "outputs" / SMOKE,
                    ignore=shutil.ignore_patterns(".staging", "*.lock"))
    for folder in EMPTY_RELEASE:
        (tmp_path / "data" / folder).mkdir(parents=True)
    lines: list[str] = []
    report = run(spec, SMOKE, WHY_TASKS, progress_bar=False, echo=lines.append, threads=1)
    assert report.ok, [(o.task, str(o.status), o.message) for o in report.outcomes]
    ran = {o.task for o in report.outcomes if o.status == "ok"}
    assert {"why_feedback", "why_quadrotor", *points} <= ran  # their data changed
    assert not {"spiral", "neural_feedback", "quadrotor_learning", "quadrotor_mpc"} & ran  # no data of theirs
    said = {t: (spec.output_dir(SMOKE, t) / f"{t}.ipynb").read_text() for t in ("why_feedback", *points)}
    assert "judging ours only" in said["why_feedback"]
    assert all("ours judged only" in text for name, text in said.items() if name != "why_feedback")
    for task in WHY_TASKS:
        assert read_whys(spec.output_dir(SMOKE, task) / WHYS_FILENAME)
