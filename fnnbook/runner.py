"""Check the tasks and decide which must run; the face of the runner's modules.

Layout, swap, logs and status: :mod:`fnnbook.layout`; fingerprints and skipping: :mod:`fnnbook.fingerprint`;
kernels: :mod:`fnnbook.kernel`; one task's execution: :mod:`fnnbook.execution`; outcomes as types:
:mod:`fnnbook.outcome`. Tasks execute one after another in this process (``workers=1``) or on a Dask cluster
(:mod:`fnnbook.executor`); the checks, fingerprints, skipping and the atomic swap of outputs are the same
either way.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from fnnbook.execution import execute, execute_task
from fnnbook.fingerprint import (NO_EARLIER_RUN, data_inputs, environment, fingerprint, imported_modules, inputs_of, is_up_to_date,
                                 notebook_code, package_roots, product_files, stale_reason, stored)
from fnnbook.kernel import KERNEL, TASK_THREADS, cpu_count, kill_kernels, task_threads
from fnnbook.layout import STATUS_FILE, logs_dir, mark_killed, read_status, staging_dir, write_status
from fnnbook.outcome import Action, Decision, RunReport, Status, TaskOutcome, blocked, blocked_by, summary
from fnnbook.params import FINGERPRINT_FILE, check_task_parameters, read_parameters, resolve_parameters
from fnnbook.plan import Plan, run_name
from fnnbook.preflight import check_grid_upstream, check_task_values
from fnnbook.scoreboard import read_claims
from fnnbook.spec import PipelineError, PipelineSpec, Task
from fnnlib.release import release_files

__all__ = ["FINGERPRINT_FILE", "KERNEL", "STATUS_FILE", "TASK_THREADS", "Action", "Decision", "Plan",
           "RunReport", "Status", "TaskOutcome", "check", "cpu_count", "decide", "execute", "execute_task",
           "is_up_to_date", "kill_kernels", "stale_reason", "logs_dir", "mark_killed", "product_files", "read_status",
           "staging_dir", "summary", "task_threads", "write_status"]


def _known_claims(claims_file: Path) -> set[str] | None:
    if not claims_file.is_file():
        return None
    try:
        return set(_claim_ids(str(claims_file), claims_file.read_bytes()))
    except ValueError as exc:  # the registry is off its schema: say so before anything runs
        raise PipelineError(str(exc)) from exc


@functools.lru_cache(maxsize=8)
def _claim_ids(path: str, content: bytes) -> frozenset[str]:
    """The claim IDs of a registry, parsed again when its content changes (the cache key): parsing the YAML
    costs ~0.06 s, and a run checks it at every call."""
    return frozenset(c.id for c in read_claims(path, content.decode("utf-8")))


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
        Package folders whose modules a notebook imports enter its fingerprint (each module it imports,
        transitively).  Default: the installed ``fnnlib`` and ``fnnbook`` packages.

    Returns
    -------
    Plan

    Raises
    ------
    PipelineError
        On the first invalid task, parameter (name, type, or a value the
        notebook's settings dataclass in :mod:`fnnbook.tasks` refuses, a grid upstream of a
        task that is not an aggregate step, a data file that is not the published one),
        claim ID or data folder. Missing data files are not an error: the
        plan lists them in ``missing_data``.
    """
    if profile not in spec.profiles:
        raise PipelineError(f"unknown profile {profile!r}; profiles: {', '.join(spec.profiles)}")
    spec = spec.for_profile(profile)
    selected = list(dict.fromkeys(tasks)) if tasks else spec.declares(profile)
    order = spec.closure(selected)
    claims = _known_claims(spec.claims_file)
    roots = package_roots([Path(s) for s in sources] if sources is not None else None)
    env = environment()
    code: dict[Path, dict[str, str]] = {}
    data: dict[tuple[str, ...], dict[str, str]] = {}
    run = run_name()
    parameters: dict[str, dict[str, Any]] = {}
    fingerprints: dict[str, str] = {}
    inputs: dict[str, dict[str, Any]] = {}
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
                                    out_dir=staging_dir(spec, profile, name, run))
        check_grid_upstream(spec, task, declared)
        reason = check_task_values(task, profile, params)
        if reason:
            missing_data[name] = reason
        parameters[name] = params
        if task.notebook not in code:
            code[task.notebook] = imported_modules(notebook_code(task.notebook), roots)
        _check_release(spec, task, params)
        reads = None
        if "data_dir" in params and spec.data_dir is not None and spec.data_dir.is_dir():
            if task.data not in data:
                data[task.data] = data_inputs(spec.data_dir, task.data)
            reads = data[task.data]
        inputs[name] = inputs_of(task, params, {u: fingerprints[u] for u in task.upstream}, code[task.notebook],
                                 env, reads)
        fingerprints[name] = fingerprint(inputs[name])
    return Plan(profile=profile, order=tuple(order), selected=tuple(selected), parameters=parameters,
                fingerprints=fingerprints, missing_data=missing_data, run=run, inputs=inputs)


def _check_release(spec: PipelineSpec, task: Task, params: Mapping[str, Any]) -> None:
    """A release file the task reads that is there with another SHA-256 than the published one: an error now, not
    inside the notebook (a missing file is no error: the task then judges our networks only)."""
    if "data_dir" not in params or spec.data_dir is None:
        return
    for entry in task.data:
        if not (entry == "release" or entry.startswith("release/")):
            continue
        under = entry.removeprefix("release").lstrip("/")
        changed = [k for k, v in release_files(spec.data_dir, under).items() if v == "changed"]
        if changed:
            raise PipelineError(f"task {task.name!r}: {spec.data_dir / 'release' / changed[0]} fails its SHA-256 "
                                f"check ({len(changed)} file(s) so): it is not the authors' published file; fetch "
                                "it again (fnn-pipeline data fetch --release) or remove it")


def decide(spec: PipelineSpec, plan: Plan, *, force: bool = False) -> dict[str, Decision]:
    """For each task of the plan, what the run does with it (before any runs): a :class:`Decision`.

    A task runs when forced (selected tasks only), when an upstream task
    runs, or when it is not up to date (an output folder a cut-short swap
    set aside counts as missing until its writer puts it back); a task whose
    data are missing, or whose upstream task cannot run, does not run.
    """
    spec = spec.for_profile(plan.profile)
    verdict: dict[str, Decision] = {}
    for name in plan.order:
        task = spec.tasks[name]
        if name in plan.missing_data:
            verdict[name] = Decision(Action.NOT_RUN, plan.missing_data[name], data_missing=True)
        elif (up := blocked_by(task, verdict)) is not None:
            o = blocked(name, spec.output_dir(plan.profile, name), up, verdict)
            verdict[name] = Decision(Action.NOT_RUN, o.message, data_missing=o.data_missing)
        else:
            ran = [u for u in task.upstream if verdict[u].action is Action.RUN]
            if force and name in plan.selected:
                why: str | None = "forced"
            elif not stored(spec, plan.profile, name):
                why = NO_EARLIER_RUN
            elif ran:
                why = f"upstream: {', '.join(ran[:3])}{' and more' if len(ran) > 3 else ''} reruns"
            else:
                why = stale_reason(spec, plan, name)
            verdict[name] = Decision(Action.SKIP) if why is None else Decision(Action.RUN, why)
    return verdict
