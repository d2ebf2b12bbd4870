"""Execute pipeline tasks with papermill: checked first, skipped when up to date.

Layout under ``<output_root>/<profile>/``::

    <task>/                 last good outputs (products, <task>.ipynb, .fingerprint.json)
    .staging/<task>/        the run in progress; swapped in only on success
    _logs/<task>.log        log of the last attempt (kernel output, error)
    _logs/<task>.ipynb      the executed notebook of a failed attempt
    _status.json            how each task of the last run fared (read by the book)

Tasks execute one after another in this process (``workers=1``) or on a
Dask cluster (:mod:`fnnbook.executor`); the checks, fingerprints, skipping
and the atomic swap of outputs are the same either way.
"""

from __future__ import annotations

import contextlib
import dataclasses
import glob
import hashlib
import json
import os
import shutil
import tempfile
import time
import traceback
import uuid
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import papermill
import psutil

import fnnlib
from fnnbook.params import FINGERPRINT_FILE, INJECTED, check_task_parameters, read_parameters, resolve_parameters
from fnnbook.preflight import check_grid_upstream, check_task_values
from fnnbook.scoreboard import read_claims
from fnnbook.spec import PipelineError, PipelineSpec, Task
from fnnlib.io import atomic_write, file_sha256

__all__ = ["Plan", "RunReport", "TaskOutcome", "check", "decide", "execute_task", "is_up_to_date", "summary",
           "write_status"]

STATUS_FILE = "_status.json"
KERNEL = "python3"
#: torch intra-op threads in each notebook's kernel when run in-process with one core (importing fnnlib
#: no longer sets them); a run on K workers gives each task cores // K (see fnnbook.executor)
TASK_THREADS = 1
_END_MARKERS = ("\n--- ok after ", "\n--- FAILED")


#: Run once in each kernel before the first cell: torch gets its threads the moment the notebook imports it
#: (a meta-path hook), so a kernel whose notebook never imports torch does not pay ~2 s of CPU for it.
_TORCH_THREADS_HOOK = """
def _fnn_torch_threads(threads):
    import sys
    from importlib.machinery import PathFinder

    class SetTorchThreads:
        def find_spec(self, name, path=None, target=None):
            if name != "torch":
                return None
            sys.meta_path.remove(self)
            spec = PathFinder.find_spec(name, path)
            run = spec.loader.exec_module

            def exec_module(module):
                run(module)
                module.set_num_threads(threads)

            spec.loader.exec_module = exec_module
            return spec

    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(threads)
    else:
        sys.meta_path.insert(0, SetTorchThreads())


_fnn_torch_threads(%d)
del _fnn_torch_threads
"""


def _kernel_arguments(threads: int) -> list[str]:
    """ipykernel options: torch's threads set when the notebook imports torch; the kernel's own log quiet.

    (The kernel's log goes to the terminal, not to the task's log: messages such as a reply that cannot be
    sent while Ctrl-C shuts it down. The notebook's output and errors still reach the task's log.)
    """
    return [f"--IPKernelApp.exec_lines={[_TORCH_THREADS_HOOK % int(threads)]!r}", "--IPKernelApp.log_level=CRITICAL"]


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
        Task -> sha256 over its notebook, parameters, upstream fingerprints,
        the library sources and (where it reads data) the data files' bytes;
        no absolute path enters it.
    missing_data : mapping of str to str
        Task -> why it cannot run here (its data files are missing); such a
        task and its dependants are "not run", the rest runs.
    """

    profile: str
    order: tuple[str, ...]
    selected: tuple[str, ...]
    parameters: Mapping[str, dict[str, Any]]
    fingerprints: Mapping[str, str]
    missing_data: Mapping[str, str] = dataclasses.field(default_factory=dict)


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
        """True when no task failed or was left out, other than for missing data (see the summary)."""
        return all(o.status in ("ok", "skipped") or (o.status == "not run" and "data missing" in o.message)
                   for o in self.outcomes)

    def outcome(self, task: str) -> TaskOutcome:
        """The outcome of ``task``."""
        for o in self.outcomes:
            if o.task == task:
                return o
        raise KeyError(task)


def staging_dir(spec: PipelineSpec, profile: str, task: str) -> Path:
    return spec.output_root / profile / ".staging" / task


def logs_dir(spec: PipelineSpec, profile: str) -> Path:
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


def _data_digest(data_dir: Path) -> str:
    """sha256 over the data files (relative names and bytes; README files left out), not the folder's path."""
    h = hashlib.sha256()
    for file in sorted(p for p in data_dir.rglob("*") if p.is_file()):
        rel = file.relative_to(data_dir)
        if file.name.lower().startswith("readme") or any(part.startswith(".") for part in rel.parts):
            continue
        h.update(rel.as_posix().encode() + b"\0" + file_sha256(file).encode() + b"\0")
    return h.hexdigest()


def _fingerprint(task: Task, params: Mapping[str, Any], upstream: Mapping[str, str], sources: str,
                 data: str | None) -> str:
    """sha256 over what a task's outputs depend on; paths (out_dir, upstream_dirs, data_dir) stay out."""
    h = hashlib.sha256()
    h.update(task.notebook.read_bytes())
    stable = {k: v for k, v in params.items() if k not in ("out_dir", "upstream_dirs", "data_dir")}
    h.update(json.dumps(stable, sort_keys=True, default=str).encode())
    h.update(json.dumps(dict(sorted(upstream.items()))).encode())
    h.update(sources.encode())
    if data is not None:
        h.update(b"data\0" + data.encode())
    return h.hexdigest()


def _known_claims(claims_file: Path) -> set[str] | None:
    if not claims_file.is_file():
        return None
    try:
        return {c.id for c in read_claims(claims_file)}
    except ValueError as exc:  # the registry is off its schema: say so before anything runs
        raise PipelineError(str(exc)) from exc


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
        On the first invalid task, parameter (name, type, or a value the
        notebook's checks in :func:`fnnbook.settings.check_notebook_settings` refuse, a grid upstream of a
        task that is not an aggregate step, a data file that is not the published one),
        claim ID or data folder. Missing data files are not an error: the
        plan lists them in ``missing_data``.
    """
    if profile not in spec.profiles:
        raise PipelineError(f"unknown profile {profile!r}; profiles: {', '.join(spec.profiles)}")
    selected = list(dict.fromkeys(tasks)) if tasks else list(spec.tasks)
    order = spec.closure(selected)
    claims = _known_claims(spec.claims_file)
    src = [Path(s) for s in sources] if sources is not None else [Path(fnnlib.__file__).resolve().parent]
    digest = _sources_digest(src)
    data = _data_digest(spec.data_dir) if spec.data_dir is not None and spec.data_dir.is_dir() else None
    parameters: dict[str, dict[str, Any]] = {}
    fingerprints: dict[str, str] = {}
    missing_data: dict[str, str] = {}
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
                                    out_dir=staging_dir(spec, profile, name))
        check_grid_upstream(spec, task, declared)
        reason = check_task_values(task, profile, params)
        if reason:
            missing_data[name] = reason
        parameters[name] = params
        fingerprints[name] = _fingerprint(task, params, {u: fingerprints[u] for u in task.upstream}, digest,
                                          data if "data_dir" in params else None)
    return Plan(profile=profile, order=tuple(order), selected=tuple(selected),
                parameters=parameters, fingerprints=fingerprints, missing_data=missing_data)


def _recover(spec: PipelineSpec, profile: str, task: str) -> None:
    """Put back an output folder left aside by an interrupted swap."""
    final = spec.output_dir(profile, task)
    old = staging_dir(spec, profile, task).with_name(f"{task}.old")
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


def product_files(products: Sequence[str], directory: Path) -> tuple[list[str], list[str]]:
    """The product files in ``directory`` and the products missing there: ``(files, missing)``.

    A product with a glob wildcard (``neural_ode_seed*.pt``: one file per seed, as many as the profile's seeds)
    stands for every file it matches, and is missing when it matches none.
    """
    files: list[str] = []
    missing: list[str] = []
    for product in products:
        if glob.has_magic(product):
            matches = sorted(p.relative_to(directory).as_posix() for p in directory.glob(product) if p.is_file())
            files += matches
            if not matches:
                missing.append(product)
        elif (directory / product).exists():
            files.append(product)
        else:
            missing.append(product)
    return files, missing


def is_up_to_date(spec: PipelineSpec, plan: Plan, task: str) -> bool:
    """Whether ``task``'s last good output is current.

    True when its output folder holds every product with the SHA-256
    recorded when it was made (a truncated or edited product is stale), was
    made with the plan's fingerprint, and from the upstream outputs that are
    there now (an upstream task rerun since, even with the same inputs, makes
    it stale).
    """
    out = spec.output_dir(plan.profile, task)
    stored = _stored(spec, plan.profile, task)
    if not stored or stored.get("fingerprint") != plan.fingerprints[task]:
        return False
    runs = {u: _stored(spec, plan.profile, u).get("run_id") for u in spec.tasks[task].upstream}
    if stored.get("upstream_runs") != runs:
        return False
    products = stored.get("products")
    files, missing = product_files(spec.tasks[task].products, out) if out.is_dir() else ([], ["*"])
    if not isinstance(products, dict) or missing or set(products) != set(files):
        return False
    return all((out / p).is_file() and file_sha256(out / p) == digest for p, digest in products.items())


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


def _point_to_final(executed: Path, staging: Path, final: Path, root: Path) -> None:
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


def kill_kernels() -> int:
    """End this process's notebook kernels (its ipykernel child processes); return how many."""
    kernels = [p for p in psutil.Process().children(recursive=True) if _is_kernel(p)]
    for proc in kernels:
        with contextlib.suppress(psutil.Error):
            proc.kill()
    psutil.wait_procs(kernels, timeout=5)
    return len(kernels)


def _is_kernel(proc: psutil.Process) -> bool:
    try:
        return "ipykernel" in " ".join(proc.cmdline())
    except psutil.Error:
        return False


def _kernel_config(folder: str) -> Any:
    """Kernels talk over IPC sockets in ``folder`` (no TCP port opened, no 'without encryption' warning)."""
    from traitlets.config import Config

    return Config({"KernelManager": {"transport": "ipc", "ip": str(Path(folder) / "kernel")}})


def execute(spec: PipelineSpec, plan: Plan, name: str, progress_bar: bool,
             threads: int = TASK_THREADS) -> tuple[float, str]:
    """Run one task's notebook into staging and swap it in.

    Returns the elapsed seconds and an error message ("" on success); a
    KeyboardInterrupt is re-raised after the failure is recorded.
    """
    task = spec.tasks[name]
    staging = staging_dir(spec, plan.profile, name)
    final = spec.output_dir(plan.profile, name)
    logs = logs_dir(spec, plan.profile)
    log = logs / f"{name}.log"
    failed_nb = logs / f"{name}.ipynb"
    executed = staging / f"{name}.ipynb"
    params = plan.parameters[name]

    _recover(spec, plan.profile, name)
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir(parents=True)
    logs.mkdir(parents=True, exist_ok=True)
    mark_killed(log, "the process running this attempt was killed")
    if log.exists():  # keep the killed attempt's log for reading
        log.replace(logs / f"{name}.previous.log")
    failed_nb.unlink(missing_ok=True)
    start = time.perf_counter()
    with open(log, "w", encoding="utf-8") as fh, tempfile.TemporaryDirectory(prefix="fnn-kernel-") as sockets:
        fh.write(f"task: {name}\nprofile: {plan.profile}\nnotebook: {task.notebook}\n"
                 f"torch threads: {threads}\n"
                 f"parameters: {json.dumps(params, sort_keys=True)}\n\n--- kernel output ---\n")
        fh.flush()
        try:
            papermill.execute_notebook(
                str(task.notebook), str(executed), parameters=params, kernel_name=KERNEL,
                cwd=str(spec.root), progress_bar=progress_bar, stdout_file=fh, stderr_file=fh,
                config=_kernel_config(sockets), extra_arguments=_kernel_arguments(threads),
            )
            products, missing = product_files(task.products, staging)
            if missing:
                raise PipelineError(f"the notebook finished but did not write these products: "
                                    f"{', '.join(missing)} (into out_dir)")
            _point_to_final(executed, staging, final, spec.root)
            record = {"fingerprint": plan.fingerprints[name], "task": name, "profile": plan.profile,
                      "parameters": {k: v for k, v in params.items() if k not in INJECTED or k == "profile"},
                      "run_id": uuid.uuid4().hex,
                      "upstream_runs": {u: _stored(spec, plan.profile, u).get("run_id")
                                        for u in task.upstream},
                      "products": {p: file_sha256(staging / p) for p in products}}
            (staging / FINGERPRINT_FILE).write_text(json.dumps(record, indent=2, sort_keys=True) + "\n",
                                                    encoding="utf-8")
            _swap(staging, final)
        except BaseException as exc:
            if not isinstance(exc, Exception):  # Ctrl-C: the kernel (in its own session) would outlive us
                kill_kernels()
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


def execute_task(spec: PipelineSpec, plan: Plan, name: str, threads: int,
                 *upstream: TaskOutcome) -> TaskOutcome:
    """Run one task unless an upstream outcome is not "ok"/"skipped"; the unit of work of an executor.

    Module-level and with picklable arguments, so a Dask worker runs it (the
    upstream outcomes are those tasks' results, passed in as dependencies).
    """
    out = spec.output_dir(plan.profile, name)
    for up in upstream:
        if up.status not in ("ok", "skipped"):
            return TaskOutcome(name, "not run", 0.0, out, message=f"upstream {up.task} {_past(up.status)}")
    seconds, error = execute(spec, plan, name, False, threads)
    log = logs_dir(spec, plan.profile) / f"{name}.log"
    if error:
        return TaskOutcome(name, "failed", seconds, out, log, error)
    return TaskOutcome(name, "ok", seconds, out, log)


def _past(status: str) -> str:
    return {"failed": "failed", "not run": "did not run"}.get(status, status)


def decide(spec: PipelineSpec, plan: Plan, *, force: bool = False) -> dict[str, str]:
    """For each task of the plan: "run", "skipped" (up to date) or "not run: <why>" (before any runs).

    A task runs when forced (selected tasks only), when an upstream task
    runs, or when it is not up to date; a task whose data are missing, or
    whose upstream task cannot run, does not run.
    """
    verdict: dict[str, str] = {}
    for name in plan.order:
        task = spec.tasks[name]
        blocked = [u for u in task.upstream if verdict[u].startswith("not run")]
        if name in plan.missing_data:
            verdict[name] = f"not run: {plan.missing_data[name]}"
        elif blocked:
            verdict[name] = f"not run: upstream {blocked[0]} did not run (data missing)"
        else:
            _recover(spec, plan.profile, name)
            stale = ((force and name in plan.selected) or any(verdict[u] == "run" for u in task.upstream)
                     or not is_up_to_date(spec, plan, name))
            verdict[name] = "run" if stale else "skipped"
    return verdict


def cpu_count() -> int:
    """Cores this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def task_threads(workers: int) -> int:
    """torch threads per task: cores // workers, at least 1."""
    return max(1, cpu_count() // workers)


def write_status(spec: PipelineSpec, report: RunReport) -> Path:
    """Record each task's last outcome in ``<output_root>/<profile>/_status.json`` (the book reads it)."""
    path = spec.output_root / report.profile / STATUS_FILE
    try:
        status = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        status = {}
    for o in report.outcomes:
        status[o.task] = {"status": o.status, "message": o.message}
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path, "w") as fh:
        fh.write(json.dumps(status, indent=2, sort_keys=True) + "\n")
    return path


def read_status(spec: PipelineSpec, profile: str) -> dict[str, dict[str, str]]:
    """The ``_status.json`` of a profile ({} if none)."""
    try:
        status = json.loads((spec.output_root / profile / STATUS_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return status if isinstance(status, dict) else {}


def summary(report: RunReport) -> str:
    """One line of counts, then one line per task that failed or did not run."""
    counts: dict[str, int] = {}
    for o in report.outcomes:
        counts[o.status] = counts.get(o.status, 0) + 1
    parts = [f"{counts[s]} {s}" for s in ("ok", "skipped", "failed", "not run") if counts.get(s)]
    lines = [f"profile {report.profile}: {', '.join(parts) or 'nothing to do'}"]
    for o in report.outcomes:
        if o.status == "failed":
            lines.append(f"  FAILED {o.task}: log {o.log}")
        elif o.status == "not run":
            lines.append(f"  NOT RUN {o.task}: {o.message}")
    return "\n".join(lines)
