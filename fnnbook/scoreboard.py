"""The scoreboard: every claim of the registry (``claims.yaml``) with its measured verdict.

The registry lists the claims by group, each with the paper's statement (paraphrased), where the paper makes
it, its settings and the task that judges it (:func:`read_claims`).  Each task's ``results.json``
(:mod:`fnnbook.results`) reports verdicts for some IDs; the rest are shown as "not run".
"""

from __future__ import annotations

import functools
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jinja2
import yaml

from fnnbook.rules import beyond
from fnnbook.why import Why
from fnnbook.results import BETTER, BY_CONSTRUCTION, STATUSES, ClaimResult, Results

__all__ = ["NOT_RUN", "SCOREBOARD_TASK", "SEEDS_CHECK_ID", "SELF_CHECK_ID", "Claim", "ScoreRow", "headline_of",
           "plot_verdicts", "read_claims", "render_scoreboard", "score_rows", "seeds_check", "self_check",
           "short_title", "verdict_counts", "with_scoreboard_claims"]

#: the claim the scoreboard reports on itself ("the scoreboard page, computed from the runs")
SELF_CHECK_ID = "B3"
SEEDS_CHECK_ID = "B2"
#: the name under which the scoreboard's own claims (B2, B3) sit beside the tasks' results
SCOREBOARD_TASK = "scoreboard"

NOT_RUN = "not run"
_ID_RE = re.compile(r"^[A-Z]+[0-9]+$")
_BADGE = {"reproduced": "success", BETTER: "primary", "partly": "warning", "not reproduced": "danger",
          BY_CONSTRUCTION: "info",
          NOT_RUN: "secondary"}


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
    words : str
        For a claim with several readings: the name of the reading the paper's words support (the one the
        scoreboard counts); "" when the claim has one reading.
    words_sentence : str
        The paper's sentence that reading rests on (quoted from the paper).
    strict : str
        The name of the strict reading, shown beside the counted one, never counted ("" when none).
    units : str
        What the claim's units share, where they are not independent experiments (one ensemble trained on
        shared mini-batches, a network shared by several units); shown beside n ("" when nothing is shared).
    shared : str
        Where the units behind the claim's own headline and rule are not independent, what they share in a
        few words ("one ensemble"); the headline then says so beside its n and spread ("" when they are
        independent: a claim whose only shared units are another check's leaves it empty).
    """

    id: str
    group: str
    text: str
    figure: str
    section: str = ""
    settings: str = ""
    task: str = ""
    notebook: str = ""
    words: str = ""
    words_sentence: str = ""
    strict: str = ""
    units: str = ""
    shared: str = ""


@dataclass(frozen=True)
class ScoreRow:
    """A claim with the verdict measured for it (or "not run").

    ``task`` is the task that reported it (or declares it); ``result`` is
    the claim's result in that task's ``results.json``, if any.  ``verdict`` is the verdict of the reading the
    paper's words support (``claim.words``; the result's own verdict for a claim with one reading), the one
    counted; ``strict`` the strict reading's (``claim.strict``), shown beside it, or None.
    """

    claim: Claim
    verdict: str
    task: str | None
    result: ClaimResult | None
    strict: str | None = None


#: fields every claim of the registry must give (non-empty); ``settings`` and ``notebook`` are optional
CLAIM_FIELDS = ("id", "statement", "section", "figure", "task")
_OPTIONAL_FIELDS = ("settings", "notebook", "words", "strict", "units", "shared")


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
    words = entry.get("words")
    if words is not None and (not isinstance(words, Mapping) or set(words) != {"reading", "sentence"}):
        raise ValueError(f"{where}: 'words' must be a mapping with 'reading' (its name) and 'sentence' (the "
                         f"paper's words it rests on), got {words!r}")
    if ("strict" in entry) != (words is not None):
        raise ValueError(f"{where}: 'words' and 'strict' go together (a claim with two readings names both)")
    if "shared" in entry and "units" not in entry:
        raise ValueError(f"{where}: 'shared' names what the units share; 'units' must explain it")
    return Claim(id=values["id"], group=group, text=values["statement"], figure=figure,
                 section=values["section"], settings=" ".join(p for p in (group_settings, own) if p),
                 task=values["task"],
                 notebook=_text(entry["notebook"], where, "notebook") if "notebook" in entry else "",
                 words="" if words is None else _text(words["reading"], where, "words.reading"),
                 words_sentence="" if words is None else _text(words["sentence"], where, "words.sentence"),
                 strict=_text(entry["strict"], where, "strict") if "strict" in entry else "",
                 units=_text(entry["units"], where, "units") if "units" in entry else "",
                 shared=_text(entry["shared"], where, "shared") if "shared" in entry else "")


def read_claims(path: str | os.PathLike[str], text: str | None = None) -> list[Claim]:
    """Read every claim of a claims registry (YAML, see ``claims.yaml`` at the repository root).

    The file holds ``groups:``, a list (possibly empty) of ``{name, settings, claims}``; each claim gives ``id``,
    ``statement``, ``section``, ``figure`` and ``task`` (all non-empty), optionally ``settings`` and
    ``notebook``; a claim with several readings names ``words`` (``reading``: the reading the paper's words
    support, counted; ``sentence``: the paper's words it rests on) and ``strict`` (the strict reading's name);
    ``units`` says what the claim's units share, where they are not independent; ``shared`` (with ``units``)
    names it in a few words where the claim's own units share training, shown beside its headline's n.

    Parameters
    ----------
    path : path-like
        The registry.
    text : str, optional
        Its content, already read (``path`` then only names it in errors).

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
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8") if text is None else text)
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
    results: Mapping[str, Results],
    declared: Mapping[str, Sequence[str]] | None = None,
) -> list[ScoreRow]:
    """Attach to each claim the verdict a task's results report for it.

    Parameters
    ----------
    claims : sequence of Claim
    results : mapping of str to Results
        Task name -> its ``results.json`` (:func:`fnnbook.results.read_results`; tasks without outputs left out).
    declared : mapping of str to sequence of str, optional
        Task name -> claim IDs it declares; names the task of claims that
        have no result yet.

    Returns
    -------
    list of ScoreRow
        One per claim, in order; verdict :data:`NOT_RUN` where no result.
    """
    found: dict[str, tuple[str, ClaimResult]] = {}
    for task, data in results.items():
        for result in data:
            found.setdefault(result.id, (task, result))
    owner = {cid: task for task, ids in (declared or {}).items() for cid in ids}
    rows = []
    for claim in claims:
        if claim.id in found:
            task, result = found[claim.id]
            rows.append(ScoreRow(claim, reading_verdict(claim, result, claim.words), task, result,
                                 reading_verdict(claim, result, claim.strict) if claim.strict else None))
        else:
            rows.append(ScoreRow(claim, NOT_RUN, owner.get(claim.id), None))
    return rows


def reading_verdict(claim: Claim, result: ClaimResult, name: str) -> str:
    """The verdict of ``result`` under its reading ``name`` (the result's own verdict when ``name`` is "" or the
    result has one reading). A result whose readings lack ``name`` is refused (ValueError): the claims file and
    the rule disagree on what the readings are."""
    verdicts = result.reading_verdicts()
    if not name or not verdicts:
        return result.verdict
    if name not in verdicts:
        raise ValueError(f"claim {claim.id}: the claims file names the reading {name!r}, the result has "
                         f"{sorted(verdicts)}")
    return verdicts[name]


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


def headline_of(result: ClaimResult | None, shared: str = "") -> tuple[str, str]:
    """The headline number of a result as ``(name, "value ± spread unit (n = k seeds)")``.

    Uses the result's ``headline`` (see :func:`fnnbook.results.headline_number`).
    A result without one (written before the field existed) shows how many
    of its checks hold instead of guessing a number from ``numbers``;
    ``("", "")`` when there is no result. ``shared`` (the claim's :attr:`Claim.shared`) marks units that
    are not independent: ``(n = 5 seeds, one ensemble: not independent)``, so that the spread is not read
    as that of independent runs.
    """
    mark = f", {shared}: not independent" if shared else ""
    if result is None:
        return "", ""
    head = result.headline
    if head is not None:
        text = _number(head.value)
        if head.spread is not None:
            text += f" ± {_number(head.spread)}"
        if head.unit:
            text += f" {head.unit}"
        if result.n is not None:
            text += f" (n = {result.n}{mark})"
        elif head.n:
            text += f" (n = {head.n} seeds{mark})"
        return head.name, text
    if not result.checks:
        return "guarantees holding", f"{len(result.guarantees or {})} (no check could fail)"
    n = f" (n = {result.n}{mark})" if result.n is not None else ""
    return "checks holding", f"{sum(result.checks.values())} of {len(result.checks)}{n}"


def _figure_label(row: ScoreRow) -> str:
    return f"claim-{row.claim.id.lower()}-figure"


def verdict_counts(rows: Sequence[ScoreRow]) -> dict[str, dict[str, int]]:
    """Group -> status -> number of claims, groups in order of first appearance.

    A claim counts once, under the verdict of the reading the paper's words support (:attr:`ScoreRow.verdict`);
    "verified by construction" is counted apart.
    """
    counts: dict[str, dict[str, int]] = {}
    for row in rows:
        group = counts.setdefault(row.claim.group, {v: 0 for v in (*STATUSES, NOT_RUN)})
        group[row.verdict] += 1
    return counts


#: badge colours of sphinx-design (Bootstrap), also used by the verdict figure
_COLOURS = {"reproduced": "#198754", BETTER: "#0d6efd", "partly": "#ffc107", "not reproduced": "#dc3545",
            BY_CONSTRUCTION: "#0dcaf0",
            NOT_RUN: "#6c757d"}


def plot_verdicts(rows: Sequence[ScoreRow], path: str | os.PathLike[str]) -> Path:
    """Draw the verdicts per section as horizontal stacked bars into ``path`` (PNG)."""
    import matplotlib  # noqa: PLC0415 (only the book needs it)

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    counts = verdict_counts(rows)
    groups = list(counts)[::-1]
    fig, ax = plt.subplots(figsize=(6.4, 0.35 * len(groups) + 0.9), dpi=110)
    left = [0] * len(groups)
    for verdict in (*STATUSES, NOT_RUN):
        widths = [counts[g][verdict] for g in groups]
        ax.barh(groups, widths, left=left, color=_COLOURS[verdict], label=verdict, height=0.6)
        left = [a + b for a, b in zip(left, widths)]
    ax.set_xlabel("claims")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.legend(ncols=3, loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False, fontsize="small")
    ax.spines[["top", "right"]].set_visible(False)
    out = Path(path)
    fig.savefig(out, bbox_inches="tight")
    plt.close(fig)
    return out


#: a claim's why that is not there: the reason, and the command that makes it (or None)
Missing = tuple[str, "str | None"]


def why_of(claim_id: str, whys: Mapping[str, Why | Missing], why_pages: Mapping[str, str]) -> dict[str, Any] | None:
    """What the row shows under **Why**: the why's one-line summary and causes, or why there is none yet
    (``("not run", "make why")``); None for a claim no why task explains."""
    why = whys.get(claim_id)
    if why is None:
        return None
    if isinstance(why, tuple):
        return {"line": why[0], "command": why[1], "causes": [], "tags": "", "link": None, "figure": None}
    causes = [{"letter": c.letter, "name": c.name, "evidence": c.evidence} for c in why.causes]
    page = why_pages.get(claim_id)
    return {"line": why.summary, "command": None, "causes": causes, "link": page,
            "tags": "".join(f"({c.letter})" for c in why.causes) or "robust",
            "figure": f"{page.rsplit('/', 1)[0]}/{why.figure}" if page and why.figure else None}


def _summary(row: ScoreRow, pages: Mapping[str, str], figures: Mapping[str, str],
             notes: Mapping[str, str], why: dict[str, Any] | None = None) -> dict[str, Any]:
    """What the template shows of a row beside the claim and its result: its summary cells and its figure."""
    result = row.result
    name, value = headline_of(result, row.claim.shared)
    ours = f"{_inline(name)}: **{_inline(value)}**" if name else (_inline(value) or "—")
    if result is None and row.task in notes:
        ours = _inline(notes[row.task])
    if result is not None and result.at_paper_setting:
        ours += f" — *at the paper's setting:* {_inline(result.at_paper_setting)}"
    where = [f"[section]({pages[row.task]})"] if row.task is not None and row.task in pages else []
    figure = f"{figures[row.task]}/{result.figure}" if result and result.figure and row.task in figures else None
    if figure:  # opens the row and scrolls to the figure inside it
        where.append(f"{{ref}}`figure <{_figure_label(row)}>`")
    return {"claim": row.claim, "result": result, "verdict": row.verdict, "badge": _BADGE[row.verdict],
            "title": (result and result.title) or short_title(row.claim.text), "ours": ours,
            "paper": (result and result.paper) or row.claim.text,
            "paper_label": f"paper, {row.claim.figure}" if row.claim.figure else "paper",
            "where": where, "figure": figure, "figure_label": _figure_label(row), "readings": readings_of(result, row.claim.words),
            "n": units_of(result), "why": why}


def readings_of(result: ClaimResult | None, counted: str = "") -> str:
    """The verdict of each reading, the counted one (``counted``, the paper's words) first and marked:
    ``"as worded (counted): reproduced; strict: partly"`` ("" for a claim with one reading)."""
    if result is None:
        return ""
    verdicts = result.reading_verdicts()
    if not verdicts:
        return ""
    first = counted if counted in verdicts else result.reading_name
    order = [first] + [k for k in verdicts if k != first]
    return "; ".join(f"{k}{' (counted)' if k == first else ''}: {verdicts[k]}" for k in order)


def units_of(result: ClaimResult | None) -> int | None:
    """The independent units a comparison rests on: the claim's ``n``, else its headline's (None if neither)."""
    if result is None:
        return None
    return result.n if result.n is not None else (result.headline.n if result.headline is not None else None)


@functools.cache
def _template() -> jinja2.Template:
    env = jinja2.Environment(loader=jinja2.PackageLoader("fnnbook", "templates"), autoescape=False,
                             trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True,
                             undefined=jinja2.StrictUndefined)
    env.filters |= {"inline": _inline, "number": _number, "code": lambda text: str(text).replace("`", "'")}
    return env.get_template("scoreboard.md.j2")


def render_scoreboard(
    rows: Sequence[ScoreRow],
    *,
    profile: str,
    pages: Mapping[str, str],
    figures: Mapping[str, str] | None = None,
    notes: Mapping[str, str] | None = None,
    summary_figure: str | None = None,
    whys: Mapping[str, Why | Missing] | None = None,
    why_pages: Mapping[str, str] | None = None,
    stale: Mapping[str, str] | None = None,
    stale_whys: Mapping[str, str] | None = None,
    unchecked: str = "",
) -> str:
    """Render the scoreboard page as MyST markdown (the template ``templates/scoreboard.md.j2``).

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
    whys : mapping of str to Why or (str, str or None), optional
        Claim -> its why (:class:`fnnbook.why.Why`), or the reason it has none yet and the command that
        makes it (``("not run", "make why")``); shown under **Why**.
    why_pages : mapping of str to str, optional
        Claim -> link target of the page of the task that wrote its why.
    stale : mapping of str to str, optional
        Claim -> the command that refreshes it, for a claim whose task's outputs are stale (an input changed
        since they ran): the row says so; its verdict is never shown as current.
    stale_whys : mapping of str to str, optional
        The same for a claim whose why task's outputs are stale.
    unchecked : str
        Why it could not be decided whether the outputs are current ("" when it was); said at the top.

    Returns
    -------
    str
    """
    counts = [f"{sum(r.verdict == v for r in rows)} {v}" for v in (*STATUSES, NOT_RUN)]
    strict = [r for r in rows if r.strict is not None]
    if strict:  # the strict readings' count beside the counted one, never in it
        beside = [(v, sum((r.strict if r.strict is not None else r.verdict) == v for r in rows))
                  for v in (*STATUSES, NOT_RUN)]
        counts.append("by the strict readings of " + ", ".join(r.claim.id for r in strict) + ": "
                      + ", ".join(f"{k} {v}" for v, k in beside if k))
    stale, stale_whys = stale or {}, stale_whys or {}
    shown = []
    for r in rows:
        row = _summary(r, pages, figures or {}, notes or {}, why_of(r.claim.id, whys or {}, why_pages or {}))
        row["stale"] = stale.get(r.claim.id)
        if row["why"] is not None:
            row["why"]["stale"] = stale_whys.get(r.claim.id)
        shown.append(row)
    n_stale = sum(1 for r in shown if r["stale"] or (r["why"] or {}).get("stale"))
    return _template().render(rows=shown, profile=profile, counts=counts, summary_figure=summary_figure,
                              n_stale=n_stale, unchecked=unchecked)


def seeds_check(results: Mapping[str, Results]) -> ClaimResult | None:
    """Claim B2 (every comparison over seeds, spread shown), judged by :func:`fnnbook.rules.beyond.b2` on the
    tasks' headlines; None when no task reported a claim."""
    headlines = {c.id: c.headline for r in results.values() for c in r if c.id not in (SEEDS_CHECK_ID, SELF_CHECK_ID)}
    return beyond.b2(headlines) if headlines else None


def self_check(claims: Sequence[Claim], results: Mapping[str, Results],
               declared: Mapping[str, Sequence[str]] | None = None) -> ClaimResult:
    """The scoreboard's own claim (B3: it is computed from the runs), judged by :func:`fnnbook.rules.beyond.b3`.

    The claims expected are every claim a task declares (or, without ``declared``, every claim of the claims
    file but B3 itself).  A reported ID the claims file does not list stops the book
    (:class:`~fnnbook.results.GuaranteeFailed`).
    """
    ids = {c.id for c in claims}
    expected = ({cid for task_ids in declared.values() for cid in task_ids} if declared is not None
                else ids - {SELF_CHECK_ID})
    return beyond.b3(ids, [c for r in results.values() for c in r], tasks_with_results=len(results),
                     expected=expected)


def with_scoreboard_claims(claims: Sequence[Claim], results: Mapping[str, Results], profile: str,
                           declared: Mapping[str, Sequence[str]] | None = None) -> dict[str, Results]:
    """``results`` with the scoreboard's own claims, where the claims file lists them, as task ``"scoreboard"``:
    B2 from the tasks' headlines, then B3 over everything (B2 included)."""
    listed = {c.id for c in claims}
    computed: list[ClaimResult] = []
    if SEEDS_CHECK_ID in listed and (b2 := seeds_check(results)) is not None:
        computed.append(b2)
    if SELF_CHECK_ID in listed:
        own = Results(task=SCOREBOARD_TASK, profile=profile, claims=tuple(computed))
        computed.append(self_check(claims, {**results, SCOREBOARD_TASK: own}, declared))
    if not computed:
        return dict(results)
    return {**results, SCOREBOARD_TASK: Results(task=SCOREBOARD_TASK, profile=profile, claims=tuple(computed))}
