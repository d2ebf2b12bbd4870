"""The fnn-pipeline command line (called in-process)."""

from __future__ import annotations

import pytest

from fnnbook.cli import main

from .nbfactory import MakePipeline, child_task, leaf_task


def test_check_list_and_run(make_pipeline: MakePipeline, capsys: pytest.CaptureFixture[str]) -> None:
    pipeline = str(make_pipeline({"leaf": leaf_task(), "child": child_task()}))
    assert main(["check", "--profile", "smoke", "--pipeline", pipeline]) == 0
    assert "ok: 2 task(s) valid in profile 'smoke': leaf, child" in capsys.readouterr().out

    assert main(["run", "--profile", "smoke", "--pipeline", pipeline, "--no-progress", "leaf"]) == 0
    assert "[1/1] leaf ... ok (" in capsys.readouterr().out

    assert main(["list", "--pipeline", pipeline]) == 0
    out = capsys.readouterr().out
    assert "leaf" in out and "Leaf" in out
    assert "claims S1; upstream -; paper: not run; smoke: up to date" in out
    assert "claims -; upstream leaf; paper: not run; smoke: not run" in out


def test_errors_exit_2_with_a_message(make_pipeline: MakePipeline,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    pipeline = str(make_pipeline())
    assert main(["check", "--profile", "papr", "--pipeline", pipeline]) == 2
    assert "error: unknown profile 'papr'" in capsys.readouterr().err
    assert main(["run", "--profile", "smoke", "--pipeline", pipeline, "nope"]) == 2
    assert "error: no task named 'nope'" in capsys.readouterr().err


def test_failed_task_exits_1(make_pipeline: MakePipeline, capsys: pytest.CaptureFixture[str]) -> None:
    pipeline = str(make_pipeline({"leaf": leaf_task(fail=True)}))
    assert main(["run", "--profile", "smoke", "--pipeline", pipeline, "--no-progress"]) == 1
    assert "FAILED (see log" in capsys.readouterr().out
