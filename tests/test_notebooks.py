"""Every pipeline task, executed in the smoke profile: one test per task of pipeline.yaml (a grid's points one by
one).

The tasks share one output root for the run (the ``smoke_outputs`` fixture of
``tests/conftest.py``), so a task and its upstream tasks run once; later tests,
here or in another xdist worker, find them up to date.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from conftest import SMOKE, SmokeOutputs

from fnnbook import load_spec
from fnnbook.runner import product_files
from fnnbook.why import WHYS_FILENAME, read_whys
from fnnbook.results import RESULTS_FILENAME, STATUSES, read_results

PIPELINE = Path(__file__).resolve().parents[1] / "pipeline.yaml"
PROFILE = SMOKE
TASKS = load_spec(PIPELINE).declares(PROFILE)  # a grid's points by name


@pytest.mark.notebook
@pytest.mark.parametrize("task", TASKS)
def test_task_runs_in_smoke_profile(smoke_outputs: SmokeOutputs, task: str) -> None:
    smoke_spec = smoke_outputs.spec
    report = smoke_outputs.run([task])
    outcome = report.outcome(task)
    assert outcome.status in ("ok", "skipped"), (
        f"{task}: {outcome.status} ({outcome.message}); log: {outcome.log}")
    assert report.ok, [(o.task, o.status, o.message) for o in report.outcomes]

    spec_task = smoke_spec.tasks[task]
    out = smoke_spec.output_dir(PROFILE, task)
    _, missing = product_files(spec_task.products, out)  # a glob product (neural_ode_seed*.pt) matches >= 1 file
    assert not missing, f"{task} did not leave {missing}"
    assert (out / f"{task}.ipynb").is_file()
    if spec_task.explains:  # a why task: one why per claim it explains (D1's needs the authors' networks)
        whys = read_whys(out / WHYS_FILENAME)  # also checks the stored causes are the ones its runs give
        assert set(whys) <= set(spec_task.explains) and len(whys) >= len(spec_task.explains) - 1, (task, set(whys))
    if RESULTS_FILENAME not in spec_task.products:  # a why task or a grid point writes no claims
        return

    results = read_results(out / RESULTS_FILENAME)  # also checks every verdict is a valid one
    assert results.task == task and results.profile == PROFILE
    reported = {c.id: c for c in results}
    missing = [cid for cid in spec_task.claims if cid not in reported]
    assert not missing, f"{task}: results.json lacks the declared claims {missing}"
    for cid in spec_task.claims:
        claim = reported[cid]
        assert claim.verdict in STATUSES
        assert claim.checks or claim.guarantees, f"{cid} has neither checks nor guarantees"
        assert bool(claim.checks) != (claim.verdict == "verified by construction"), cid
        if claim.figure:
            assert (out / claim.figure).is_file(), f"{cid}: figure {claim.figure} missing"
