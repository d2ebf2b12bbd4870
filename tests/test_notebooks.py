"""Every pipeline task, executed in the smoke profile: one test per task of pipeline.yaml.

The tasks share one output root for the session, so a task's upstream tasks
run once (later tests find them up to date).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from fnnbook import PipelineSpec, load_spec, run
from fnnlib.results import RESULTS_FILENAME, VERDICTS, read_results

PIPELINE = Path(__file__).resolve().parents[1] / "pipeline.yaml"
PROFILE = "smoke"
TASKS = list(yaml.safe_load(PIPELINE.read_text(encoding="utf-8"))["tasks"])


@pytest.fixture(scope="session")
def smoke_spec(tmp_path_factory: pytest.TempPathFactory) -> PipelineSpec:
    """The repository's pipeline, writing into a fresh output root for this session."""
    return load_spec(PIPELINE).with_paths(output_root=tmp_path_factory.mktemp("outputs"))


@pytest.mark.notebook
@pytest.mark.parametrize("task", TASKS)
def test_task_runs_in_smoke_profile(smoke_spec: PipelineSpec, task: str) -> None:
    report = run(smoke_spec, PROFILE, [task], progress_bar=False)
    outcome = report.outcome(task)
    assert outcome.status in ("ok", "skipped"), (
        f"{task}: {outcome.status} ({outcome.message}); log: {outcome.log}")
    assert report.ok, [(o.task, o.status, o.message) for o in report.outcomes]

    spec_task = smoke_spec.tasks[task]
    out = smoke_spec.output_dir(PROFILE, task)
    for product in spec_task.products:
        assert (out / product).exists(), f"{task} did not leave {product}"
    assert (out / f"{task}.ipynb").is_file()

    results = read_results(out / RESULTS_FILENAME)  # also checks every verdict is a valid one
    assert results["task"] == task and results["profile"] == PROFILE
    reported = {c["id"]: c for c in results["claims"]}
    missing = [cid for cid in spec_task.claims if cid not in reported]
    assert not missing, f"{task}: results.json lacks the declared claims {missing}"
    for cid in spec_task.claims:
        claim = reported[cid]
        assert claim["verdict"] in VERDICTS
        assert claim["checks"], f"{cid} has no checks"
        if claim.get("figure"):
            assert (out / claim["figure"]).is_file(), f"{cid}: figure {claim['figure']} missing"
