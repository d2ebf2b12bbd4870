"""Fixtures shared across the suite: the smoke-profile outputs, run once per pytest run.

``smoke_outputs`` runs pipeline tasks in the smoke profile into one output
root shared by every test of the run, including every pytest-xdist worker:
one file lock per task lets one worker execute it while others run other
tasks, and the runner skips a task whose outputs are up to date, so each task
runs once however many tests (the task tests, nbval, the book in the
browser) need it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import pytest
import torch
from filelock import FileLock

import fnnlib
from fnnbook import PipelineSpec, RunReport, load_spec, run
from fnnbook.runner import TaskOutcome

ROOT = Path(__file__).resolve().parents[1]
PIPELINE = ROOT / "pipeline.yaml"
SMOKE = "smoke"


def pytest_configure(config):
    """The tests compute with one torch thread, as the notebooks do (importing fnnlib does not set it)."""
    fnnlib.set_num_threads(1)


@pytest.fixture(scope="module")
def f():
    """A small random vector field f(t, x) on R^2: a float64 tanh MLP 2-8-2 drawn with seed 0 (the Sec. 3
    kernels' tests; one per test module)."""
    from fnnlib.models import mlp  # noqa: PLC0415

    torch.manual_seed(0)
    net = mlp(2, 2, (8,), "tanh").double()
    return lambda t, x: net(x)


@dataclass(frozen=True)
class SmokeOutputs:
    """The repository's pipeline writing into this run's shared smoke output root."""

    spec: PipelineSpec

    def run(self, tasks: list[str] | None = None) -> RunReport:
        """Run ``tasks`` (all when None) and their upstream tasks, each under its own lock.

        Up-to-date tasks are skipped; the first task that fails stops the rest.
        """
        outcomes: list[TaskOutcome] = []
        for name in self.spec.closure(tasks):
            with FileLock(str(self.spec.output_root / f".{name}.lock")):
                report = run(self.spec, SMOKE, [name], progress_bar=False, echo=lambda _: None,
                             threads=1)  # one torch thread per task, as the paper runs
            outcomes += [o for o in report.outcomes if o.task == name]
            if not report.ok:
                break
        return RunReport(SMOKE, tuple(outcomes))

    def dir(self, task: str) -> Path:
        return self.spec.output_dir(SMOKE, task)


@pytest.fixture(scope="session")
def smoke_outputs(tmp_path_factory: pytest.TempPathFactory) -> SmokeOutputs:
    """One smoke output root for the whole run (shared by the xdist workers of one run)."""
    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent  # the run's folder, above each worker's own basetemp
    root = base / "smoke-outputs"
    root.mkdir(exist_ok=True)
    return SmokeOutputs(load_spec(PIPELINE).with_paths(output_root=root))


def _depth(task: str, upstream: dict[str, list[str]]) -> int:
    return 1 + max((_depth(u, upstream) for u in upstream[task]), default=-1)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run the tests that need the smoke pipeline first, tasks without upstream tasks first.

    The task tests (test_notebooks.py) come first, then nbval, then every other test,
    then the book in the browser (it needs every task). xdist hands the first tests
    out one at a time to alternate workers, so the workers run independent tasks side
    by side; a worker that needs a task another one is running waits for its lock.
    """
    import yaml  # noqa: PLC0415

    upstream = {name: list(t.get("upstream", [])) for name, t in
                yaml.safe_load(PIPELINE.read_text(encoding="utf-8"))["tasks"].items()}
    order = sorted(upstream, key=lambda t: _depth(t, upstream))

    def key(item: pytest.Item) -> tuple[int, int]:
        path = item.path.as_posix()
        task = getattr(item, "callspec", None) and item.callspec.params.get("task")
        rank = order.index(task) if task in upstream else 0
        if path.endswith("tests/test_notebooks.py"):
            return 0, rank
        if "smoke_outputs" not in getattr(item, "fixturenames", ()):
            return 2, 0
        return (3, 0) if "test_browser" in path else (1, rank)

    items.sort(key=key)  # stable: the order within a stage is kept
