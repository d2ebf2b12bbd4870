"""Claim verdicts and the per-task results JSON read by the scoreboard.

A notebook decomposes each claim of the registry (``claims.yaml``) into named boolean checks,
each computed from measured numbers by a rule stated in the notebook.  The
verdict is derived from the checks alone, never set by hand:

* ``"reproduced"``      every check holds,
* ``"partly"``          some but not all checks hold,
* ``"not reproduced"``  no check holds.

Besides its ``checks``, a claim may carry:

* ``guarantees``: named booleans that hold by construction, by a theorem
  with constants measured on the same run, or by self-consistency (frozen
  weights, bookkeeping).  They never count toward the verdict, and a false
  one stops the notebook (:class:`GuaranteeFailed`);
* ``headline``: the one number a reader looks for first,
  ``{"name", "value", "unit"}`` plus ``"spread"``, ``"n"`` and
  ``"per_seed"`` when it is measured over seeds (:func:`headline_number`);
* ``paper``: the paper's number or statement it is compared with;
* ``title``: the claim in a few words.

All four are optional: a result without them reads as before, and the
scoreboard falls back on the claims file and the numbers.
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


class GuaranteeFailed(AssertionError):
    """A guarantee of a claim (something that must hold by construction) is false."""


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


def headline_number(name: str, value: float | Sequence[float], *, unit: str = "") -> dict[str, Any]:
    """The headline number of a claim, as the scoreboard shows it.

    Parameters
    ----------
    name : str
        What the number is, in a few words (e.g. ``"N=50 error, feedback / neural ODE"``).
    value : float or sequence of float
        One measured value, or one value per seed.  Per-seed values are
        reported as their mean, with the sample standard deviation
        (``ddof=1``) as ``spread`` and the count as ``n``.
    unit : str
        E.g. ``"cm"``; empty for a ratio.

    Raises
    ------
    ValueError
        If ``name`` is empty or ``value`` is an empty sequence.
    """
    if not name:
        raise ValueError("a headline needs a name")
    out: dict[str, Any] = {"name": name}
    values = _plain(value)
    if isinstance(values, list):
        if not values:
            raise ValueError(f"headline {name!r}: no per-seed values")
        values = [float(v) for v in values]
        n = len(values)
        mean = math.fsum(values) / n
        out["value"] = mean
        out["spread"] = math.sqrt(math.fsum((v - mean) ** 2 for v in values) / (n - 1)) if n > 1 else 0.0
        out["n"] = n
        out["per_seed"] = values
    else:
        out["value"] = float(values)
    out["unit"] = unit
    return _plain(out)


def claim_result(
    claim_id: str,
    *,
    checks: Mapping[str, bool],
    numbers: Mapping[str, Any],
    rule: str,
    figure: str | None = None,
    guarantees: Mapping[str, bool] | None = None,
    headline: Mapping[str, Any] | None = None,
    paper: str | None = None,
    title: str | None = None,
) -> dict[str, Any]:
    """Bundle one claim's measured numbers, checks and derived verdict.

    Parameters
    ----------
    claim_id : str
        The ID in the claims registry (``claims.yaml``), e.g. ``"S2"``.
    checks : mapping of str to bool
        Named sub-checks, each computed from ``numbers``.
    numbers : mapping
        The measured numbers the checks use (scalars or short lists).
    rule : str
        The rule, in words, that turns ``numbers`` into ``checks``.
    figure : str, optional
        Path of the figure that shows the claim, relative to the task's
        output directory (e.g. ``"figures/fig4f_multistep.png"``).
    guarantees : mapping of str to bool, optional
        What holds by construction or self-consistency; shown apart from
        ``checks`` and never counted toward the verdict.
    headline : mapping, optional
        The claim's headline number, as made by :func:`headline_number`.
    paper : str, optional
        The paper's number or statement for this claim.
    title : str, optional
        The claim in a few words.

    Raises
    ------
    GuaranteeFailed
        If a guarantee is false: something that must hold does not, so the
        run itself is wrong and no verdict is written.
    ValueError
        If ``checks`` is empty, or ``headline`` lacks a name or a value.
    """
    result: dict[str, Any] = {
        "id": claim_id,
        "verdict": verdict_from_checks(checks),
        "rule": rule,
        "checks": {k: bool(v) for k, v in checks.items()},
        "numbers": _plain(dict(numbers)),
        "figure": figure,
    }
    # optional fields are written only when given, so older results stay byte for byte the same
    if guarantees is not None:
        failed = [k for k, v in guarantees.items() if not bool(v)]
        if failed:
            raise GuaranteeFailed(f"claim {claim_id}: guarantee(s) {', '.join(failed)} do not hold")
        result["guarantees"] = {k: True for k in guarantees}
    if headline is not None:
        missing = [k for k in ("name", "value") if k not in headline]
        if missing:
            raise ValueError(f"claim {claim_id}: headline lacks {', '.join(missing)}")
        result["headline"] = _plain(dict(headline))
    if paper is not None:
        result["paper"] = paper
    if title is not None:
        result["title"] = title
    return result


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
        if not all((c.get("guarantees") or {}).values()):
            raise ValueError(f"results file {p}: claim {c.get('id')!r} has a failed guarantee")
    return data
