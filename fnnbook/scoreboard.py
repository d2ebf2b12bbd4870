"""The scoreboard: every claim of the registry (``claims.yaml``) with its measured verdict.

The registry lists the claims by group, each with the paper's statement (paraphrased), where the paper makes
it, its settings and the task that judges it (:func:`read_claims`).  Each task's ``results.json``
(:mod:`fnnlib.results`) reports verdicts for some IDs; the rest are shown as "not run".
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from fnnlib.results import VERDICTS, GuaranteeFailed, claim_result, headline_number, verdict_from_checks

__all__ = ["NOT_RUN", "SEEDS_CHECK_ID", "SELF_CHECK_ID", "Claim", "ScoreRow", "headline_of", "plot_verdicts", "read_claims",
           "render_scoreboard", "score_rows", "seeds_check", "self_check", "short_title", "verdict_counts"]

#: the claim the scoreboard reports on itself ("the scoreboard page, computed from the runs")
SELF_CHECK_ID = "B3"
SEEDS_CHECK_ID = "B2"

NOT_RUN = "not run"
_ID_RE = re.compile(r"^[A-Z]+[0-9]+$")
_BADGE = {"reproduced": "success", "partly": "warning", "not reproduced": "danger", NOT_RUN: "secondary"}


@dataclass(frozen=True)
class Claim:
    """One claim of the registry.

    Attributes
    ----------
    id : str
        E.g. ``"S2"``.
    group : str
        The group (scoreboard section) the claim belongs to.
    text : str
        The paper's statement, paraphrased.
    figure : str
        The paper's figure ("" where the registry says ``none ...``: the paper has no figure for it).
    section : str
        Where the paper makes the claim (section, appendix).
    settings : str
        The paper's settings for it (the group's, then the claim's own).
    task : str
        The pipeline task that judges it (``"scoreboard"``: computed by the book).
    notebook : str
        That task's notebook source ("" when none).
    """

    id: str
    group: str
    text: str
    figure: str
    section: str = ""
    settings: str = ""
    task: str = ""
    notebook: str = ""


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


#: fields every claim of the registry must give (non-empty); ``settings`` and ``notebook`` are optional
CLAIM_FIELDS = ("id", "statement", "section", "figure", "task")
_OPTIONAL_FIELDS = ("settings", "notebook")


def _text(value: Any, where: str, name: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"{where}: {name!r} must be a non-empty string, got {value!r}")
    return " ".join(value.split())


def _claim(entry: Any, group: str, group_settings: str, where: str) -> Claim:
    if not isinstance(entry, Mapping):
        raise ValueError(f"{where}: a claim must be a mapping, got {entry!r}")
    unknown = sorted(set(entry) - set(CLAIM_FIELDS) - set(_OPTIONAL_FIELDS))
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {unknown}; a claim has {CLAIM_FIELDS + _OPTIONAL_FIELDS}")
    values = {name: _text(entry.get(name), where, name) for name in CLAIM_FIELDS}
    if not _ID_RE.match(values["id"]):
        raise ValueError(f"{where}: claim ID {values['id']!r} is not letters followed by a number")
    own = _text(entry["settings"], where, "settings") if "settings" in entry else ""
    figure = "" if values["figure"].lower().startswith("none") else values["figure"]
    return Claim(id=values["id"], group=group, text=values["statement"], figure=figure,
                 section=values["section"], settings=" ".join(p for p in (group_settings, own) if p),
                 task=values["task"],
                 notebook=_text(entry["notebook"], where, "notebook") if "notebook" in entry else "")


def read_claims(path: str | os.PathLike[str]) -> list[Claim]:
    """Read every claim of a claims registry (YAML, see ``claims.yaml`` at the repository root).

    The file holds ``groups:``, a list (possibly empty) of ``{name, settings, claims}``; each claim gives ``id``,
    ``statement``, ``section``, ``figure`` and ``task`` (all non-empty), optionally ``settings`` and
    ``notebook``.

    Parameters
    ----------
    path : path-like
        The registry.

    Returns
    -------
    list of Claim
        In file order.

    Raises
    ------
    ValueError
        If the file does not follow the schema, a required field is empty, or an ID occurs twice.
    """
    where = str(path)
    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise ValueError(f"{where}: not a YAML claims registry: {exc}") from exc
    groups = data.get("groups") if isinstance(data, Mapping) else None
    if not isinstance(groups, list):
        raise ValueError(f"{where}: expected a list under 'groups'")
    claims: list[Claim] = []
    seen: set[str] = set()
    for i, group in enumerate(groups):
        if not isinstance(group, Mapping) or not isinstance(group.get("claims"), list):
            raise ValueError(f"{where}: group {i} must be a mapping with a list under 'claims'")
        name = _text(group.get("name"), f"{where}: group {i}", "name")
        settings = _text(group.get("settings"), f"{where}: group {name!r}", "settings")
        for j, entry in enumerate(group["claims"]):
            claim = _claim(entry, name, settings, f"{where}: group {name!r}, claim {j}")
            if claim.id in seen:
                raise ValueError(f"{where}: claim ID {claim.id!r} appears twice")
            seen.add(claim.id)
            claims.append(claim)
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


def _inline(text: str) -> str:
    """Make text safe as inline markdown on one line (no markup taken from it)."""
    text = " ".join(str(text).split())
    for ch in "\\`*_[]{}<>|$":
        text = text.replace(ch, "\\" + ch)
    return text


def short_title(text: str, words: int = 9) -> str:
    """The claim in a few words: its first clause, cut to ``words`` words."""
    head = re.split(r"[;:]\s", text, maxsplit=1)[0].strip()
    parts = head.split()
    return " ".join(parts[:words]) + (" …" if len(parts) > words else "") if parts else ""


def headline_of(entry: Mapping[str, Any]) -> tuple[str, str]:
    """The headline number of a result as ``(name, "value ± spread unit (n = k seeds)")``.

    Uses the result's ``headline`` (see :func:`fnnlib.results.headline_number`).
    A result without one (written before the field existed) shows how many
    of its checks hold instead of guessing a number from ``numbers``;
    ``("", "")`` when there is no result.
    """
    head = entry.get("headline")
    if head:
        text = _number(head.get("value"))
        if head.get("spread") is not None:
            text += f" ± {_number(head['spread'])}"
        if head.get("unit"):
            text += f" {head['unit']}"
        if head.get("n"):
            text += f" (n = {head['n']} seeds)"
        return str(head.get("name", "")), text
    checks = entry.get("checks") or {}
    if checks:
        return "checks holding", f"{sum(bool(v) for v in checks.values())} of {len(checks)}"
    return "", ""


def _bullets(marks: Mapping[str, bool]) -> list[str]:
    return [f"- {'✓' if ok else '✗'} `{str(k).replace('`', chr(39))}`" for k, ok in marks.items()]


def _details(row: ScoreRow, figure: str | None) -> list[str]:
    """The folded body of a row: the paper's claim, rule, checks, guarantees, numbers, figure."""
    entry = row.result or {}
    out = [f"**Claim ({row.claim.figure or 'paper'}).** {_inline(row.claim.text)}", ""]
    if not entry:
        return out + ["No task has produced a result for this claim yet.", ""]
    if entry.get("rule"):
        out += [f"**Rule.** {_inline(entry['rule'])}", ""]
    out += ["**Checks** (they decide the verdict):", "", *_bullets(entry.get("checks") or {}), ""]
    guarantees = entry.get("guarantees") or {}
    if guarantees:
        out += ["**Guarantees** (hold by construction or by a theorem on the same run; asserted while the "
                "notebook runs, never counted toward the verdict):", "", *_bullets(guarantees), ""]
    numbers = entry.get("numbers") or {}
    if numbers:
        out += ["**Numbers.**", "", "| name | value |", "|---|---|"]
        out += [f"| `{str(k).replace('`', chr(39))}` | {_inline(_number(v))} |" for k, v in numbers.items()]
        out.append("")
    if figure:
        out += [f"({_figure_label(row)})=", f"```{{image}} {figure}", f":alt: figure of claim {row.claim.id}",
                ":width: 100%", "```", ""]
    return out


def _figure_label(row: ScoreRow) -> str:
    return f"claim-{row.claim.id.lower()}-figure"


def verdict_counts(rows: Sequence[ScoreRow]) -> dict[str, dict[str, int]]:
    """Group -> verdict -> number of claims, groups in order of first appearance."""
    counts: dict[str, dict[str, int]] = {}
    for row in rows:
        group = counts.setdefault(row.claim.group, {v: 0 for v in (*VERDICTS, NOT_RUN)})
        group[row.verdict] += 1
    return counts


#: badge colours of sphinx-design (Bootstrap), also used by the verdict figure
_COLOURS = {"reproduced": "#198754", "partly": "#ffc107", "not reproduced": "#dc3545", NOT_RUN: "#6c757d"}


def plot_verdicts(rows: Sequence[ScoreRow], path: str | os.PathLike[str]) -> Path:
    """Draw the verdicts per section as horizontal stacked bars into ``path`` (PNG)."""
    import matplotlib  # noqa: PLC0415 (only the book needs it)

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    counts = verdict_counts(rows)
    groups = list(counts)[::-1]
    fig, ax = plt.subplots(figsize=(6.4, 0.35 * len(groups) + 0.9), dpi=110)
    left = [0] * len(groups)
    for verdict in (*VERDICTS, NOT_RUN):
        widths = [counts[g][verdict] for g in groups]
        ax.barh(groups, widths, left=left, color=_COLOURS[verdict], label=verdict, height=0.6)
        left = [a + b for a, b in zip(left, widths)]
    ax.set_xlabel("claims")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.legend(ncols=4, loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False, fontsize="small")
    ax.spines[["top", "right"]].set_visible(False)
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
    plt.close(fig)
    return out


def render_scoreboard(
    rows: Sequence[ScoreRow],
    *,
    profile: str,
    pages: Mapping[str, str],
    figures: Mapping[str, str] | None = None,
    notes: Mapping[str, str] | None = None,
    summary_figure: str | None = None,
) -> str:
    """Render the scoreboard page as MyST markdown.

    At the top, the counts of each verdict (and ``summary_figure``, the
    verdicts per section, see :func:`plot_verdicts`).  Then one row per
    claim, grouped by section: the claim in a few words, our headline
    number (± its spread over seeds), the paper's statement, the verdict
    badge, and links to the section and the figure.  Each row is a
    dropdown that unfolds the rule, the checks, the guarantees (apart) and
    every measured number.

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
    summary_figure : str, optional
        Image (relative to the scoreboard) shown under the counts.

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
    if summary_figure:
        out += [f"```{{image}} {summary_figure}", ":alt: verdicts per section", ":class: sb-summary", "```", ""]
    if profile != "paper":
        out += [":::{warning}",
                f"These numbers come from the `{profile}` profile, not the paper's settings; "
                "the verdicts say whether the code runs end to end, not whether the paper's "
                "claims hold.", ":::", ""]
    out += [
        "Each verdict is computed from the measured numbers by the rule shown in the claim's fold-out: "
        "*reproduced* when every check holds, *partly* when some do, *not reproduced* when none "
        "does; *not run* when no task has produced a result for the claim. Guarantees (what holds by "
        "construction) are listed apart and never count. Click a row to unfold its checks and numbers.",
        "",
    ]
    group = None
    for row in rows:
        if row.claim.group != group:
            group = row.claim.group
            out += ["", f"## {group}", "",
                    '<div class="sb-head"><span class="sb-id">ID</span><span class="sb-claim">claim</span>'
                    '<span class="sb-ours">ours (headline number)</span><span class="sb-verdict">verdict</span>'
                    '<span class="sb-where">see</span></div>', ""]
        entry = row.result or {}
        name, value = headline_of(entry)
        ours = f"{_inline(name)}: **{_inline(value)}**" if name else (_inline(value) or "—")
        paper = entry.get("paper") or row.claim.text
        paper_label = f"paper, {row.claim.figure}" if row.claim.figure else "paper"
        if row.result is None and row.task in (notes or {}):
            ours = _inline(notes[row.task])
        where = []
        if row.task is not None and row.task in pages:
            where.append(f"[section]({pages[row.task]})")
        fig = f"{figures[row.task]}/{entry['figure']}" if entry.get("figure") and row.task in figures else None
        if fig:  # opens the row and scrolls to the figure inside it
            where.append(f"{{ref}}`figure <{_figure_label(row)}>`")
        title = entry.get("title") or short_title(row.claim.text)
        summary = " ".join([
            f"[{row.claim.id}]{{.sb-id}}",
            f"[{_inline(title)}]{{.sb-claim}}",
            f"[{ours}]{{.sb-ours}}",
            f"[*{_inline(paper_label)}:* {_inline(paper)}]{{.sb-paper}}",
            f"[{{bdg-{_BADGE[row.verdict]}}}`{row.verdict}`]{{.sb-verdict}}",
            f"[{' '.join(where) or '—'}]{{.sb-where}}",
        ])
        out += [f"::::{{dropdown}} {summary}", f":name: claim-{row.claim.id.lower()}",
                ":class-container: sb-row", "", *_details(row, fig), "::::", ""]
    return "\n".join(out) + "\n"


def seeds_check(results: Mapping[str, Mapping[str, Any]]) -> dict[str, Any] | None:
    """Claim B2 (every comparison over seeds, spread shown), computed from the tasks' claims by
    :func:`fnnbook.rules.beyond.b2`; None when no task reported a claim."""
    from fnnbook.rules import beyond  # noqa: PLC0415

    headlines = {e["id"]: e.get("headline") for data in results.values() for e in data.get("claims", [])
                 if e["id"] not in (SEEDS_CHECK_ID, SELF_CHECK_ID)}
    if not headlines:
        return None
    rule = beyond.b2(headlines)
    seeded = [k for k in rule["numbers"]["seeds_per_claim"].values() if k]
    return claim_result(SEEDS_CHECK_ID, **rule, title="every comparison over seeds, spread shown",
                        headline=headline_number("judged claims with a per-seed headline",
                                                 len(seeded) / len(headlines)),
                        paper="the paper shows single runs")


def self_check(claims: Sequence[Claim], results: Mapping[str, Mapping[str, Any]],
               declared: Mapping[str, Sequence[str]] | None = None) -> dict[str, Any]:
    """The scoreboard's own claim (B3): it is computed from the runs.

    Checks (each fails on a plausible run): some task has results; every claim a task declares (or, without
    ``declared``, every claim of the claims file but B3 itself) has a verdict, i.e. no task failed or was
    skipped.  Guarantees (bookkeeping that holds by construction, shown apart and never counted): every
    reported ID is in the claims file, and every verdict is the one its checks imply.  A broken guarantee
    stops the book (:class:`~fnnlib.results.GuaranteeFailed`) naming the claims at fault.
    """
    ids = {c.id for c in claims}
    entries = [e for data in results.values() for e in data.get("claims", [])]
    unknown = sorted({e["id"] for e in entries} - ids)
    mismatched = sorted(e["id"] for e in entries
                        if not e.get("checks") or verdict_from_checks(e["checks"]) != e.get("verdict"))
    if unknown or mismatched:
        raise GuaranteeFailed(f"claim {SELF_CHECK_ID}: IDs not in the claims file {unknown}; verdicts not "
                              f"from their checks {mismatched}")
    expected = ({cid for task_ids in declared.values() for cid in task_ids} if declared is not None
                else ids - {SELF_CHECK_ID})
    missing = sorted(expected - {e["id"] for e in entries})
    return claim_result(
        SELF_CHECK_ID,
        checks={"results_found": bool(results), "every_declared_claim_reported": not missing},
        guarantees={"ids_known": not unknown, "verdicts_follow_checks": not mismatched},
        numbers={"tasks_with_results": len(results), "claims_reported": len(entries), "claims_listed": len(ids),
                 "claims_not_reported": missing},
        rule="some task has results and every claim a task declares has a verdict (checks); every reported ID "
             "is in the claims file and every verdict equals the one its checks imply (guarantees: bookkeeping)",
    )
