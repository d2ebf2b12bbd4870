"""``run``: check the tasks, decide which must run, and run them here or on Dask.

In-process (``workers=1``) the tasks run one after another with papermill's
progress bar; otherwise :mod:`fnnbook.executor` submits them to a Dask
cluster. Either way each task runs through :mod:`fnnbook.runner` (staging
folder, fingerprint record, atomic swap) and the run ends with the same
summary and ``_status.json``, and the run's utilisation: task seconds / (workers x wall seconds).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable, Mapping, Sequence

from fnnbook.executor import run_on_dask
from fnnbook.execution import execute, ignoring_interrupts
from fnnbook.kernel import task_threads
from fnnbook.layout import STATUS_FILE, clear_stale, holding, logs_dir, staging_of, write_status
from fnnbook.outcome import (Action, Decision, Interrupted, RunReport, TaskOutcome, blocked, blocked_by, interrupted,
                             progress_line, summary, utilisation_line)
from fnnbook.fingerprint import NO_EARLIER_RUN
from fnnbook.plan import Plan
from fnnbook.runner import check, decide
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
    Each task executes in this run's own ``<output_root>/<profile>/.staging/<run>/<task>/`` and
    replaces ``<output_root>/<profile>/<task>/`` only on success; a failed
    task (a file-system fault included: ``io_error``) leaves the previous
    outputs untouched and its log in ``_logs/``, and its dependants do not
    run; the other tasks go on. The run holds the writer lock of each task
    it runs and a reader's share of the others (:func:`fnnbook.layout.holding`):
    a second run on the same outputs waits, and says for whom.

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
        Re-raised after the running tasks are cancelled and the run is
        recorded in ``_status.json`` (a second Ctrl-C meanwhile is ignored).
    """
    if workers < 1 or (threads is not None and threads < 1):
        raise PipelineError(f"workers and threads must be >= 1, got workers={workers}, threads={threads}")
    spec = spec.for_profile(profile)  # without the grid points the profile leaves out
    plan = check(spec, profile, tasks, sources=sources)
    if threads is None:  # on a cluster given by address, the local core count says nothing: 1
        threads = 1 if scheduler is not None else task_threads(workers)
    with staging_of(spec, profile, plan.run):
        verdict = decide(spec, plan, force=force)  # a first look, to know which outputs to lock for writing
        while True:
            writes = {n for n, d in verdict.items() if d.action is Action.RUN}
            with holding(spec, profile, writes, read=plan.order, echo=echo):
                try:
                    clear_stale(spec, profile, writes, plan.run)
                except OSError as exc:
                    raise PipelineError(f"cannot clear the staging folder of an earlier run: {exc}") from exc
                verdict = decide(spec, plan, force=force)  # again, now that no other run writes these
                if {n for n, d in verdict.items() if d.action is Action.RUN} <= writes:
                    for line in rerun_lines(verdict):
                        echo(line)
                    return _execute(spec, plan, verdict, workers=workers, scheduler=scheduler, threads=threads,
                                    echo=echo, progress_bar=progress_bar)
            # another run changed an output meanwhile: lock what must run now, and look again


def rerun_lines(verdict: Mapping[str, Decision]) -> list[str]:
    """One line per task that reruns over an earlier output, naming the input that changed (its trigger)."""
    return [f"{name} reruns: {d.reason}" for name, d in verdict.items()
            if d.action is Action.RUN and d.reason and d.reason != NO_EARLIER_RUN]


def _execute(spec: PipelineSpec, plan: Plan, verdict: Mapping[str, Decision], *, workers: int,
             scheduler: str | None, threads: int, echo: Callable[[str], None], progress_bar: bool) -> RunReport:
    """Run the tasks decided to run (here or on Dask), record and summarise the outcomes."""
    start, used = time.perf_counter(), [1]  # wall clock; the workers the run had (a cluster reports its own)
    try:
        if (scheduler is not None or workers > 1) and any(v.action is Action.RUN for v in verdict.values()):
            outcomes = run_on_dask(spec, plan, verdict, workers=workers, scheduler=scheduler, threads=threads,
                                   echo=echo, progress_bar=progress_bar, on_workers=used.append)
        else:
            outcomes = run_here(spec, plan, verdict, threads=threads, echo=echo, progress_bar=progress_bar)
    except KeyboardInterrupt as stop:  # a second Ctrl-C meanwhile: the run is still recorded as interrupted
        with ignoring_interrupts():
            outcomes = stop.outcomes if isinstance(stop, Interrupted) else _stopped_before_tasks(spec, plan, verdict)
            _finish(spec, plan, outcomes, echo, used[-1], time.perf_counter() - start)
        raise KeyboardInterrupt from None
    return _finish(spec, plan, outcomes, echo, used[-1], time.perf_counter() - start)


def _stopped_before_tasks(spec: PipelineSpec, plan: Plan, verdict: Mapping[str, Decision]) -> dict[str, TaskOutcome]:
    """The outcomes of a run stopped before its tasks started (a Ctrl-C while the cluster starts): each task
    to run, interrupted; the others as decided."""
    logs = logs_dir(spec, plan.profile)
    return {n: interrupted(n, spec.output_dir(plan.profile, n), logs / f"{n}.log") if d.action is Action.RUN
            else d.outcome(n, spec.output_dir(plan.profile, n)) for n, d in verdict.items()}


def _finish(spec: PipelineSpec, plan: Plan, outcomes: Mapping[str, TaskOutcome], echo: Callable[[str], None],
            workers: int, wall: float) -> RunReport:
    """Record the outcomes in ``_status.json`` (one clear line if that fails), echo the utilisation and summary."""
    report = RunReport(plan.profile, tuple(outcomes[n] for n in plan.order if n in outcomes), workers, wall)
    try:
        write_status(spec, report)
    except OSError as exc:
        echo(f"note: could not record the outcomes in {STATUS_FILE} ({exc.strerror or exc})")
    if (line := utilisation_line(report)) is not None:
        echo(line)
    echo(summary(report))
    return report


def run_here(spec: PipelineSpec, plan: Plan, verdict: Mapping[str, Decision], *, threads: int,
             echo: Callable[[str], None], progress_bar: bool) -> dict[str, TaskOutcome]:
    """Today's path: the tasks one after another in this process.

    Raises
    ------
    Interrupted
        On Ctrl-C, with the outcomes so far (the running task: failed, "interrupted").
    """
    spec = spec.for_profile(plan.profile)
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
            try:
                outcomes[name] = execute(spec, plan, name, progress_bar, threads)
            except KeyboardInterrupt:
                with ignoring_interrupts():
                    outcomes[name] = interrupted(name, out, logs_dir(spec, plan.profile) / f"{name}.log")
                    echo(progress_line(i, n, outcomes[name]))
                raise Interrupted(outcomes) from None
        echo(progress_line(i, n, outcomes[name]))
    return outcomes
