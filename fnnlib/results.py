"""Claim verdicts and the per-task results JSON read by the scoreboard.

A notebook decomposes each claim of ``CLAIMS.md`` into named boolean checks,
each computed from measured numbers by a rule stated in the notebook.  The
verdict is derived from the checks alone, never set by hand:

* ``"reproduced"``      every check holds,
* ``"partly"``          some but not all checks hold,
* ``"not reproduced"``  no check holds.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from fnnlib.io import atomic_write

VERDICTS = ("reproduced", "partly", "not reproduced")
RESULTS_FILENAME = "results.json"


def verdict_from_checks(checks: Mapping[str, bool]) -> str:
    """Return the verdict implied by a mapping of named boolean checks."""
    if not checks:
        raise ValueError("a claim needs at least one check to have a verdict")
    values = [bool(v) for v in checks.values()]
    if all(values):
        return VERDICTS[0]
    if any(values):
        return VERDICTS[1]
    return VERDICTS[2]


def _plain(value: Any) -> Any:
    """Convert numpy/torch scalars and arrays to JSON-friendly Python values."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)  # JSON has no NaN/inf; keep it visible as text
    return value


def claim_result(
    claim_id: str,
    *,
    checks: Mapping[str, bool],
    numbers: Mapping[str, Any],
    rule: str,
    figure: str | None = None,
) -> dict[str, Any]:
    """Bundle one claim's measured numbers, checks and derived verdict.

    Parameters
    ----------
    claim_id : str
        The ID in ``CLAIMS.md``, e.g. ``"S2"``.
    checks : mapping of str to bool
        Named sub-checks, each computed from ``numbers``.
    numbers : mapping
        The measured numbers the checks use (scalars or short lists).
    rule : str
        The rule, in words, that turns ``numbers`` into ``checks``.
    figure : str, optional
        Path of the figure that shows the claim, relative to the task's
        output directory (e.g. ``"figures/fig4f_multistep.png"``).
    """
    return {
        "id": claim_id,
        "verdict": verdict_from_checks(checks),
        "rule": rule,
        "checks": {k: bool(v) for k, v in checks.items()},
        "numbers": _plain(dict(numbers)),
        "figure": figure,
    }


def write_results(
    out_dir: str | os.PathLike[str],
    *,
    task: str,
    profile: str,
    claims: Sequence[Mapping[str, Any]],
    metrics: Mapping[str, Any] | None = None,
) -> Path:
    """Write ``results.json`` for one task atomically (temp file + rename).

    Returns the path written.
    """
    ids = [c["id"] for c in claims]
    if len(ids) != len(set(ids)):
        raise ValueError(f"duplicate claim IDs in results: {ids}")
    payload = {
        "task": task,
        "profile": profile,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "claims": [_plain(dict(c)) for c in claims],
        "metrics": _plain(dict(metrics or {})),
    }
    path = Path(out_dir) / RESULTS_FILENAME
    with atomic_write(path, "w") as fh:
        json.dump(payload, fh, indent=2, sort_keys=False)
        fh.write("\n")
    return path


def read_results(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read and minimally validate a results JSON written by :func:`write_results`."""
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise
    except (OSError, ValueError) as exc:
        raise ValueError(f"results file {p} is not valid JSON: {exc}") from exc
    for key in ("task", "profile", "claims"):
        if key not in data:
            raise ValueError(f"results file {p} lacks the key {key!r}")
    for c in data["claims"]:
        if c.get("verdict") not in VERDICTS:
            raise ValueError(f"results file {p}: claim {c.get('id')!r} has verdict {c.get('verdict')!r}")
    return data
