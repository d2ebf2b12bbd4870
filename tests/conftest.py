"""Fixtures shared across the suite: the smoke-profile outputs, run once per pytest run, as a new user would.

``smoke_outputs`` first copies the repository's files (tracked, and untracked
but not ignored: what a clone of the working tree holds) into an empty
temporary folder with nothing beside it, and runs the pipeline there, with
the defaults of its own ``pipeline.yaml`` (claims registry, data directory,
output root, all inside the copy); the notebooks' kernels import the copy's
``fnnlib``. So the task tests, nbval and the book in the browser all show
that the repository alone suffices. The run is shared by every test of the
run, including every pytest-xdist worker: one file lock per task lets one
worker execute it while others run other tasks, and the runner skips a task
whose outputs are up to date, so each task runs once however many tests need
it.
"""

from __future__ import annotations

import fnmatch
import os
import shutil
import signal
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from filelock import FileLock
from hypothesis import settings

if TYPE_CHECKING:
    from fnnbook import PipelineSpec, RunReport

# torch, fnnlib and fnnbook are imported where used: the xdist controller loads this file before it starts the
# workers and runs no test, so their ~2.5 s of imports there only delayed every worker's start

ROOT = Path(__file__).resolve().parents[1]
PIPELINE = ROOT / "pipeline.yaml"
SMOKE = "smoke"


def pytest_configure(config):
    """The tests compute with one torch thread, as the notebooks do (importing fnnlib does not set it), and
    hypothesis draws its examples from a fixed seed: the same command runs the same examples (a property test
    that fails fails every time, not one run in many)."""
    if not (getattr(config.option, "numprocesses", None) and not os.environ.get("PYTEST_XDIST_WORKER")):
        import fnnlib  # noqa: PLC0415 (a process that runs tests: not the xdist controller)

        fnnlib.threads.set_num_threads(1)
    settings.register_profile("fixed", derandomize=True)
    settings.load_profile("fixed")


@pytest.fixture(scope="module")
def f():
    """A small random vector field f(t, x) on R^2: a float64 tanh MLP 2-8-2 drawn with seed 0 (the Sec. 3
    kernels' tests; one per test module)."""
    import torch  # noqa: PLC0415

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
        from fnnbook import RunReport, run  # noqa: PLC0415

        outcomes = []
        for name in self.spec.for_profile(SMOKE).closure(tasks):  # the grid points the smoke profile runs
            with FileLock(str(self.spec.output_root / f".{name}.lock")):
                report = run(self.spec, SMOKE, [name], progress_bar=False, echo=lambda _: None,
                             threads=1)  # one torch thread per task, as the paper runs
            outcomes += [o for o in report.outcomes if o.task == name]
            if not report.ok:
                break
        return RunReport(SMOKE, tuple(outcomes))

    def dir(self, task: str) -> Path:
        return self.spec.output_dir(SMOKE, task)


def repository_files(root: Path = ROOT) -> list[str]:
    """The repository's files relative to ``root``: tracked, and untracked but not ignored.

    ``git ls-files -co --exclude-standard``; outside a git checkout (an unpacked archive), every file but
    those matching a pattern of ``.gitignore``.
    """
    try:
        listed = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=root, check=True,
                                capture_output=True).stdout.decode().split("\0")
        return sorted(p for p in listed if p and (root / p).is_file())  # a deleted tracked file is listed too
    except (OSError, subprocess.CalledProcessError):
        pass
    patterns = [line.strip().rstrip("/") for line in (root / ".gitignore").read_text(encoding="utf-8").splitlines()
                if line.strip() and not line.startswith("#")]

    def ignored(rel: Path) -> bool:
        return any(fnmatch.fnmatch(rel.as_posix(), pat) if "/" in pat else
                   any(fnmatch.fnmatch(part, pat) for part in rel.parts) for pat in patterns)

    return sorted(p.relative_to(root).as_posix() for p in root.rglob("*")
                  if p.is_file() and ".git" not in p.relative_to(root).parts and not ignored(p.relative_to(root)))


def bare_copy(dest: Path) -> Path:
    """Copy :func:`repository_files` into ``dest`` (created, must not exist); returns ``dest``."""
    dest.mkdir(parents=True)
    for rel in repository_files():
        (dest / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / rel, dest / rel)
    return dest


@pytest.fixture(autouse=True)
def _sigint_as_found() -> Iterator[None]:
    """A test leaves Ctrl-C's handler as it found it: a process left ignoring SIGINT hands that on to every
    child, and a later test's ``fnn-pipeline run`` would then not stop on Ctrl-C."""
    before = signal.getsignal(signal.SIGINT)
    yield
    after = signal.getsignal(signal.SIGINT)
    if after is not before:
        signal.signal(signal.SIGINT, before)
        pytest.fail(f"the test left SIGINT's handler changed: {before!r} -> {after!r}")


@pytest.fixture(scope="session")
def smoke_outputs(tmp_path_factory: pytest.TempPathFactory) -> SmokeOutputs:
    """The smoke runs of the whole run, in a bare copy of the repository (shared by the xdist workers).

    ``<run>/new-user/`` holds the copy and nothing else; its ``pipeline.yaml`` is used as it is.
    """
    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent  # the run's folder, above each worker's own basetemp
    repo = base / "new-user" / ROOT.name
    with FileLock(str(base / "new-user.lock")):
        if not (base / "new-user.copied").is_file():
            bare_copy(repo)
            (base / "new-user.copied").touch()
    from fnnbook import load_spec  # noqa: PLC0415

    # the notebooks' kernels (and the book's autodoc) import the copy's fnnlib, not this checkout's
    path = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = os.pathsep.join([str(repo), *([path] if path else [])])
    return SmokeOutputs(load_spec(repo / "pipeline.yaml"))


def _depth(task: str, upstream: dict[str, list[str]]) -> int:
    return 1 + max((_depth(u, upstream) for u in upstream[task]), default=-1)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run the tests that need the smoke pipeline first, upstream tasks first, and keep the book's tests together.

    The task tests (test_notebooks.py) come first, then nbval and the other tests of the smoke outputs, then the
    book in the browser (it needs every task; its tests form one xdist group, so one worker builds the book
    while the other goes on), then every other test. With ``--dist loadgroup --no-loadscope-reorder``
    (pyproject.toml) xdist hands each worker the next test in this order as it runs low (two ahead). Tasks are
    ordered upstream first (by depth), the head of the longest chain of dependants first within a depth (the
    executor's rule, each task counted as one), and a grid's points by their grid: so the two workers start
    on independent roots, and a worker seldom waits for the lock of a task the other one is running (before,
    a grid's points sorted first, and both workers began with points of one grid: one ran its upstream chain
    while the other waited 32 s).
    """
    import yaml  # noqa: PLC0415

    from fnnbook import load_spec  # noqa: PLC0415
    from fnnbook.executor import longest_remaining  # noqa: PLC0415

    _group_the_marked(config, items)
    upstream = {name: list(t.get("upstream", [])) for name, t in
                yaml.safe_load(PIPELINE.read_text(encoding="utf-8"))["tasks"].items()}
    height = longest_remaining(upstream, dict.fromkeys(upstream, 1.0))
    order = sorted(upstream, key=lambda t: (_depth(t, upstream), -height[t]))
    grid_of = {point: grid for grid, points in load_spec(PIPELINE).grids.items() for point in points}

    def key(item: pytest.Item) -> tuple[int, int]:
        path = item.path.as_posix()
        task = getattr(item, "callspec", None) and item.callspec.params.get("task")
        task = grid_of.get(task, task)
        rank = order.index(task) if task in upstream else 0
        if path.endswith("tests/test_notebooks.py"):
            return 0, rank
        if "smoke_outputs" not in getattr(item, "fixturenames", ()):
            return 3, 0
        return (2, 0) if "test_browser" in path else (1, rank)

    items.sort(key=key)  # stable: the order within a stage is kept


def _group_the_marked(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Give each test marked ``xdist_group(name)`` the ``@name`` suffix that xdist's loadgroup scheduler groups by.

    pytest-xdist 3.8 writes the suffix into ``item._nodeid``, which pytest 9.2 no longer reads (a node's id is
    ``item._id``, a ``NodeId``): the marks were silently ignored and the book's tests split over both workers,
    one of them waiting for the other's build (pytest-dev/pytest-xdist#1386, open). Where the suffix is already
    there (a fixed xdist), nothing changes.
    """
    from _pytest.nodeid import NodeId  # noqa: PLC0415 (private: the only way to set an item's id on pytest 9.2)

    if not getattr(config.option, "loadgroup", False):
        return
    for item in items:
        names = sorted({str(m.args[0] if m.args else m.kwargs.get("name", "default"))
                        for m in item.iter_markers("xdist_group")})
        suffix = "@" + "_".join(names)
        if names and not item.nodeid.endswith(suffix):
            item._id = NodeId.parse(item.nodeid + suffix)
