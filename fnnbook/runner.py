"""Execute pipeline tasks with papermill: checked first, skipped when up to date.

Layout under ``<output_root>/<profile>/``::

    <task>/                 last good outputs (products, <task>.ipynb, .fingerprint.json)
    .staging/<task>/        the run in progress; swapped in only on success
    _logs/<task>.log        log of the last attempt (kernel output, error)
    _logs/<task>.ipynb      the executed notebook of a failed attempt
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
import traceback
import uuid
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import fnnlib
from fnnbook.scoreboard import read_claims
from fnnbook.params import check_task_parameters, read_parameters, resolve_parameters
from fnnbook.spec import PipelineError, PipelineSpec, Task

__all__ = ["Plan", "RunReport", "TaskOutcome", "check", "is_up_to_date", "run"]

FINGERPRINT_FILE = ".fingerprint.json"
KERNEL = "python3"
#: torch intra-op threads in each notebook's kernel (importing fnnlib no longer sets them)
TASK_THREADS = 1


def _kernel_arguments(threads: int) -> list[str]:
    """ipykernel options that set torch's threads before the notebook's first cell."""
    return [f"--IPKernelApp.exec_lines=['import torch', 'torch.set_num_threads({int(threads)})']"]


@dataclass(frozen=True)
class Plan:
    """What a run would execute: checked parameters and input fingerprints.

    Attributes
    ----------
    profile : str
    order : tuple of str
        Selected tasks and their upstream tasks, upstream first.
    selected : tuple of str
        The tasks asked for (all when none were named).
    parameters : mapping of str to dict
        Task -> parameters papermill injects.
    fingerprints : mapping of str to str
        Task -> sha256 over its notebook, parameters, upstream fingerprints
        and the library sources.
    """

    profile: str
    order: tuple[str, ...]
    selected: tuple[str, ...]
    parameters: Mapping[str, dict[str, Any]]
    fingerprints: Mapping[str, str]


@dataclass(frozen=True)
class TaskOutcome:
    """How one task fared: ``status`` is "ok", "skipped", "failed" or "not run"."""

    task: str
    status: str
    seconds: float
    out_dir: Path
    log: Path | None = None
    message: str = ""


@dataclass(frozen=True)
class RunReport:
    """The outcomes of one :func:`run`, in execution order."""

    profile: str
    outcomes: tuple[TaskOutcome, ...]

    @property
    def ok(self) -> bool:
        """True when no task failed or was left out."""
        return all(o.status in ("ok", "skipped") for o in self.outcomes)

    def outcome(self, task: str) -> TaskOutcome:
        """The outcome of ``task``."""
        for o in self.outcomes:
            if o.task == task:
                return o
        raise KeyError(task)


def _staging_dir(spec: PipelineSpec, profile: str, task: str) -> Path:
    return spec.output_root / profile / ".staging" / task


def _logs_dir(spec: PipelineSpec, profile: str) -> Path:
    return spec.output_root / profile / "_logs"


def _sources_digest(sources: Sequence[Path]) -> str:
    """sha256 over every ``*.py`` file below ``sources`` (paths and bytes)."""
    h = hashlib.sha256()
    for root in sources:
        for file in sorted(Path(root).rglob("*.py")):
            if "__pycache__" in file.parts:
                continue
            h.update(file.relative_to(root).as_posix().encode())
            h.update(b"\0")
            h.update(file.read_bytes())
            h.update(b"\0")
    return h.hexdigest()


def _fingerprint(task: Task, params: Mapping[str, Any], upstream: Mapping[str, str], sources: str) -> str:
    h = hashlib.sha256()
    h.update(task.notebook.read_bytes())
    stable = {k: v for k, v in params.items() if k != "out_dir"}  # out_dir is the staging folder
    h.update(json.dumps(stable, sort_keys=True, default=str).encode())
    h.update(json.dumps(dict(sorted(upstream.items()))).encode())
    h.update(sources.encode())
    return h.hexdigest()


def _known_claims(claims_file: Path) -> set[str] | None:
    if not claims_file.is_file():
        return None
    return {c.id for c in read_claims(claims_file)}


def check(
    spec: PipelineSpec,
    profile: str,
    tasks: Iterable[str] | None = None,
    *,
    sources: Sequence[str | os.PathLike[str]] | None = None,
) -> Plan:
    """Validate the selected tasks and their upstream tasks; run nothing.

    Parameters
    ----------
    spec : PipelineSpec
    profile : str
        Name of a parameter profile, e.g. ``"paper"`` or ``"smoke"``.
    tasks : iterable of str, optional
        Tasks to run; their upstream tasks are added.  Default: all.
    sources : sequence of path-like, optional
        Folders whose ``*.py`` files enter every fingerprint.  Default: the
        installed ``fnnlib`` package.

    Returns
    -------
    Plan

    Raises
    ------
    PipelineError
        On the first invalid task, parameter, claim ID or data folder.
    """
    if profile not in spec.profiles:
        raise PipelineError(f"unknown profile {profile!r}; profiles: {', '.join(spec.profiles)}")
    selected = list(dict.fromkeys(tasks)) if tasks else list(spec.tasks)
    order = spec.closure(selected)
    claims = _known_claims(spec.claims_file)
    src = [Path(s) for s in sources] if sources is not None else [Path(fnnlib.__file__).resolve().parent]
    digest = _sources_digest(src)
    parameters: dict[str, dict[str, Any]] = {}
    fingerprints: dict[str, str] = {}
    for name in order:
        task = spec.tasks[name]
        declared = read_parameters(task.notebook)
        check_task_parameters(task, profile, declared)
        if claims is not None:
            for cid in task.claims:
                if cid not in claims:
                    raise PipelineError(f"task {name!r} declares claim {cid!r}, which is not in "
                                        f"{spec.claims_file.name}")
        params = resolve_parameters(spec, task, profile, declared,
                                    out_dir=_staging_dir(spec, profile, name))
        parameters[name] = params
        fingerprints[name] = _fingerprint(task, params, {u: fingerprints[u] for u in task.upstream}, digest)
    return Plan(profile=profile, order=tuple(order), selected=tuple(selected),
                parameters=parameters, fingerprints=fingerprints)


def _recover(spec: PipelineSpec, profile: str, task: str) -> None:
    """Put back an output folder left aside by an interrupted swap."""
    final = spec.output_dir(profile, task)
    old = _staging_dir(spec, profile, task).with_name(f"{task}.old")
    if old.is_dir():
        if final.exists():
            shutil.rmtree(old)
        else:
            os.rename(old, final)


def _stored(spec: PipelineSpec, profile: str, task: str) -> dict[str, Any]:
    """The ``.fingerprint.json`` of a task's last good output ({} if none)."""
    try:
        stored = json.loads((spec.output_dir(profile, task) / FINGERPRINT_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return stored if isinstance(stored, dict) else {}


def is_up_to_date(spec: PipelineSpec, plan: Plan, task: str) -> bool:
    """Whether ``task``'s last good output is current.

    True when its output folder holds every product, was made with the
    plan's fingerprint, and from the upstream outputs that are there now
    (an upstream task rerun since, even with the same inputs, makes it stale).
    """
    out = spec.output_dir(plan.profile, task)
    stored = _stored(spec, plan.profile, task)
    if not stored or stored.get("fingerprint") != plan.fingerprints[task]:
        return False
    runs = {u: _stored(spec, plan.profile, u).get("run_id") for u in spec.tasks[task].upstream}
    if stored.get("upstream_runs") != runs:
        return False
    return all((out / p).exists() for p in spec.tasks[task].products)


def _swap(staging: Path, final: Path) -> None:
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


def _point_to_final(executed: Path, staging: Path, final: Path) -> None:
    """Make the executed notebook name the final output folder wherever it names staging.

    (The injected ``out_dir``, papermill's metadata, printed paths.)
    """
    old, new = json.dumps(str(staging))[1:-1], json.dumps(str(final))[1:-1]
    text = executed.read_text(encoding="utf-8")
    if old in text:
        executed.write_text(text.replace(old, new), encoding="utf-8")


def _execute(spec: PipelineSpec, plan: Plan, name: str, progress_bar: bool) -> tuple[float, str]:
    """Run one task's notebook into staging and swap it in.

    Returns the elapsed seconds and an error message ("" on success); a
    KeyboardInterrupt is re-raised after the failure is recorded.
    """
    import papermill  # noqa: PLC0415 (only needed to execute)

    task = spec.tasks[name]
    staging = _staging_dir(spec, plan.profile, name)
    final = spec.output_dir(plan.profile, name)
    logs = _logs_dir(spec, plan.profile)
    log = logs / f"{name}.log"
    failed_nb = logs / f"{name}.ipynb"
    executed = staging / f"{name}.ipynb"
    params = plan.parameters[name]

    _recover(spec, plan.profile, name)
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir(parents=True)
    logs.mkdir(parents=True, exist_ok=True)
    failed_nb.unlink(missing_ok=True)
    start = time.perf_counter()
    with open(log, "w", encoding="utf-8") as fh:
        fh.write(f"task: {name}\nprofile: {plan.profile}\nnotebook: {task.notebook}\n"
                 f"parameters: {json.dumps(params, sort_keys=True)}\n\n--- kernel output ---\n")
        fh.flush()
        try:
            papermill.execute_notebook(
                str(task.notebook), str(executed), parameters=params, kernel_name=KERNEL,
                cwd=str(spec.root), progress_bar=progress_bar, stdout_file=fh, stderr_file=fh,
                extra_arguments=_kernel_arguments(TASK_THREADS),
            )
            missing = [p for p in task.products if not (staging / p).exists()]
            if missing:
                raise PipelineError(f"the notebook finished but did not write these products: "
                                    f"{', '.join(missing)} (into out_dir)")
            _point_to_final(executed, staging, final)
            record = {"fingerprint": plan.fingerprints[name], "task": name, "profile": plan.profile,
                      "parameters": {k: v for k, v in params.items() if k != "out_dir"},
                      "run_id": uuid.uuid4().hex,
                      "upstream_runs": {u: _stored(spec, plan.profile, u).get("run_id")
                                        for u in task.upstream}}
            (staging / FINGERPRINT_FILE).write_text(json.dumps(record, indent=2, sort_keys=True) + "\n",
                                                    encoding="utf-8")
            _swap(staging, final)
        except BaseException as exc:
            elapsed = time.perf_counter() - start
            cell_error = hasattr(exc, "ename") and hasattr(exc, "evalue")  # papermill's cell error
            detail = str(exc) if cell_error else traceback.format_exc()
            fh.write(f"\n--- FAILED after {elapsed:.1f} s ---\n{type(exc).__name__}: {detail}\n")
            if executed.exists():
                shutil.copy2(executed, failed_nb)
                fh.write(f"executed notebook: {failed_nb}\n")
            shutil.rmtree(staging, ignore_errors=True)
            if not isinstance(exc, Exception):
                raise
            if cell_error:
                return elapsed, f"{getattr(exc, 'ename')}: {getattr(exc, 'evalue')}"
            return elapsed, (f"{type(exc).__name__}: {exc}".strip().splitlines() or [""])[0]
        elapsed = time.perf_counter() - start
        fh.write(f"\n--- ok after {elapsed:.1f} s ---\n")
    return elapsed, ""


def run(
    spec: PipelineSpec,
    profile: str,
    tasks: Iterable[str] | None = None,
    *,
    force: bool = False,
    progress_bar: bool = True,
    echo: Callable[[str], None] = print,
    sources: Sequence[str | os.PathLike[str]] | None = None,
) -> RunReport:
    """Check, then execute, the selected tasks and any stale upstream tasks.

    Every selected task and its upstream tasks are validated before anything
    runs (:func:`check`).  A task is skipped when it is up to date
    (:func:`is_up_to_date`: same fingerprint, same upstream outputs, products
    present) unless ``force``, which applies to the selected tasks only.  Each
    task executes in ``<output_root>/<profile>/.staging/<task>/`` and
    replaces ``<output_root>/<profile>/<task>/`` only on success; a failed
    task leaves the previous outputs untouched and its log in ``_logs/``.

    Parameters
    ----------
    spec : PipelineSpec
    profile : str
    tasks : iterable of str, optional
        Default: every task.
    force : bool
        Rerun the selected tasks even if up to date.
    progress_bar : bool
        Show papermill's per-cell progress bar.
    echo : callable
        Receives each progress line.
    sources : sequence of path-like, optional
        See :func:`check`.

    Returns
    -------
    RunReport
        ``report.ok`` is False when a task failed.

    Raises
    ------
    PipelineError
        If the check fails (nothing has run).
    KeyboardInterrupt
        Re-raised after the interrupted task is recorded as failed.
    """
    plan = check(spec, profile, tasks, sources=sources)
    n = len(plan.order)
    outcomes: list[TaskOutcome] = []
    executed: set[str] = set()
    bad: set[str] = set()
    for i, name in enumerate(plan.order, 1):
        task = spec.tasks[name]
        out = spec.output_dir(profile, name)
        prefix = f"[{i}/{n}] {name} ..."
        blocked = [u for u in task.upstream if u in bad]
        if blocked:
            bad.add(name)
            outcomes.append(TaskOutcome(name, "not run", 0.0, out, message=f"upstream {blocked[0]} failed"))
            echo(f"{prefix} not run (upstream {blocked[0]} failed)")
            continue
        _recover(spec, profile, name)
        stale = ((force and name in plan.selected) or any(u in executed for u in task.upstream)
                 or not is_up_to_date(spec, plan, name))
        if not stale:
            outcomes.append(TaskOutcome(name, "skipped", 0.0, out))
            echo(f"{prefix} skipped (up to date)")
            continue
        echo(prefix)
        log = _logs_dir(spec, profile) / f"{name}.log"
        try:
            seconds, error = _execute(spec, plan, name, progress_bar)
        except BaseException:
            outcomes.append(TaskOutcome(name, "failed", 0.0, out, log, "interrupted"))
            echo(f"{prefix} FAILED (interrupted; see log {log})")
            echo(_summary(RunReport(profile, tuple(outcomes))))
            raise
        executed.add(name)
        if error:
            bad.add(name)
            outcomes.append(TaskOutcome(name, "failed", seconds, out, log, error))
            echo(f"{prefix} FAILED (see log {log})\n    {error}")
        else:
            outcomes.append(TaskOutcome(name, "ok", seconds, out, log))
            echo(f"{prefix} ok ({seconds:.1f} s)")
    report = RunReport(profile, tuple(outcomes))
    echo(_summary(report))
    return report


def _summary(report: RunReport) -> str:
    counts: dict[str, int] = {}
    for o in report.outcomes:
        counts[o.status] = counts.get(o.status, 0) + 1
    parts = [f"{counts[s]} {s}" for s in ("ok", "skipped", "failed", "not run") if counts.get(s)]
    lines = [f"profile {report.profile}: {', '.join(parts) or 'nothing to do'}"]
    for o in report.outcomes:
        if o.status == "failed":
            lines.append(f"  FAILED {o.task}: log {o.log}")
    return "\n".join(lines)
