"""A profile that extends another (``profiles: {why: {extends: paper}}``): its own tasks run on the extended
profile's outputs, which it reuses and writes in place, and neither profile runs the other's own tasks."""

from __future__ import annotations

from typing import Any

import pytest

from fnnbook import PipelineError, load_spec, run

from .nbfactory import MakePipeline, child_task, leaf_task


def _why_child() -> dict[str, Any]:
    return {**child_task(), "explains": ["S1"], "parameters": {"why": {}, "smoke": {}}}


def _pipeline(make_pipeline: MakePipeline, **top: Any):
    return load_spec(make_pipeline({"leaf": leaf_task(), "child": _why_child()},
                                   profiles={"why": {"extends": "paper"}}, **top))


def _run(spec, profile: str, tasks=None):
    lines: list[str] = []
    return run(spec, profile, tasks, progress_bar=False, echo=lines.append), lines


def test_an_extending_profile_reuses_and_writes_the_extended_outputs(make_pipeline: MakePipeline) -> None:
    spec = _pipeline(make_pipeline)
    assert spec.declares("paper") == ["leaf"] and spec.declares("why") == ["child"]
    assert spec.home("why", "leaf") == "paper" and spec.home("why", "child") == "why"
    assert spec.tasks["child"].explains == ("S1",)

    report, _ = _run(spec, "paper")  # the paper profile does not run the why task
    assert [o.task for o in report.outcomes] == ["leaf"] and report.ok

    report, lines = _run(spec, "why")  # leaf is up to date in the paper folder: skipped, child reads it there
    assert {o.task: str(o.status) for o in report.outcomes} == {"leaf": "skipped", "child": "ok"}, lines
    assert (spec.output_root / "why" / "child" / "double.txt").read_text() == "6.0"  # paper's value 3, doubled
    assert not (spec.output_root / "why" / "leaf").exists()


def test_an_extending_run_runs_what_the_extended_profile_lacks_in_its_folder(make_pipeline: MakePipeline) -> None:
    spec = _pipeline(make_pipeline)
    report, _ = _run(spec, "why")
    assert {o.task: str(o.status) for o in report.outcomes} == {"leaf": "ok", "child": "ok"}
    assert (spec.output_root / "paper" / "leaf" / "value.txt").read_text() == "3.0"
    assert "profile = \"paper\"" in (spec.output_root / "paper" / "leaf" / "leaf.ipynb").read_text().replace(
        "\\\"", "\"")  # it ran as in the paper profile
    assert not list((spec.output_root / "paper" / ".staging").glob("*"))  # its staging there is gone
    report, _ = _run(spec, "paper")
    assert report.outcome("leaf").status == "skipped"


@pytest.mark.parametrize("profiles, message", [
    ({"why": {"extends": "papr"}}, "extends 'papr', which no task declares"),
    ({"why": {"extends": "why"}}, "extends itself"),
    ({"why": {"extends": "paper", "also": 1}}, "unknown key 'also'"),
    ({"why": {"extends": "paper"}, "deep": {"extends": "why"}}, "extends a profile itself"),
])
def test_a_bad_profiles_block_is_refused(make_pipeline: MakePipeline, profiles: dict, message: str) -> None:
    with pytest.raises(PipelineError, match=message):
        load_spec(make_pipeline({"leaf": leaf_task(), "child": _why_child()}, profiles=profiles))


def test_a_why_whose_task_is_stale_is_shown_as_stale(make_pipeline: MakePipeline, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The paper-side task reran after the why ran: the why's row says stale and names `make why`."""
    import shutil  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415

    from fnnbook.book import assemble_book  # noqa: PLC0415

    spec = _pipeline(make_pipeline)
    assert _run(spec, "why")[0].ok
    book = tmp_path / "book"
    shutil.copytree(Path(__file__).resolve().parents[2] / "book", book,
                    ignore=shutil.ignore_patterns("_build", "_generated", "_toc.yml"))
    assemble_book(spec, "paper", book, api=False)
    assert "stale" not in (book / "_generated" / "scoreboard.md").read_text().lower()
    assert run(spec, "paper", force=True, progress_bar=False, echo=lambda _: None).ok  # leaf reran: child is stale
    assemble_book(spec, "paper", book, api=False)
    board = (book / "_generated" / "scoreboard.md").read_text()
    assert "**Why (stale).** This why comes from outputs whose inputs changed since they ran; `make why` " \
           "refreshes it." in board
    assert "1 row(s) show results that are **stale**" in board
