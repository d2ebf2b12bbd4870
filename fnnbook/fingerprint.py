"""Fingerprints: what a task's outputs depend on, and whether its last good outputs are current.

A fingerprint is a SHA-256 over the notebook, its parameters (no paths), the upstream fingerprints, the
library sources and, where the task reads data, the data files' bytes. The run record beside the outputs
(``.fingerprint.json``) holds it with the SHA-256 of every product.
"""

from __future__ import annotations

import glob
import hashlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fnnbook.params import FINGERPRINT_FILE
from fnnbook.spec import PipelineSpec, Task
from fnnlib.io import file_sha256

if TYPE_CHECKING:
    from fnnbook.runner import Plan

__all__ = ["data_digest", "fingerprint", "is_up_to_date", "product_files", "sources_digest", "stored"]


def sources_digest(sources: Sequence[Path]) -> str:
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


def data_digest(data_dir: Path) -> str:
    """sha256 over the data files (relative names and bytes; README files left out), not the folder's path."""
    h = hashlib.sha256()
    for file in sorted(p for p in data_dir.rglob("*") if p.is_file()):
        rel = file.relative_to(data_dir)
        if file.name.lower().startswith("readme") or any(part.startswith(".") for part in rel.parts):
            continue
        h.update(rel.as_posix().encode() + b"\0" + file_sha256(file).encode() + b"\0")
    return h.hexdigest()


def fingerprint(task: Task, params: Mapping[str, Any], upstream: Mapping[str, str], sources: str,
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


def stored(spec: PipelineSpec, profile: str, task: str) -> dict[str, Any]:
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
    record = stored(spec, plan.profile, task)
    if not record or record.get("fingerprint") != plan.fingerprints[task]:
        return False
    runs = {u: stored(spec, plan.profile, u).get("run_id") for u in spec.tasks[task].upstream}
    if record.get("upstream_runs") != runs:
        return False
    products = record.get("products")
    files, missing = product_files(spec.tasks[task].products, out) if out.is_dir() else ([], ["*"])
    if not isinstance(products, dict) or missing or set(products) != set(files):
        return False
    return all((out / p).is_file() and file_sha256(out / p) == digest for p, digest in products.items())
