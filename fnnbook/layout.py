"""The output layout under ``<output_root>/<profile>/``, the atomic swap of a task's outputs, logs, status.

::

    <task>/                 last good outputs (products, <task>.ipynb, .fingerprint.json)
    .staging/<task>/        the run in progress; swapped in only on success
    _logs/<task>.log        log of the last attempt (kernel output, error)
    _logs/<task>.ipynb      the executed notebook of a failed attempt
    _status.json            how each task of the last run fared (read by the book)
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Any

from fnnbook.outcome import RunReport
from fnnbook.spec import PipelineSpec
from fnnlib.io import atomic_write

__all__ = ["STATUS_FILE", "logs_dir", "mark_killed", "point_to_final", "read_status", "recover", "staging_dir",
           "swap", "write_status"]

STATUS_FILE = "_status.json"
_END_MARKERS = ("\n--- ok after ", "\n--- FAILED")


def staging_dir(spec: PipelineSpec, profile: str, task: str) -> Path:
    return spec.output_root / profile / ".staging" / task


def logs_dir(spec: PipelineSpec, profile: str) -> Path:
    return spec.output_root / profile / "_logs"



def recover(spec: PipelineSpec, profile: str, task: str) -> None:
    """Put back an output folder left aside by an interrupted swap."""
    final = spec.output_dir(profile, task)
    old = staging_dir(spec, profile, task).with_name(f"{task}.old")
    if old.is_dir():
        if final.exists():
            shutil.rmtree(old)
        else:
            os.rename(old, final)



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
    """Record each task's last outcome in ``<output_root>/<profile>/_status.json`` (the book reads it)."""
    path = spec.output_root / report.profile / STATUS_FILE
    try:
        status = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        status = {}
    for o in report.outcomes:
        status[o.task] = {"status": str(o.status), "message": o.message}
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

