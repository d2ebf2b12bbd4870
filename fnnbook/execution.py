"""One task's execution: its notebook run by papermill into staging, its run record, the swap; its outcome."""

from __future__ import annotations

import json
import shutil
import tempfile
import time
import traceback
import uuid
from typing import TYPE_CHECKING

import papermill

from fnnbook.fingerprint import product_files, stored
from fnnbook.kernel import KERNEL, TASK_THREADS, kernel_arguments, kernel_config, kill_kernels
from fnnbook.layout import logs_dir, mark_killed, point_to_final, recover, staging_dir, swap
from fnnbook.outcome import Status, TaskOutcome, blocked, blocked_by
from fnnbook.params import FINGERPRINT_FILE, INJECTED
from fnnbook.spec import PipelineError, PipelineSpec
from fnnlib.io import file_sha256

if TYPE_CHECKING:
    from fnnbook.runner import Plan

__all__ = ["execute", "execute_task"]


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

    recover(spec, plan.profile, name)
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
                config=kernel_config(sockets), extra_arguments=kernel_arguments(threads),
            )
            products, missing = product_files(task.products, staging)
            if missing:
                raise PipelineError(f"the notebook finished but did not write these products: "
                                    f"{', '.join(missing)} (into out_dir)")
            point_to_final(executed, staging, final, spec.root)
            record = {"fingerprint": plan.fingerprints[name], "task": name, "profile": plan.profile,
                      "parameters": {k: v for k, v in params.items() if k not in INJECTED or k == "profile"},
                      "run_id": uuid.uuid4().hex,
                      "upstream_runs": {u: stored(spec, plan.profile, u).get("run_id")
                                        for u in task.upstream},
                      "products": {p: file_sha256(staging / p) for p in products}}
            (staging / FINGERPRINT_FILE).write_text(json.dumps(record, indent=2, sort_keys=True) + "\n",
                                                    encoding="utf-8")
            swap(staging, final)
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
    """Run one task unless an upstream outcome stops it; the unit of work of an executor.

    Module-level and with picklable arguments, so a Dask worker runs it (the
    upstream outcomes are those tasks' results, passed in as dependencies).
    """
    out = spec.output_dir(plan.profile, name)
    known = {up.task: up for up in upstream}
    if (up := blocked_by(spec.tasks[name], known)) is not None:
        return blocked(name, out, up, known)
    seconds, error = execute(spec, plan, name, False, threads)
    log = logs_dir(spec, plan.profile) / f"{name}.log"
    if error:
        return TaskOutcome(name, Status.FAILED, seconds, out, log, error)
    return TaskOutcome(name, Status.OK, seconds, out, log)
