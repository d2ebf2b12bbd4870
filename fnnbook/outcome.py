"""Task outcomes as types: what a run decided for each task, how each task fared, and how both are shown.

One rule decides when an upstream task stops its dependants (:func:`blocked_by`), and one formatter
writes a task's progress line (:func:`progress_line`), for the in-process and the Dask path alike.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from fnnbook.spec import Task

__all__ = ["Action", "Decision", "Interrupted", "RunReport", "Status", "TaskOutcome", "blocked", "blocked_by", "interrupted", "progress_line",
           "summary", "utilisation_line"]


class Status(str, enum.Enum):
    """How a task fared; the value is what ``_status.json`` and the summary show."""

    OK = "ok"
    SKIPPED = "skipped"
    FAILED = "failed"
    NOT_RUN = "not run"

    def __str__(self) -> str:
        return self.value


class Action(enum.Enum):
    """What a run does with a task, decided before anything runs."""

    RUN = "run"
    SKIP = "skip"  # up to date
    NOT_RUN = "not run"


class _Upstream(Protocol):
    @property
    def blocks(self) -> bool: ...

    @property
    def past(self) -> str: ...

    @property
    def data_missing(self) -> bool: ...


@dataclass(frozen=True)
class Decision:
    """What a run does with one task (:func:`fnnbook.runner.decide`), and why when it does not run it.

    ``data_missing``: it does not run only because data files are missing here (its own or an upstream
    task's); such a run still counts as ok.
    """

    action: Action
    reason: str = ""
    data_missing: bool = False

    @property
    def blocks(self) -> bool:
        return self.action is Action.NOT_RUN

    @property
    def past(self) -> str:
        return "did not run"

    def outcome(self, task: str, out_dir: Path) -> TaskOutcome:
        """The outcome of a task that is not run or skipped (a task that runs gets its outcome from the run)."""
        if self.action is Action.RUN:
            raise ValueError(f"task {task!r} is to run: its outcome comes from the run")
        status = Status.SKIPPED if self.action is Action.SKIP else Status.NOT_RUN
        return TaskOutcome(task, status, 0.0, out_dir, message=self.reason, data_missing=self.data_missing)


@dataclass(frozen=True)
class TaskOutcome:
    """How one task fared. ``data_missing``: not run only because data files are missing here;
    ``io_error``: failed on the file system (read-only or full disk, no permission), not in the science."""

    task: str
    status: Status
    seconds: float
    out_dir: Path
    log: Path | None = None
    message: str = ""
    data_missing: bool = False
    io_error: bool = False
    interrupted: bool = False

    @property
    def blocks(self) -> bool:
        """Whether its dependants cannot run."""
        return self.status in (Status.FAILED, Status.NOT_RUN)

    @property
    def past(self) -> str:
        return "failed" if self.status == Status.FAILED else "did not run"


@dataclass(frozen=True)
class RunReport:
    """The outcomes of one run, in execution order; ``workers`` ran them in ``wall`` seconds."""

    profile: str
    outcomes: tuple[TaskOutcome, ...]
    workers: int = 1
    wall: float = 0.0

    @property
    def busy(self) -> float:
        """Seconds of task time: the sum over the tasks that ran (ok or failed)."""
        return sum(o.seconds for o in self.outcomes if o.status in (Status.OK, Status.FAILED))

    @property
    def utilisation(self) -> float | None:
        """``busy / (workers * wall)``: the share of the workers' time spent in tasks (None if nothing ran)."""
        if self.busy <= 0 or self.wall <= 0:
            return None
        return self.busy / (self.workers * self.wall)

    @property
    def ok(self) -> bool:
        """True when no task failed or was left out, other than for missing data (see the summary)."""
        return all(o.status in (Status.OK, Status.SKIPPED) or (o.status == Status.NOT_RUN and o.data_missing)
                   for o in self.outcomes)

    @property
    def io_error(self) -> bool:
        """True when a task failed on the file system (the command line exits with 2)."""
        return any(o.io_error for o in self.outcomes)

    def outcome(self, task: str) -> TaskOutcome:
        """The outcome of ``task``."""
        for o in self.outcomes:
            if o.task == task:
                return o
        raise KeyError(task)


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a run, carrying the outcomes so far (so the run is still recorded)."""

    def __init__(self, outcomes: Mapping[str, TaskOutcome]) -> None:
        super().__init__("interrupted")
        self.outcomes = dict(outcomes)


def interrupted(task: str, out_dir: Path, log: Path | None) -> TaskOutcome:
    """The outcome of a task stopped by Ctrl-C."""
    return TaskOutcome(task, Status.FAILED, 0.0, out_dir, log, "interrupted", interrupted=True)


def blocked_by(task: Task, known: Mapping[str, _Upstream]) -> str | None:
    """The first upstream task of ``task`` whose decision or outcome in ``known`` stops it, or None."""
    return next((u for u in task.upstream if u in known and known[u].blocks), None)


def blocked(task: str, out_dir: Path, upstream: str, known: Mapping[str, _Upstream]) -> TaskOutcome:
    """The outcome of a task that does not run because ``upstream`` failed or did not run."""
    up = known[upstream]
    why = f"upstream {upstream} {up.past}" + (" (data missing)" if up.data_missing else "")
    return TaskOutcome(task, Status.NOT_RUN, 0.0, out_dir, message=why, data_missing=up.data_missing)


def progress_line(index: int, total: int, o: TaskOutcome) -> str:
    """``[i/n] task ... ok (1.2 s)``, and the like for each status."""
    text = {Status.OK: f"ok ({o.seconds:.1f} s)", Status.SKIPPED: "skipped (up to date)",
            Status.FAILED: (f"FAILED (interrupted; see log {o.log})" if o.interrupted
                            else f"FAILED (see log {o.log})\n    {o.message}"),
            Status.NOT_RUN: f"not run ({o.message})"}[o.status]
    return f"[{index}/{total}] {o.task} ... {text}"


def utilisation_line(report: RunReport) -> str | None:
    """``utilisation 83% (task time 50.0 s / (2 workers x 30.0 s wall))``; None if no task ran."""
    if (u := report.utilisation) is None:
        return None
    return (f"utilisation {100 * u:.0f}% (task time {report.busy:.1f} s / ({report.workers} worker(s) x "
            f"{report.wall:.1f} s wall))")


def summary(report: RunReport) -> str:
    """One line of counts, then one line per task that failed or did not run."""
    counts = {s: sum(o.status == s for o in report.outcomes) for s in Status}
    parts = [f"{n} {s}" for s, n in counts.items() if n]
    lines = [f"profile {report.profile}: {', '.join(parts) or 'nothing to do'}"]
    for o in report.outcomes:
        if o.status == Status.FAILED:
            lines.append(f"  FAILED {o.task}: log {o.log}")
        elif o.status == Status.NOT_RUN:
            lines.append(f"  NOT RUN {o.task}: {o.message}")
    return "\n".join(lines)
