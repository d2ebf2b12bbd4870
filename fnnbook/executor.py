"""Run pipeline tasks on a Dask cluster: a local one, or one already running.

Each task that must run is submitted as :func:`fnnbook.runner.execute_task`
with its upstream tasks' futures as dependencies, so independent tasks
overlap and a task starts only when its upstream tasks are done; papermill
runs inside the worker.  A worker process that dies mid-task makes the
scheduler retry the task once on another worker (``allowed-failures: 1``),
then report it failed; either way the task's outputs are replaced only by a
whole successful run (staging folder + rename).

Ready tasks go first by their longest remaining path (:func:`longest_remaining`, as Dask priorities): a
task's own estimated seconds plus those of the longest chain of tasks that wait on it, the estimate being
the task's last measured time (``_status.json``) or 1 s, so the long chains start first and the short tasks
fill the workers around them.

Ctrl-C is the run's alone: the local cluster's workers ignore it, the run cancels the tasks and stops their
kernels, those still starting too (:func:`fnnbook.kernel.stop_kernels`), and then closes the cluster.

Workers of a cluster given by address need the same checkout and venv at
the same path, and the same output root (a shared file system).
"""

from __future__ import annotations

import contextlib
import graphlib
import importlib.util
import logging
import os
import shutil
import signal
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence

import dask
import psutil
from distributed import Client, Future, LocalCluster, wait
from distributed.security import Security
from tqdm import tqdm

from fnnbook.execution import deferring_interrupts, execute_task, ignoring_interrupts
from fnnbook.kernel import cpu_count, stop_kernels
from fnnbook.layout import logs_dir, mark_killed, measured_seconds, staging_dir
from fnnbook.outcome import (Action, Decision, Interrupted, Status, TaskOutcome, blocked, blocked_by, interrupted,
                             progress_line)
from fnnbook.plan import Plan
from fnnbook.spec import PipelineError, PipelineSpec

__all__ = ["TASK_MEMORY", "blocking_interrupts", "UNMEASURED_SECONDS", "WORKERS_IGNORE_CTRL_C", "default_workers", "local_cluster",
           "longest_remaining", "priorities", "run_on_dask"]

_HAS_BOKEH = importlib.util.find_spec("bokeh") is not None  # the dashboard needs it

#: run by each worker process as it starts (a Dask preload, as script text): the terminal's Ctrl-C reaches
#: the whole process group, workers included; they ignore it, and the run stops their tasks, then closes them
#: (a worker starts with SIGINT blocked, :func:`blocking_interrupts`: one pressed meanwhile is pending and
#: discarded by the ignore, then the signal is unblocked for the kernels it starts)
WORKERS_IGNORE_CTRL_C = ("import signal\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\n"
                         "signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})\n")
#: memory one task may take (the largest, quadrotor_learning, peaks near 1.2 GiB)
TASK_MEMORY = 2 * 1024**3
#: the estimated seconds of a task never measured
UNMEASURED_SECONDS = 1.0


def default_workers() -> int:
    """Cores, capped so that each worker has :data:`TASK_MEMORY` of the available memory."""
    by_memory = max(1, psutil.virtual_memory().available // TASK_MEMORY)
    return int(max(1, min(cpu_count(), by_memory)))


@contextlib.contextmanager
def local_cluster(workers: int) -> Iterator[Client]:
    """A LocalCluster of ``workers`` single-threaded worker processes, and a client to it.

    Closed to other local clients: scheduler, workers and this client speak TLS with a temporary self-signed
    certificate that only this run holds (``Security.temporary()``), so a ``Client`` from another process
    cannot submit code to the workers.

    Ctrl-C is the run's alone (:data:`WORKERS_IGNORE_CTRL_C`): a worker that closed itself on Ctrl-C would
    miss the run's order to stop its kernels, be killed by its nanny 4 s later and leave a kernel that was
    still starting as an orphan, or be restarted by its nanny meanwhile. The run cancels the tasks, stops
    their kernels, then closes the cluster. A Ctrl-C while the cluster starts takes effect once it is up: SIGINT
    is blocked meanwhile (:func:`blocking_interrupts`), so a worker process starting then does not get it (its
    nanny would fail to start it) and the run gets it as the start ends.
    """
    logging.getLogger("distributed").setLevel(logging.ERROR)  # a killed worker is reported by the runner
    # worker-saturation 1: a worker holds only the task it runs, the ready ones wait at the scheduler in
    # priority order (a free worker takes the longest path next, not what was queued on it early)
    with dask.config.set({"distributed.scheduler.allowed-failures": 1,
                          "distributed.scheduler.worker-saturation": 1.0}):
        cluster = client = None
        try:
            with blocking_interrupts():  # a Ctrl-C meanwhile arrives once both are up: inside this try
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                       protocol="tls://", security=Security.temporary(),
                                       dashboard_address="127.0.0.1:0",  # any free port
                                       worker_dashboard_address=None, memory_limit=0,
                                       preload=[WORKERS_IGNORE_CTRL_C])
                client = Client(cluster)
            yield client
        finally:
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()


@contextlib.contextmanager
def blocking_interrupts() -> Iterator[None]:
    """Hold Ctrl-C back while the block runs, from this process and from the processes it starts meanwhile.

    SIGINT is blocked in this thread, so the threads and processes started meanwhile inherit it blocked (a
    worker process being spawned must not die of a Ctrl-C before its preload ignores it: its nanny would fail
    to start it); multiprocessing's resource tracker is started first, since starting it unblocks SIGINT in the
    calling thread. A Ctrl-C pressed meanwhile raises KeyboardInterrupt as the block ends
    (:func:`fnnbook.execution.deferring_interrupts`, for the one a thread of a native library takes).

    (In the main thread; elsewhere, where Python delivers no Ctrl-C, the block just runs.)
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    from multiprocessing import resource_tracker  # noqa: PLC0415

    resource_tracker.ensure_running()
    with deferring_interrupts():
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            yield
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)  # a pending Ctrl-C is delivered now, and recorded


def longest_remaining(upstream: Mapping[str, Sequence[str]], seconds: Mapping[str, float]) -> dict[str, float]:
    """Each task's longest remaining path: its seconds plus the longest remaining path among its dependants.

    ``upstream`` maps each task to its upstream tasks (those outside the mapping are done and ignored);
    ``seconds`` is each task's estimated duration. The critical-path rule of list scheduling: the task that
    starts the longest chain of work still ahead goes first.
    """
    downstream: dict[str, list[str]] = {t: [] for t in upstream}
    for task, ups in upstream.items():
        for u in ups:
            if u in downstream:
                downstream[u].append(task)
    order = graphlib.TopologicalSorter({t: [u for u in ups if u in upstream] for t, ups in upstream.items()})
    path: dict[str, float] = {}
    for task in reversed(list(order.static_order())):  # dependants first
        path[task] = seconds[task] + max((path[d] for d in downstream[task]), default=0.0)
    return path


def priorities(spec: PipelineSpec, plan: Plan, verdict: Mapping[str, Decision]) -> dict[str, float]:
    """The Dask priority of each task that runs: its :func:`longest_remaining` path in estimated seconds."""
    runs = [n for n in plan.order if verdict[n].action is Action.RUN]
    last = measured_seconds(spec, plan.profile)
    return longest_remaining({n: spec.tasks[n].upstream for n in runs},
                             {n: last.get(n, UNMEASURED_SECONDS) for n in runs})


def run_on_dask(spec: PipelineSpec, plan: Plan, verdict: Mapping[str, Decision], *, workers: int,
                scheduler: str | None, threads: int, echo: Callable[[str], None],
                progress_bar: bool, on_workers: Callable[[int], None] = lambda _: None) -> dict[str, TaskOutcome]:
    """Run the plan's tasks decided to run on Dask; return every task's outcome.

    ``on_workers`` is told how many workers the cluster has, once it is up.

    Raises
    ------
    PipelineError
        If the scheduler cannot be reached.
    KeyboardInterrupt
        After cancelling the tasks and stopping their kernels.
    """
    spec = spec.for_profile(plan.profile)
    if scheduler is not None:
        try:
            ctx: contextlib.AbstractContextManager[Client] = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise PipelineError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from exc
    else:
        ctx = local_cluster(workers)
    with ctx as client:
        n_workers = len(client.scheduler_info().get("workers", {}))
        on_workers(max(1, n_workers))
        where = f"Dask scheduler {scheduler}" if scheduler else "a local Dask cluster"
        echo(f"running on {where}: {n_workers} worker(s), {threads} torch thread(s) per task")
        link = client.dashboard_link if (scheduler or _HAS_BOKEH) else None
        echo(f"dashboard: {link}" if link else "dashboard: not available (install bokeh to get one)")
        return _submit_and_wait(spec, plan, verdict, client, threads, echo, progress_bar)


def _submit_and_wait(spec: PipelineSpec, plan: Plan, verdict: Mapping[str, Decision], client: Client,
                     threads: int, echo: Callable[[str], None], progress_bar: bool) -> dict[str, TaskOutcome]:
    n = len(plan.order)
    index = {name: i for i, name in enumerate(plan.order, 1)}
    outcomes: dict[str, TaskOutcome] = {}
    futures: dict[str, Future] = {}
    stamp = f"{os.getpid()}-{time.time_ns()}"
    for name in plan.order:
        if verdict[name].action is not Action.RUN:
            outcomes[name] = verdict[name].outcome(name, spec.output_dir(plan.profile, name))
    priority = priorities(spec, plan, verdict)
    # longest path first is also an upstream-first order (a task's path exceeds its dependants'; ties keep the
    # plan's order): the first tasks submitted take the free workers, so they must be the long paths' heads
    for name in sorted(priority, key=lambda t: (-priority[t], index[t])):
        deps = [futures[u] for u in spec.tasks[name].upstream if u in futures]
        futures[name] = client.submit(execute_task, spec, plan, name, threads, *deps,
                                      key=f"{name}-{stamp}", pure=False, priority=priority[name])
    for name, o in outcomes.items():
        echo(progress_line(index[name], n, o))
    bar = tqdm(total=n, initial=len(outcomes), desc="tasks", unit="task", disable=not progress_bar,
               dynamic_ncols=True)
    pending = {f.key: name for name, f in futures.items()}
    slots, shown = sum(client.nthreads().values()), None
    try:
        while pending:
            try:
                done, _ = wait([futures[name] for name in pending.values()], timeout=1.0,
                               return_when="FIRST_COMPLETED")
            except TimeoutError:
                done = set()
            for fut in done:
                name = pending.pop(fut.key)
                outcomes[name] = _outcome(spec, plan, name, fut, outcomes)
                with tqdm.external_write_mode():
                    echo(progress_line(index[name], n, outcomes[name]))
                bar.update(1)
            # a worker's processing set also holds tasks queued behind the one it runs: at most one runs per thread
            queued = {k for keys in client.processing().values() for k in keys} & set(pending)
            counts = {s: sum(o.status == s for o in outcomes.values()) for s in Status}
            postfix = dict(done=counts[Status.OK], running=min(len(queued), slots), failed=counts[Status.FAILED],
                           skipped=counts[Status.SKIPPED])
            if postfix != shown:  # redraw on change only: a log file gets one line per change, not one a second
                bar.set_postfix(postfix, refresh=True)
                shown = postfix
    except KeyboardInterrupt:
        with ignoring_interrupts():  # a second Ctrl-C: the cancel still runs to its end
            bar.close()
            _cancel(client, futures, spec, plan, pending)
            logs = logs_dir(spec, plan.profile)
            stopped = {n: interrupted(n, spec.output_dir(plan.profile, n), logs / f"{n}.log")
                       for n in pending.values()}
        raise Interrupted({**outcomes, **stopped}) from None
    except BaseException:
        bar.close()
        _cancel(client, futures, spec, plan, pending)
        raise
    bar.close()
    return outcomes


def _outcome(spec: PipelineSpec, plan: Plan, name: str, fut: Future,
             known: Mapping[str, TaskOutcome]) -> TaskOutcome:
    out = spec.output_dir(plan.profile, name)
    log = logs_dir(spec, plan.profile) / f"{name}.log"
    if fut.status == "finished":
        return fut.result()
    if (up := blocked_by(spec.tasks[name], known)) is not None:
        return blocked(name, out, up, known)
    exc = fut.exception()
    why = f"{type(exc).__name__}: {exc}".splitlines()[0]
    if type(exc).__name__ == "KilledWorker":
        why = "the worker process running it died (twice, with the retry); outputs untouched"
    mark_killed(log, why)
    shutil.rmtree(staging_dir(spec, plan.profile, name, plan.run), ignore_errors=True)
    return TaskOutcome(name, Status.FAILED, 0.0, out, log, why)


def _cancel(client: Client, futures: Mapping[str, Future], spec: PipelineSpec, plan: Plan,
            pending: Mapping[str, str]) -> None:
    """Cancel every task, stop the running kernels, mark their logs.

    (Each task's own error handling removes its staging folder; the next run clears any that is left.)
    """
    with contextlib.suppress(Exception):
        client.cancel(list(futures.values()), force=True)
    with contextlib.suppress(Exception):
        client.run(stop_kernels)  # awaited on each worker: its kernels end, those still starting too
    for name in pending.values():
        mark_killed(logs_dir(spec, plan.profile) / f"{name}.log", "interrupted (Ctrl-C)")
