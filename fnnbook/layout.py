"""The output layout under ``<output_root>/<profile>/``, the atomic swap of a task's outputs, logs, status.

::

    <task>/                 last good outputs (products, <task>.ipynb, .fingerprint.json)
    .staging/<run>/<task>/  a run in progress, in a folder of its own; swapped in only on success
    .locks/<task>.lock      held by the one run that may write <task>/ and its log (``.holder``: who)
    _logs/<task>.log        log of the last attempt (kernel output, error)
    _logs/<task>.ipynb      the executed notebook of a failed attempt
    _status.json            how each task of the last run fared (read by the book), its last measured
                            seconds, and under "_run" the last run's workers, wall time and utilisation

One writer per output: a run holds the writer lock of every task it runs and a reader's share of every task
it only reads (taken in name order, so two runs never wait on each other in a circle) from its decisions to
its summary; the book holds a reader's share of every task. A second run that would write what another
writes or reads waits, and says which process it waits for; readers and runs of disjoint tasks go side by
side. A run marks its staging folder alive with ``.staging/<run>.lock``; an ended run's folder is removed.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import socket
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from filelock import FileLock

from fnnbook.outcome import RunReport, Status
from fnnbook.spec import PipelineError, PipelineSpec
from fnnlib.io import atomic_write

__all__ = ["RUN_KEY", "STATUS_FILE", "clear_stale", "holding", "staging_of", "logs_dir", "mark_killed", "measured_seconds", "point_to_final",
           "read_status",
           "recover", "staging_dir", "swap", "write_status"]

LOCKS = ".locks"

STATUS_FILE = "_status.json"
#: the entry of ``_status.json`` that describes the last run as a whole, not a task
RUN_KEY = "_run"
_END_MARKERS = ("\n--- ok after ", "\n--- FAILED")


def staging_dir(spec: PipelineSpec, profile: str, task: str, run: str) -> Path:
    """Where run ``run`` writes ``task``'s outputs before the swap (no other run writes there)."""
    return spec.output_root / spec.home(profile, task) / ".staging" / run / task


def logs_dir(spec: PipelineSpec, profile: str) -> Path:
    return spec.output_root / profile / "_logs"



def recover(spec: PipelineSpec, profile: str, task: str) -> None:
    """Put back an output folder left aside by an interrupted swap (of any run: the caller holds the lock)."""
    final = spec.output_dir(profile, task)
    for old in (spec.output_root / spec.home(profile, task) / ".staging").glob(f"*/{task}.old"):
        if final.exists():
            shutil.rmtree(old)
        else:
            os.rename(old, final)


def clear_stale(spec: PipelineSpec, profile: str, tasks: Iterable[str], run: str) -> None:
    """Remove what ended runs (killed ones too) left in staging; put back swaps cut short for ``tasks``.

    A run holds ``.staging/<run>.lock`` while it lives, so a folder whose lock can be taken is an ended run's.
    Its partial outputs go; an output folder it had set aside mid-swap (``<task>.old``) is put back only for
    ``tasks``, whose writer locks the caller holds, and kept for the next run that writes it otherwise.
    """
    tasks = set(tasks)
    for task in tasks:
        recover(spec, profile, task)
    for folder in sorted(p for staging in _staging_roots(spec, profile) for p in staging.glob("*")
                         if p.is_dir() and p.name != run):
        with _flock(folder.with_name(f"{folder.name}.lock"), fcntl.LOCK_EX | fcntl.LOCK_NB) as ended:
            if not ended:
                continue  # a live run's
            for left in folder.iterdir():
                if not left.name.endswith(".old"):
                    shutil.rmtree(left, ignore_errors=True)
            with contextlib.suppress(OSError):
                folder.rmdir()  # only when empty (a set-aside output waits for its task's writer)
                folder.with_name(f"{folder.name}.lock").unlink()


@contextlib.contextmanager
def _flock(path: Path, mode: int) -> Iterator[bool]:
    """flock ``path`` (created if missing) in ``mode``; yields whether it was taken (False: LOCK_NB and busy)."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        try:
            fcntl.flock(fd, mode)
        except BlockingIOError:
            yield False
            return
        yield True
    finally:
        os.close(fd)  # releases the lock


def _staging_roots(spec: PipelineSpec, profile: str) -> list[Path]:
    """The staging folders a run of ``profile`` writes in: its own, and the extended profile's (where the
    tasks it inherits keep their outputs)."""
    return [spec.output_root / p / ".staging" for p in dict.fromkeys((profile, spec.home_profile(profile)))]


@contextlib.contextmanager
def staging_of(spec: PipelineSpec, profile: str, run: str) -> Iterator[None]:
    """Mark run ``run`` alive for its lifetime (``.staging/<run>.lock`` held, in every staging folder it writes
    in); remove its folders at the end."""
    with contextlib.ExitStack() as stack:
        for staging in _staging_roots(spec, profile):
            try:
                staging.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise PipelineError(f"cannot write to the output root {spec.output_root}: {_why(exc)}") from exc
            stack.enter_context(_flock(staging / f"{run}.lock", fcntl.LOCK_EX))
            stack.callback(_remove_run, staging, run)
        yield


def _remove_run(staging: Path, run: str) -> None:
    with contextlib.suppress(OSError):
        (staging / run).rmdir()
    with contextlib.suppress(OSError):
        (staging / f"{run}.lock").unlink()


def _holder(path: Path) -> str:
    try:
        who = json.loads(path.read_text(encoding="utf-8"))
        return f"pid {who['pid']} on {who['host']} ({who['command']}, since {who['since']})"
    except (OSError, ValueError, KeyError, TypeError):
        return "another process (no holder record)"


@contextlib.contextmanager
def holding(spec: PipelineSpec, profile: str, tasks: Iterable[str], *, read: Iterable[str] = (),
            echo: Callable[[str], None] = print) -> Iterator[None]:
    """Hold the writer lock of each of ``tasks``' outputs and a reader's share of each of ``read``'s.

    One writer or any number of readers per task output (``flock``: exclusive or shared); the locks are
    taken in name order. While another run holds one, wait, and say who (``.locks/<task>.holder``).

    Raises
    ------
    PipelineError
        If the output root cannot hold the lock files (read-only, full, no permission).
    """
    modes = {t: fcntl.LOCK_SH for t in read}
    modes.update({t: fcntl.LOCK_EX for t in tasks})
    with contextlib.ExitStack() as held:
        for task in sorted(modes):
            folder = spec.output_root / spec.home(profile, task) / LOCKS  # beside the folder it guards
            try:
                folder.mkdir(parents=True, exist_ok=True)
                lock = folder / f"{task}.lock"
                if not held.enter_context(_flock(lock, modes[task] | fcntl.LOCK_NB)):
                    echo(f"waiting: the outputs of {task} are in use by {_holder(folder / f'{task}.holder')}")
                    held.enter_context(_flock(lock, modes[task]))
                if modes[task] == fcntl.LOCK_EX:
                    who = {"pid": os.getpid(), "host": socket.gethostname(), "command": " ".join(sys.argv),
                           "since": time.strftime("%Y-%m-%d %H:%M:%S")}
                    with atomic_write(folder / f"{task}.holder", "w") as fh:
                        fh.write(json.dumps(who) + "\n")
            except OSError as exc:
                raise PipelineError(f"cannot write to the output root {spec.output_root}: {_why(exc)}") from exc
        yield


def _why(exc: OSError) -> str:
    """An OSError in one line: what failed on which file."""
    return f"{exc.strerror or exc}" + (f": {exc.filename}" if exc.filename else "")


def swap(staging: Path, final: Path) -> None:
    """Replace ``final`` by ``staging`` with renames only (old aside, new in, old deleted)."""
    old = staging.with_name(f"{final.name}.old")
    if old.exists():
        shutil.rmtree(old)
    if final.exists():
        os.rename(final, old)
    try:
        os.rename(staging, final)
    except BaseException:
        if old.exists() and not final.exists():
            os.rename(old, final)
        raise
    shutil.rmtree(old, ignore_errors=True)


def point_to_final(executed: Path, staging: Path, final: Path, root: Path) -> None:
    """Make the executed notebook name the final output folder wherever it names staging, and write the
    repository's absolute path out of the cells' outputs.

    (Staging: the injected ``out_dir``, papermill's metadata, printed paths. The repository root: a warning's
    ``/abs/repo/fnnlib/...:92`` reads ``fnnlib/...:92``; sources and metadata keep it, for a rerun.)
    """
    old, new = json.dumps(str(staging))[1:-1], json.dumps(str(final))[1:-1]
    nb = json.loads(executed.read_text(encoding="utf-8").replace(old, new))
    prefix = str(root).rstrip(os.sep) + os.sep

    def relative(value: Any) -> Any:
        if isinstance(value, str):
            return value.replace(prefix, "")
        if isinstance(value, list):
            return [relative(v) for v in value]
        if isinstance(value, dict):
            return {k: v if k.startswith("image/") else relative(v) for k, v in value.items()}
        return value

    for cell in nb.get("cells", []):
        if "outputs" in cell:
            cell["outputs"] = relative(cell["outputs"])
    executed.write_text(json.dumps(nb, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")


def mark_killed(log: Path, why: str) -> None:
    """Append a FAILED marker to a task's log that has no end marker (its process was killed)."""
    try:
        text = log.read_text(encoding="utf-8")
    except OSError:
        return
    if not any(m in text for m in _END_MARKERS):
        with open(log, "a", encoding="utf-8") as fh:
            fh.write(f"\n--- FAILED: {why} ---\n")



def write_status(spec: PipelineSpec, report: RunReport) -> Path:
    """Record each task's last outcome in ``<output_root>/<profile>/_status.json`` (the book reads it).

    A task that ran ok records its seconds (the scheduler's estimate next time, :func:`measured_seconds`); one
    that did not keeps its last measured seconds. A run in which a task ran records itself under
    :data:`RUN_KEY`: workers, wall seconds, task seconds and the utilisation (:attr:`RunReport.utilisation`).
    """
    path = spec.output_root / report.profile / STATUS_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    with FileLock(path.with_name(f".{STATUS_FILE}.lock")):  # runs of disjoint tasks share this file
        status = read_status(spec, report.profile)
        for o in report.outcomes:
            entry = {"status": str(o.status), "message": o.message}
            if o.status == Status.OK:  # the measured time; a task that did not run keeps its last one
                entry["seconds"] = round(o.seconds, 2)
            elif (last := _seconds(status, o.task)) is not None:
                entry["seconds"] = last
            status[o.task] = entry
        if report.utilisation is not None:
            status[RUN_KEY] = {"workers": report.workers, "wall_seconds": round(report.wall, 2),
                               "task_seconds": round(report.busy, 2),
                               "utilisation": round(report.utilisation, 4)}
        with atomic_write(path, "w") as fh:
            fh.write(json.dumps(status, indent=2, sort_keys=True) + "\n")
    return path


def measured_seconds(spec: PipelineSpec, profile: str) -> dict[str, float]:
    """Task -> the seconds its last successful run took, from ``_status.json`` (tasks never measured: absent)."""
    status = read_status(spec, profile)
    return {task: seconds for task in status if task != RUN_KEY and (seconds := _seconds(status, task)) is not None}


def _seconds(status: dict[str, Any], task: str) -> float | None:
    entry = status.get(task)
    seconds = entry.get("seconds") if isinstance(entry, dict) else None
    return float(seconds) if isinstance(seconds, (int, float)) and not isinstance(seconds, bool) else None


def read_status(spec: PipelineSpec, profile: str) -> dict[str, dict[str, Any]]:
    """The ``_status.json`` of a profile ({} if none)."""
    try:
        status = json.loads((spec.output_root / profile / STATUS_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return status if isinstance(status, dict) else {}

