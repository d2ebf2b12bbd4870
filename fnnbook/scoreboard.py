"""The scoreboard: every claim of ``CLAIMS.md`` with its measured verdict.

``CLAIMS.md`` lists claims in markdown tables, one ``## section`` per group,
rows like ``| S1 | claim text | Fig. 4c |``.  Each task's ``results.json``
(:mod:`fnnlib.results`) reports verdicts for some IDs; the rest are
shown as "not run".
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fnnlib.results import VERDICTS, claim_result, verdict_from_checks

__all__ = ["NOT_RUN", "SELF_CHECK_ID", "Claim", "ScoreRow", "read_claims", "render_scoreboard", "score_rows",
           "self_check"]

#: the claim the scoreboard reports on itself ("the scoreboard page, computed from the runs")
SELF_CHECK_ID = "B3"

NOT_RUN = "not run"
_ID_RE = re.compile(r"^[A-Z]+[0-9]+$")
_BADGE = {"reproduced": "success", "partly": "warning", "not reproduced": "danger", NOT_RUN: "secondary"}


@dataclass(frozen=True)
class Claim:
    """One row of a claims table.

    Attributes
    ----------
    id : str
        E.g. ``"S2"``.
    group : str
        The ``##`` section the table sits in.
    text : str
        The claim (second column).
    figure : str
        The paper's figure (third column, when its header names a figure).
    """

    id: str
    group: str
    text: str
    figure: str


@dataclass(frozen=True)
class ScoreRow:
    """A claim with the verdict measured for it (or "not run").

    ``task`` is the task that reported it (or declares it); ``result`` is
    the claim's entry of that task's ``results.json``, if any.
    """

    claim: Claim
    verdict: str
    task: str | None
    result: Mapping[str, Any] | None


def _cells(line: str) -> list[str]:
    body = line.strip()[1:]
    if body.endswith("|"):
        body = body[:-1]
    return [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", body)]


def read_claims(path: str | os.PathLike[str]) -> list[Claim]:
    """Parse every claim ID from the markdown tables of a claims file.

    Parameters
    ----------
    path : path-like
        The claims file (``CLAIMS.md``).

    Returns
    -------
    list of Claim
        In file order.

    Raises
    ------
    ValueError
        If an ID occurs twice.
    """
    claims: list[Claim] = []
    seen: set[str] = set()
    group = ""
    header: list[str] = []
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        stripped = line.strip()
        if stripped.startswith("#"):
            group = stripped.lstrip("#").strip()
            header = []
            continue
        if not stripped.startswith("|"):
            header = []
            continue
        cells = _cells(stripped)
        if not header:
            header = [c.lower() for c in cells]
            continue
        if not cells or not _ID_RE.match(cells[0]):
            continue  # separator row or a table without IDs
        if cells[0] in seen:
            raise ValueError(f"{path}: claim ID {cells[0]!r} appears twice")
        seen.add(cells[0])
        figure = cells[2] if len(cells) > 2 and len(header) > 2 and "figure" in header[2] else ""
        claims.append(Claim(id=cells[0], group=group, text=cells[1] if len(cells) > 1 else "",
                            figure=figure))
    return claims


def score_rows(
    claims: Sequence[Claim],
    results: Mapping[str, Mapping[str, Any]],
    declared: Mapping[str, Sequence[str]] | None = None,
) -> list[ScoreRow]:
    """Attach to each claim the verdict a task's results report for it.

    Parameters
    ----------
    claims : sequence of Claim
    results : mapping of str to dict
        Task name -> its ``results.json`` (tasks without outputs left out).
    declared : mapping of str to sequence of str, optional
        Task name -> claim IDs it declares; names the task of claims that
        have no result yet.

    Returns
    -------
    list of ScoreRow
        One per claim, in order; verdict :data:`NOT_RUN` where no result.
    """
    found: dict[str, tuple[str, Mapping[str, Any]]] = {}
    for task, data in results.items():
        for entry in data.get("claims", []):
            found.setdefault(entry["id"], (task, entry))
    owner = {cid: task for task, ids in (declared or {}).items() for cid in ids}
    rows = []
    for claim in claims:
        if claim.id in found:
            task, entry = found[claim.id]
            verdict = entry.get("verdict", NOT_RUN)
            rows.append(ScoreRow(claim, verdict if verdict in VERDICTS else NOT_RUN, task, entry))
        else:
            rows.append(ScoreRow(claim, NOT_RUN, owner.get(claim.id), None))
    return rows


def _number(value: Any) -> str:
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, float):
        return f"{value:.3g}"
    if isinstance(value, (list, tuple)):
        shown = ", ".join(_number(v) for v in value[:4])
        return f"[{shown}, ...] (n={len(value)})" if len(value) > 4 else f"[{shown}]"
    if isinstance(value, Mapping):
        shown = ", ".join(f"{k}: {_number(v)}" for k, v in list(value.items())[:4])
        return f"{{{shown}, ...}}" if len(value) > 4 else f"{{{shown}}}"
    return str(value)


def _cell(text: str) -> str:
    """Make text safe inside a markdown table cell."""
    return text.replace("\n", " ").replace("|", "\\|")


def _code(text: str) -> str:
    return "`" + text.replace("`", "'") + "`" if text else ""


def render_scoreboard(
    rows: Sequence[ScoreRow],
    *,
    profile: str,
    pages: Mapping[str, str],
    figures: Mapping[str, str] | None = None,
    notes: Mapping[str, str] | None = None,
) -> str:
    """Render the scoreboard page as MyST markdown.

    Parameters
    ----------
    rows : sequence of ScoreRow
    profile : str
        The profile whose results are shown.
    pages : mapping of str to str
        Task -> link target of its book page (relative to the scoreboard).
    figures : mapping of str to str, optional
        Task -> folder (relative to the scoreboard) where its output's
        ``figure`` paths resolve.
    notes : mapping of str to str, optional
        Task -> why it has no results (e.g. "not run: data missing ..."),
        shown for its claims.

    Returns
    -------
    str
    """
    figures = figures or {}
    counts = {v: sum(r.verdict == v for r in rows) for v in (*VERDICTS, NOT_RUN)}
    out = [
        "# Scoreboard",
        "",
        f"Profile **{profile}**: {len(rows)} claims, "
        + ", ".join(f"{counts[v]} {v}" for v in (*VERDICTS, NOT_RUN)) + ".",
        "",
    ]
    if profile != "paper":
        out += [":::{warning}",
                f"These numbers come from the `{profile}` profile, not the paper's settings; "
                "the verdicts say whether the code runs end to end, not whether the paper's "
                "claims hold.", ":::", ""]
    out += [
        "Each verdict is computed from the measured numbers by the rule shown: "
        "*reproduced* when every check holds, *partly* when some do, *not reproduced* when none "
        "does; *not run* when no task has produced a result for the claim.",
        "",
    ]
    group = None
    for row in rows:
        if row.claim.group != group:
            group = row.claim.group
            out += ["", f"## {group}", "",
                    "| ID | claim | paper | verdict | measured | rule | where |",
                    "|---|---|---|---|---|---|---|"]
        entry = row.result or {}
        numbers = "; ".join(f"{k} = {_number(v)}" for k, v in (entry.get("numbers") or {}).items())
        checks = "; ".join(f"{'✓' if ok else '✗'} {k}" for k, ok in (entry.get("checks") or {}).items())
        measured = "<br>".join(_code(s) for s in (numbers, checks) if s)
        if row.result is None and row.task in (notes or {}):
            measured = notes[row.task]
        where = []
        if row.task is not None and row.task in pages:
            where.append(f"[{row.task}]({pages[row.task]})")
        fig = entry.get("figure")
        if fig and row.task in figures:
            where.append(f"[figure]({figures[row.task]}/{fig})")
        out.append("| " + " | ".join(_cell(c) for c in (
            f"**{row.claim.id}**", row.claim.text, row.claim.figure,
            f"{{bdg-{_BADGE[row.verdict]}}}`{row.verdict}`", measured, entry.get("rule", ""),
            " ".join(where))) + " |")
    return "\n".join(out) + "\n"


def self_check(claims: Sequence[Claim], results: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """The scoreboard's own claim (B3): it is computed from the runs.

    Checks: at least one task has results; every claim a result reports is
    an ID of the claims file; every reported verdict is the one its checks
    imply (no verdict set by hand).
    """
    ids = {c.id for c in claims}
    entries = [e for data in results.values() for e in data.get("claims", [])]
    unknown = sorted({e["id"] for e in entries} - ids)
    mismatched = sorted(e["id"] for e in entries
                        if not e.get("checks") or verdict_from_checks(e["checks"]) != e.get("verdict"))
    return claim_result(
        SELF_CHECK_ID,
        checks={"results_found": bool(results), "ids_known": not unknown, "verdicts_follow_checks": not mismatched},
        numbers={"tasks_with_results": len(results), "claims_reported": len(entries), "claims_listed": len(ids),
                 "unknown_ids": unknown, "verdicts_not_from_checks": mismatched},
        rule="some task has results; every reported ID is in the claims file; every verdict equals the one "
             "its checks imply",
    )
