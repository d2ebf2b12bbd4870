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
from fnnbook.execution import execute
from fnnbook.kernel import task_threads
from fnnbook.layout import logs_dir, write_status
from fnnbook.outcome import Action, Decision, RunReport, Status, TaskOutcome, blocked, blocked_by, progress_line, summary
from fnnbook.runner import Plan, check, decide
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
    if (scheduler is not None or workers > 1) and any(v.action is Action.RUN for v in verdict.values()):
        outcomes = run_on_dask(spec, plan, verdict, workers=workers, scheduler=scheduler, threads=threads,
                               echo=echo, progress_bar=progress_bar)
    else:
        outcomes = run_here(spec, plan, verdict, threads=threads, echo=echo, progress_bar=progress_bar)
    report = RunReport(profile, tuple(outcomes[n] for n in plan.order))
    write_status(spec, report)
    echo(summary(report))
    return report


def run_here(spec: PipelineSpec, plan: Plan, verdict: Mapping[str, Decision], *, threads: int,
             echo: Callable[[str], None], progress_bar: bool) -> dict[str, TaskOutcome]:
    """Today's path: the tasks one after another in this process."""
    n = len(plan.order)
    outcomes: dict[str, TaskOutcome] = {}
    for i, name in enumerate(plan.order, 1):
        out = spec.output_dir(plan.profile, name)
        if verdict[name].action is not Action.RUN:
            outcomes[name] = verdict[name].outcome(name, out)
        elif (up := blocked_by(spec.tasks[name], outcomes)) is not None:
            outcomes[name] = blocked(name, out, up, outcomes)
        else:
            echo(f"[{i}/{n}] {name} ...")
            log = logs_dir(spec, plan.profile) / f"{name}.log"
            try:
                seconds, error = execute(spec, plan, name, progress_bar, threads)
            except BaseException:
                outcomes[name] = TaskOutcome(name, Status.FAILED, 0.0, out, log, "interrupted")
                echo(f"[{i}/{n}] {name} ... FAILED (interrupted; see log {log})")
                echo(summary(RunReport(plan.profile, tuple(outcomes.values()))))
                raise
            outcomes[name] = (TaskOutcome(name, Status.FAILED, seconds, out, log, error) if error
                              else TaskOutcome(name, Status.OK, seconds, out, log))
        echo(progress_line(i, n, outcomes[name]))
    return outcomes
