"""One task's execution: its notebook run by papermill into staging, its run record, the swap; its outcome."""

from __future__ import annotations

import contextlib
import json
import shutil
import signal
import threading
import tempfile
import time
import traceback
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import IO, TYPE_CHECKING

import papermill

from fnnbook.fingerprint import product_files, stored
from fnnbook.kernel import KERNEL, TASK_THREADS, kernel_arguments, kernel_config, kill_kernels, task_kernel
from fnnbook.layout import logs_dir, mark_killed, point_to_final, recover, staging_dir, swap
from fnnbook.outcome import Status, TaskOutcome, blocked, blocked_by
from fnnbook.params import FINGERPRINT_FILE, INJECTED
from fnnbook.spec import PipelineError, PipelineSpec
from fnnlib.io import atomic_write, file_sha256

if TYPE_CHECKING:
    from fnnbook.plan import Plan

__all__ = ["deferring_interrupts", "execute", "execute_task", "ignoring_interrupts"]


#: a notebook's own error that is the file system's (a full disk, a read-only folder, a missing permission)
_OS_ERRORS = frozenset({"OSError", "PermissionError", "FileNotFoundError", "IsADirectoryError", "IOError"})


@contextlib.contextmanager
def ignoring_interrupts() -> Iterator[None]:
    """Ignore Ctrl-C while a failure is recorded (a second Ctrl-C must not leave staging or a log unmarked)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, before)


@contextlib.contextmanager
def deferring_interrupts() -> Iterator[None]:
    """Hold Ctrl-C back while the block runs: one pressed meanwhile raises KeyboardInterrupt as it ends.

    (In the main thread; elsewhere, where Python delivers no Ctrl-C, the block just runs.)
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pressed: list[int] = []
    before = signal.signal(signal.SIGINT, lambda signum, _frame: pressed.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, before)
    if pressed:
        raise KeyboardInterrupt


def execute(spec: PipelineSpec, plan: Plan, name: str, progress_bar: bool,
            threads: int = TASK_THREADS) -> TaskOutcome:
    """Run one task's notebook into this run's staging folder and swap it in; its outcome.

    A file-system fault (read-only or full disk, no permission) is a failed
    outcome with ``io_error`` set and one line saying which file; staging is
    removed whatever happens. A KeyboardInterrupt is re-raised after the
    failure is recorded (a second Ctrl-C meanwhile is ignored).
    """
    task = spec.tasks[name]
    staging = staging_dir(spec, plan.profile, name, plan.run)
    out = spec.output_dir(plan.profile, name)
    logs = logs_dir(spec, plan.profile)
    log = logs / f"{name}.log"
    executed = staging / f"{name}.ipynb"
    params = plan.parameters[name]
    start = time.perf_counter()
    fh: IO[str] | None = None
    try:
        recover(spec, plan.profile, name)
        shutil.rmtree(staging, ignore_errors=True)
        staging.mkdir(parents=True)
        fh = _open_log(logs, name)
        fh.write(f"task: {name}\nprofile: {plan.profile}\nnotebook: {task.notebook}\n"
                 f"torch threads: {threads}\n"
                 f"parameters: {json.dumps(params, sort_keys=True)}\n\n--- kernel output ---\n")
        fh.flush()
        with tempfile.TemporaryDirectory(prefix="fnn-kernel-") as sockets, task_kernel():
            papermill.execute_notebook(
                str(task.notebook), str(executed), parameters=params, kernel_name=KERNEL,
                cwd=str(spec.root), progress_bar=progress_bar, stdout_file=fh, stderr_file=fh,
                config=kernel_config(sockets), extra_arguments=kernel_arguments(threads),
            )
        _publish(spec, plan, name, staging, executed, out)
        elapsed = time.perf_counter() - start
    except BaseException as exc:
        with ignoring_interrupts():
            try:
                return _failed(exc, name, out, log, fh, staging, executed, time.perf_counter() - start)
            finally:
                if fh is not None:
                    with contextlib.suppress(OSError):
                        fh.close()
    try:  # the outputs are in: a log that cannot take its last line does not undo that
        fh.write(f"\n--- ok after {elapsed:.1f} s ---\n")
        fh.close()
    except OSError:
        pass
    return TaskOutcome(name, Status.OK, elapsed, out, log)


def _open_log(logs: Path, name: str) -> IO[str]:
    """A fresh ``_logs/<name>.log``; the last attempt's log kept as ``<name>.previous.log`` (the caller holds
    the task's lock, so no other run writes these)."""
    log = logs / f"{name}.log"
    logs.mkdir(parents=True, exist_ok=True)
    mark_killed(log, "the process running this attempt was killed")
    if log.exists():  # keep the last attempt's log for reading
        log.replace(logs / f"{name}.previous.log")
    (logs / f"{name}.ipynb").unlink(missing_ok=True)
    return open(log, "w", encoding="utf-8")


def _publish(spec: PipelineSpec, plan: Plan, name: str, staging: Path, executed: Path, final: Path) -> None:
    """Check the products, write the run record beside them, and swap staging in."""
    task = spec.tasks[name]
    params = plan.parameters[name]
    products, missing = product_files(task.products, staging)
    if missing:
        raise PipelineError(f"the notebook finished but did not write these products: "
                            f"{', '.join(missing)} (into out_dir)")
    point_to_final(executed, staging, final, spec.root)
    record = {"fingerprint": plan.fingerprints[name], "task": name, "profile": plan.profile,
              "parameters": {k: v for k, v in params.items() if k not in INJECTED or k == "profile"},
              "run_id": uuid.uuid4().hex,
              "upstream_runs": {u: stored(spec, plan.profile, u).get("run_id") for u in task.upstream},
              "products": {p: file_sha256(staging / p) for p in products},
              "inputs": plan.inputs.get(name)}
    with atomic_write(staging / FINGERPRINT_FILE, "w") as fh:
        fh.write(json.dumps(record, indent=2, sort_keys=True) + "\n")
    swap(staging, final)


def _failed(exc: BaseException, name: str, out: Path, log: Path, fh: IO[str] | None, staging: Path,
            executed: Path, elapsed: float) -> TaskOutcome:
    """Record a failed attempt (log marker, the executed notebook kept) and remove staging; re-raise Ctrl-C.

    Nothing here may raise on a full disk: the log and the copy are best effort, staging always goes.
    """
    interrupted = not isinstance(exc, Exception)
    if interrupted:  # Ctrl-C: the kernel (in its own session) would outlive us
        kill_kernels()
    cell_error = hasattr(exc, "ename") and hasattr(exc, "evalue")  # papermill's cell error
    io_error = isinstance(exc, OSError) or (cell_error and getattr(exc, "ename") in _OS_ERRORS)
    if isinstance(exc, OSError):
        message = f"{type(exc).__name__}: {exc.strerror or exc}" + (f": {exc.filename}" if exc.filename else "")
    elif cell_error:
        message = f"{getattr(exc, 'ename')}: {getattr(exc, 'evalue')}"
    else:
        message = (f"{type(exc).__name__}: {exc}".strip().splitlines() or [""])[0]
    with contextlib.suppress(OSError):
        if fh is not None and not fh.closed:
            detail = str(exc) if cell_error or io_error else traceback.format_exc()
            fh.write(f"\n--- FAILED after {elapsed:.1f} s ---\n{type(exc).__name__}: {detail}\n")
            fh.flush()
    with contextlib.suppress(OSError):
        if executed.exists():
            shutil.copy2(executed, log.with_suffix(".ipynb"))
            if fh is not None and not fh.closed:
                fh.write(f"executed notebook: {log.with_suffix('.ipynb')}\n")
    shutil.rmtree(staging, ignore_errors=True)
    with contextlib.suppress(OSError):
        staging.parent.rmdir()  # this run's staging folder, once empty
    if interrupted:
        raise exc
    return TaskOutcome(name, Status.FAILED, elapsed, out, log, message, io_error=io_error)


def execute_task(spec: PipelineSpec, plan: Plan, name: str, threads: int,
                 *upstream: TaskOutcome) -> TaskOutcome:
    """Run one task unless an upstream outcome stops it; the unit of work of an executor.

    Module-level and with picklable arguments, so a Dask worker runs it (the
    upstream outcomes are those tasks' results, passed in as dependencies).
    """
    out = spec.output_dir(plan.profile, name)
    known = {up.task: up for up in upstream}
    if (up := blocked_by(spec.tasks[name], known)) is not None:
        return blocked(name, out, up, known)
    return execute(spec, plan, name, False, threads)
