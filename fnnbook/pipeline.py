"""``run``: check the tasks, decide which must run, and run them here or on Dask.

In-process (``workers=1``) the tasks run one after another with papermill's
progress bar; otherwise :mod:`fnnbook.executor` submits them to a Dask
cluster. Either way each task runs through :mod:`fnnbook.runner` (staging
folder, fingerprint record, atomic swap) and the run ends with the same
summary and ``_status.json``.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping, Sequence

from fnnbook.executor import run_on_dask
from fnnbook.runner import (Plan, RunReport, TaskOutcome, execute, logs_dir, check, decide, summary, task_threads,
                            write_status)
from fnnbook.spec import PipelineError, PipelineSpec

__all__ = ["run", "run_here"]


def run(
    spec: PipelineSpec,
    profile: str,
    tasks: Iterable[str] | None = None,
    *,
    force: bool = False,
    progress_bar: bool = True,
    echo: Callable[[str], None] = print,
    sources: Sequence[str | os.PathLike[str]] | None = None,
    workers: int = 1,
    scheduler: str | None = None,
    threads: int | None = None,
) -> RunReport:
    """Check, then execute, the selected tasks and any stale upstream tasks.

    Every selected task and its upstream tasks are validated before anything
    runs (:func:`check`).  A task is skipped when it is up to date
    (:func:`is_up_to_date`: same fingerprint, same upstream outputs, products
    unchanged) unless ``force``, which applies to the selected tasks only.
    Each task executes in ``<output_root>/<profile>/.staging/<task>/`` and
    replaces ``<output_root>/<profile>/<task>/`` only on success; a failed
    task leaves the previous outputs untouched and its log in ``_logs/``,
    and its dependants do not run; the other tasks go on.

    Parameters
    ----------
    spec : PipelineSpec
    profile : str
    tasks : iterable of str, optional
        Default: every task.
    force : bool
        Rerun the selected tasks even if up to date.
    progress_bar : bool
        Show a progress bar (papermill's per cell in-process; one for the
        whole run on Dask).
    echo : callable
        Receives each progress line.
    sources : sequence of path-like, optional
        See :func:`check`.
    workers : int
        1: run the tasks one after another in this process. K > 1: on a
        local Dask cluster of K single-threaded worker processes.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:port``); overrides
        ``workers``.
    threads : int, optional
        torch threads per task. Default: cores // workers (at least 1); 1 on
        a cluster given by ``scheduler``.

    Returns
    -------
    RunReport
        ``report.ok`` is False when a task failed or did not run.

    Raises
    ------
    PipelineError
        If the check fails (nothing has run).
    KeyboardInterrupt
        Re-raised after the running tasks are cancelled and recorded.
    """
    if workers < 1 or (threads is not None and threads < 1):
        raise PipelineError(f"workers and threads must be >= 1, got workers={workers}, threads={threads}")
    plan = check(spec, profile, tasks, sources=sources)
    verdict = decide(spec, plan, force=force)
    if threads is None:  # on a cluster given by address, the local core count says nothing: 1
        threads = 1 if scheduler is not None else task_threads(workers)
    if (scheduler is not None or workers > 1) and any(v == "run" for v in verdict.values()):
        outcomes = run_on_dask(spec, plan, verdict, workers=workers, scheduler=scheduler, threads=threads,
                               echo=echo, progress_bar=progress_bar)
    else:
        outcomes = run_here(spec, plan, verdict, threads=threads, echo=echo, progress_bar=progress_bar)
    report = RunReport(profile, tuple(outcomes[n] for n in plan.order))
    write_status(spec, report)
    echo(summary(report))
    return report


def run_here(spec: PipelineSpec, plan: Plan, verdict: Mapping[str, str], *, threads: int,
              echo: Callable[[str], None], progress_bar: bool) -> dict[str, TaskOutcome]:
    """Today's path: the tasks one after another in this process."""
    n = len(plan.order)
    outcomes: dict[str, TaskOutcome] = {}
    bad: set[str] = set()
    for i, name in enumerate(plan.order, 1):
        task = spec.tasks[name]
        out = spec.output_dir(plan.profile, name)
        prefix = f"[{i}/{n}] {name} ..."
        blocked = [u for u in task.upstream if u in bad]
        if verdict[name].startswith("not run"):
            bad.add(name)
            outcomes[name] = TaskOutcome(name, "not run", 0.0, out, message=verdict[name][len("not run: "):])
            echo(f"{prefix} {verdict[name]}")
            continue
        if blocked:
            bad.add(name)
            outcomes[name] = TaskOutcome(name, "not run", 0.0, out, message=f"upstream {blocked[0]} failed")
            echo(f"{prefix} not run (upstream {blocked[0]} failed)")
            continue
        if verdict[name] == "skipped":
            outcomes[name] = TaskOutcome(name, "skipped", 0.0, out)
            echo(f"{prefix} skipped (up to date)")
            continue
        echo(prefix)
        log = logs_dir(spec, plan.profile) / f"{name}.log"
        try:
            seconds, error = execute(spec, plan, name, progress_bar, threads)
        except BaseException:
            outcomes[name] = TaskOutcome(name, "failed", 0.0, out, log, "interrupted")
            echo(f"{prefix} FAILED (interrupted; see log {log})")
            echo(summary(RunReport(plan.profile, tuple(outcomes.values()))))
            raise
        if error:
            bad.add(name)
            outcomes[name] = TaskOutcome(name, "failed", seconds, out, log, error)
            echo(f"{prefix} FAILED (see log {log})\n    {error}")
        else:
            outcomes[name] = TaskOutcome(name, "ok", seconds, out, log)
            echo(f"{prefix} ok ({seconds:.1f} s)")
    return outcomes
