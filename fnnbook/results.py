"""Claim verdicts and the per-task results JSON read by the scoreboard.

A notebook decomposes each claim of the registry (``claims.yaml``) into named boolean checks,
each computed from measured numbers by a rule stated in the notebook.  The
verdict is derived from the checks alone, never set by hand:

* ``"reproduced"``      every check holds,
* ``"partly"``          some but not all checks hold,
* ``"not reproduced"``  no check holds;
* ``"better than claimed"``  some check fails, and every failed check fails because the measured result beats
  the claim in the claim's own direction (``better``: e.g. a cost below the paper's band, an error below the
  one the paper calls "slightly larger"); it is not "reproduced" either;
* ``"verified by construction"``  the claim has no check, only guarantees: nothing measured could have
  refuted it, so it is never counted as reproduced (the scoreboard counts it apart).

Besides its ``checks``, a claim may carry:

* ``guarantees``: named booleans that hold by construction, by a theorem
  with constants measured on the same run, or by self-consistency (frozen
  weights, bookkeeping).  They never count toward the verdict, and a false
  one stops the notebook (:class:`GuaranteeFailed`);
* ``headline``: the one number a reader looks for first (:class:`Headline`),
  ``{"name", "value", "unit"}`` plus ``"spread"``, ``"n"`` and
  ``"per_seed"`` when it is measured over seeds (:func:`headline_number`);
* ``paper``: the paper's number or statement it is compared with;
* ``title``: the claim in a few words;
* ``reading`` (and ``reading_name``): one sentence on how the rule reads the paper's words;
* ``readings``: the other readings of an ambiguous claim, each a :class:`Reading` with its own checks and
  verdict; the claim's own checks (the reading written first) are the ones counted;
* ``n``: the number of independent units the comparison rests on;
* ``better``: for checks that can fail in the claim's own direction, whether the measured result beats the
  claim there (check name -> bool); they make a failed check read "better than claimed";
* ``at_paper_setting``: where a claim is judged at a setting other than the paper's stated one, the outcome
  at the stated one (or why it cannot be judged there, with the number).

All are optional: a result without them reads as before, and the
scoreboard falls back on the claims file and the numbers.

One claim is a :class:`ClaimResult` (what every rule of ``fnnbook.rules``
returns); one task's ``results.json`` is a :class:`Results`, written by
:func:`write_results` and read by :func:`read_results` (``.claim(id)``).
"""

from __future__ import annotations

import copy
import dataclasses
import datetime as _dt
import json
import math
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fnnlib.io import atomic_write

__all__ = ["BETTER", "BY_CONSTRUCTION", "RESULTS_FILENAME", "STATUSES", "VERDICTS", "ClaimResult", "GuaranteeFailed",
           "Headline", "Reading", "Results", "headline_number", "read_results", "verdict_from_checks",
           "verdict_with_better", "write_results"]

VERDICTS = ("reproduced", "partly", "not reproduced")
#: the verdict of a claim whose every failed check fails because the result beats the claim in its own direction
BETTER = "better than claimed"
#: the status of a claim whose only support holds by construction (no check, some guarantees)
BY_CONSTRUCTION = "verified by construction"
#: every status a claim can have: the three verdicts, :data:`BETTER`, then :data:`BY_CONSTRUCTION`
STATUSES = (*VERDICTS, BETTER, BY_CONSTRUCTION)
#: the name of a task's results file in its output folder
RESULTS_FILENAME = "results.json"

#: the keys of a claim's JSON, in the order they are written; the last four only when given
_REQUIRED = ("id", "verdict", "rule", "checks", "numbers", "figure")
_OPTIONAL = ("guarantees", "headline", "paper", "title", "reading", "reading_name", "readings", "n",
             "at_paper_setting", "better")


def _stored_verdict_holds(result: Any, stored: str, what: str) -> Any:
    """``result`` when the verdict stored in a file is the one its checks imply; else ValueError naming ``what``."""
    if result.verdict != stored:
        raise ValueError(f"{what} verdict {stored!r} is not the one its checks imply ({result.verdict!r})")
    return result


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


def verdict_with_better(checks: Mapping[str, bool], better: Mapping[str, bool] | None) -> str:
    """The verdict of ``checks`` (:func:`verdict_from_checks`), or :data:`BETTER` when some check fails and every
    failed one is marked in ``better`` as failing because the result beats the claim in its own direction."""
    verdict = verdict_from_checks(checks)
    failed = [k for k, v in checks.items() if not v]
    if failed and better and all(better.get(k, False) for k in failed):
        return BETTER
    return verdict


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


@dataclass(frozen=True)
class Headline:
    """The one number of a claim a reader looks for first, as the scoreboard shows it (:func:`headline_number`).

    Attributes
    ----------
    name : str
        What the number is, in a few words.
    value : float
        The number; over seeds, their mean.
    unit : str
        E.g. ``"cm"``; empty for a ratio.
    spread, n, per_seed : float, int, tuple of float, or None
        Over seeds: the sample standard deviation (``ddof=1``), the count and the values; None for one run.
    """

    name: str
    value: float
    unit: str = ""
    spread: float | None = None
    n: int | None = None
    per_seed: tuple[float, ...] | None = None

    def to_json(self) -> dict[str, Any]:
        """``{"name", "value", "unit"}``, with ``"spread", "n", "per_seed"`` before ``"unit"`` when over seeds."""
        out: dict[str, Any] = {"name": self.name, "value": self.value}
        if self.n is not None:
            out |= {"spread": self.spread, "n": self.n, "per_seed": list(self.per_seed or ())}
        return _plain(out | {"unit": self.unit})

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Headline:
        """Read what :meth:`to_json` wrote.

        Raises
        ------
        ValueError
            If ``name`` or ``value`` is missing, or a key is unknown.
        """
        missing = [k for k in ("name", "value") if k not in data]
        unknown = sorted(set(data) - {f.name for f in dataclasses.fields(cls)})
        if missing or unknown:
            raise ValueError(f"headline lacks {', '.join(missing)}" if missing else f"headline: unknown keys {unknown}")
        per_seed = data.get("per_seed")
        return cls(**{**data, "per_seed": None if per_seed is None else tuple(per_seed)})


def headline_number(name: str, value: float | Sequence[float], *, unit: str = "") -> Headline:
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
    values = _plain(value)
    if not isinstance(values, list):
        return Headline(name, float(values), unit)
    if not values:
        raise ValueError(f"headline {name!r}: no per-seed values")
    values = [float(v) for v in values]
    n = len(values)
    mean = math.fsum(values) / n
    spread = math.sqrt(math.fsum((v - mean) ** 2 for v in values) / (n - 1)) if n > 1 else 0.0
    return Headline(name, mean, unit, spread=spread, n=n, per_seed=tuple(values))


@dataclass(frozen=True)
class Reading:
    """One reading of an ambiguous claim's words: the sentence that states it and the checks it implies.

    Attributes
    ----------
    sentence : str
        How this reading takes the paper's words, in one sentence.
    checks : mapping of str to bool
        Its own checks, computed from the same measured numbers; they alone decide :attr:`verdict`.

    Raises
    ------
    ValueError
        If ``sentence`` or ``checks`` is empty.
    """

    sentence: str
    checks: Mapping[str, bool]

    def __post_init__(self) -> None:
        if not self.sentence:
            raise ValueError("a reading needs its sentence")
        verdict_from_checks(self.checks)
        object.__setattr__(self, "checks", {k: bool(v) for k, v in self.checks.items()})

    @property
    def verdict(self) -> str:
        """The verdict its checks imply (:func:`verdict_from_checks`)."""
        return verdict_from_checks(self.checks)

    def to_json(self) -> dict[str, Any]:
        """``{"reading", "checks", "verdict"}``."""
        return {"reading": self.sentence, "checks": dict(self.checks), "verdict": self.verdict}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Reading:
        """Read what :meth:`to_json` wrote; a stored verdict other than the checks' is refused (ValueError)."""
        if set(data) != {"reading", "checks", "verdict"}:
            raise ValueError(f"a reading has the keys reading, checks, verdict, got {sorted(data)}")
        return _stored_verdict_holds(cls(data["reading"], data["checks"]), data["verdict"], "reading")


@dataclass(frozen=True)
class ClaimResult:
    """One claim's checks, guarantees, measured numbers and the verdict they imply.

    Every rule of ``fnnbook.rules`` returns one; the notebook adds what only it knows (the numbers shown, the
    figure, the headline) with :meth:`replace` and writes it with :func:`write_results`.

    Attributes
    ----------
    id : str
        The claim's ID in the claims registry (``claims.yaml``), e.g. ``"S2"``.
    checks : mapping of str to bool
        Named sub-checks, each computed from the measured numbers; they alone decide :attr:`verdict`.
    rule : str
        The rule, in words, that turns the numbers into ``checks``.
    numbers : mapping
        The measured numbers behind the checks (scalars or short lists), made JSON-plain.
    figure : str, optional
        Path of the figure that shows the claim, relative to the task's output directory
        (e.g. ``"figures/fig4f_multistep.png"``).
    guarantees : mapping of str to bool, optional
        What holds by construction, by a theorem with constants measured on the same run, or by
        self-consistency; shown apart from ``checks``, never counted toward the verdict.  ``None``: the rule
        states none, and the JSON has no ``guarantees`` key.
    headline : Headline, optional
        The claim's headline number, as made by :func:`headline_number`.
    paper : str, optional
        The paper's number or statement for this claim.
    title : str, optional
        The claim in a few words.
    reading : str, optional
        How this rule reads the paper's words, in one sentence.
    reading_name : str, optional
        A short name for that reading (e.g. ``"strict"``) when the claim has other :attr:`readings`.
    readings : mapping of str to Reading, optional
        The other readings of an ambiguous claim, by name; shown beside the verdict, never counted.
    n : int, optional
        The number of independent units (seeds, networks, disturbance draws) the comparison rests on.
    at_paper_setting : str, optional
        When judged at a setting other than the paper's stated one: the outcome at the stated one, or why it
        cannot be judged there, with the number.
    better : mapping of str to bool, optional
        For the checks that can fail in the claim's own direction: whether the measured result beats the claim
        there (a marked check must fail to be marked True). Every failed check marked True: :data:`BETTER`.

    With no checks and non-empty ``guarantees`` the claim is :data:`BY_CONSTRUCTION`.

    Raises
    ------
    GuaranteeFailed
        If a guarantee is false: something that must hold does not, so the run itself is wrong and no
        verdict is written.
    ValueError
        If ``checks`` and ``guarantees`` are both empty, ``readings`` is given without ``reading_name``, or
        ``n`` is below 1.
    TypeError
        If ``headline`` is not a :class:`Headline` or a reading not a :class:`Reading`.
    """

    id: str
    checks: Mapping[str, bool]
    rule: str
    numbers: Mapping[str, Any] = field(default_factory=dict)
    figure: str | None = None
    guarantees: Mapping[str, bool] | None = None
    headline: Headline | None = None
    paper: str | None = None
    title: str | None = None
    reading: str | None = None
    reading_name: str | None = None
    readings: Mapping[str, Reading] | None = None
    n: int | None = None
    at_paper_setting: str | None = None
    better: Mapping[str, bool] | None = None

    def __post_init__(self) -> None:
        if self.better is not None:
            unknown = sorted(set(self.better) - set(self.checks))
            held = [k for k, v in self.better.items() if v and self.checks.get(k)]
            if unknown or held:
                raise ValueError(f"claim {self.id}: 'better' names checks it does not have ({unknown}) or marks "
                                 f"checks that hold ({held})")
            object.__setattr__(self, "better", {k: bool(v) for k, v in self.better.items()})
        if self.checks or not self.guarantees:
            verdict_from_checks(self.checks)  # refuses a claim with neither checks nor guarantees
        if self.readings is not None:
            wrong = [k for k, r in self.readings.items() if not isinstance(r, Reading)]
            if wrong or not self.readings or not self.reading_name:
                raise (TypeError if wrong else ValueError)(
                    f"claim {self.id}: readings must be a non-empty name -> Reading mapping beside a reading_name "
                    f"(wrong: {wrong})")
            object.__setattr__(self, "readings", dict(self.readings))
        if self.n is not None:
            if isinstance(self.n, bool) or int(self.n) != self.n or self.n < 1:
                raise ValueError(f"claim {self.id}: n must be a positive count of independent units, got {self.n!r}")
            object.__setattr__(self, "n", int(self.n))
        failed = [k for k, v in (self.guarantees or {}).items() if not bool(v)]
        if failed:
            raise GuaranteeFailed(f"claim {self.id}: guarantee(s) {', '.join(failed)} do not hold")
        if self.headline is not None and not isinstance(self.headline, Headline):
            raise TypeError(f"claim {self.id}: headline must be a Headline (headline_number), got {self.headline!r}")
        plain = {"checks": {k: bool(v) for k, v in self.checks.items()}, "numbers": _plain(dict(self.numbers)),
                 "guarantees": None if self.guarantees is None else {k: True for k in self.guarantees}}
        for name, value in plain.items():
            object.__setattr__(self, name, value)

    @property
    def verdict(self) -> str:
        """``"reproduced"`` (every check holds), ``"partly"`` (some do), ``"not reproduced"`` (none does),
        :data:`BETTER` (every failed check fails in the claim's own direction, :attr:`better`), or
        :data:`BY_CONSTRUCTION` (no check, only guarantees)."""
        return verdict_with_better(self.checks, self.better) if self.checks else BY_CONSTRUCTION

    def reading_verdicts(self) -> dict[str, str]:
        """Reading name -> verdict, the counted one (:attr:`reading_name`) first; empty with one reading."""
        if not self.readings:
            return {}
        return {str(self.reading_name): self.verdict} | {k: r.verdict for k, r in self.readings.items()}

    def replace(self, **changes: Any) -> ClaimResult:
        """A copy with ``changes`` (e.g. the ``numbers``, ``figure`` and ``headline`` a notebook adds)."""
        return dataclasses.replace(self, **changes)

    def to_json(self) -> dict[str, Any]:
        """The claim as ``results.json`` holds it: ``id, verdict, rule, checks, numbers, figure``, then
        ``guarantees, headline, paper, title`` where given (so results without them read as before)."""
        out = {k: getattr(self, k) for k in _REQUIRED}
        out |= {k: getattr(self, k) for k in _OPTIONAL if getattr(self, k) is not None}
        if self.headline is not None:
            out["headline"] = self.headline.to_json()
        if self.readings is not None:
            out["readings"] = {k: r.to_json() for k, r in self.readings.items()}
        return copy.deepcopy(out)  # the result stays frozen

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ClaimResult:
        """Read one claim written by :meth:`to_json`.

        Raises
        ------
        ValueError
            If a key is missing or unknown, the verdict is not one of :data:`VERDICTS` or not the one its
            checks imply, a guarantee is false (a file edited by hand, or written by another program), or the
            headline lacks its name or value.
        """
        cid = data.get("id")
        missing = [k for k in _REQUIRED if k not in data]
        unknown = sorted(set(data) - {*_REQUIRED, *_OPTIONAL})
        if missing or unknown:
            raise ValueError(f"claim {cid!r}: keys missing {missing}, unknown {unknown}")
        if data["verdict"] not in STATUSES:
            raise ValueError(f"claim {cid!r} has verdict {data['verdict']!r}")
        if not all((data.get("guarantees") or {}).values()):
            raise ValueError(f"claim {cid!r} has a failed guarantee")
        fields = {k: v for k, v in data.items() if k != "verdict"}
        if data.get("headline") is not None:
            fields["headline"] = Headline.from_json(data["headline"])
        if data.get("readings") is not None:
            fields["readings"] = {k: Reading.from_json(r) for k, r in data["readings"].items()}
        return _stored_verdict_holds(cls(**fields), data["verdict"], f"claim {cid!r}:")


@dataclass(frozen=True)
class Results:
    """One task's ``results.json``: its claims, typed, and its free-form ``metrics``.

    Attributes
    ----------
    task, profile : str
        The task that wrote it and the profile it ran.
    claims : tuple of ClaimResult
        In the order written; IDs are unique.
    metrics : mapping
        What later tasks or the reader need beside the claims (JSON values).
    created : str
        ISO time stamp of the write (empty when not recorded).
    """

    task: str
    profile: str
    claims: tuple[ClaimResult, ...] = ()
    metrics: Mapping[str, Any] = field(default_factory=dict)
    created: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "claims", tuple(self.claims))
        ids = [c.id for c in self.claims]
        if len(ids) != len(set(ids)):
            raise ValueError(f"duplicate claim IDs in results: {ids}")

    def __iter__(self) -> Iterator[ClaimResult]:
        return iter(self.claims)

    def claim(self, claim_id: str) -> ClaimResult:
        """The claim ``claim_id``; a :class:`KeyError` naming the task and the IDs it has when absent."""
        for c in self.claims:
            if c.id == claim_id:
                return c
        raise KeyError(f"task {self.task!r} reports no claim {claim_id!r} (it has {[c.id for c in self.claims]})")

    def to_json(self) -> dict[str, Any]:
        """The file's content: ``task, profile, created, claims, metrics``."""
        return {"task": self.task, "profile": self.profile, "created": self.created,
                "claims": [c.to_json() for c in self.claims], "metrics": _plain(dict(self.metrics))}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Results:
        """Read what :meth:`to_json` wrote (see :meth:`ClaimResult.from_json` for the errors)."""
        for key in ("task", "profile", "claims"):
            if key not in data:
                raise ValueError(f"lacks the key {key!r}")
        return cls(task=data["task"], profile=data["profile"], created=data.get("created", ""),
                   claims=tuple(ClaimResult.from_json(c) for c in data["claims"]), metrics=data.get("metrics", {}))


def write_results(
    out_dir: str | os.PathLike[str],
    *,
    task: str,
    profile: str,
    claims: Sequence[ClaimResult],
    metrics: Mapping[str, Any] | None = None,
) -> Path:
    """Write ``results.json`` for one task atomically (temp file + rename).

    Returns the path written.

    Raises
    ------
    TypeError
        If a claim is not a :class:`ClaimResult`.
    ValueError
        If two claims share an ID.
    """
    wrong = [type(c).__name__ for c in claims if not isinstance(c, ClaimResult)]
    if wrong:
        raise TypeError(f"write_results takes ClaimResult claims, got {wrong}")
    created = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    results = Results(task=task, profile=profile, claims=tuple(claims), metrics=metrics or {}, created=created)
    path = Path(out_dir) / RESULTS_FILENAME
    with atomic_write(path, "w") as fh:
        json.dump(results.to_json(), fh, indent=2, sort_keys=False)
        fh.write("\n")
    return path


def read_results(path: str | os.PathLike[str]) -> Results:
    """Read and validate a results JSON written by :func:`write_results` (find a claim with
    :meth:`Results.claim`).

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    ValueError
        If it is not valid JSON, lacks ``task``, ``profile`` or ``claims``, or a claim is invalid
        (see :meth:`ClaimResult.from_json`).
    """
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise
    except (OSError, ValueError) as exc:
        raise ValueError(f"results file {p} is not valid JSON: {exc}") from exc
    try:
        return Results.from_json(data)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"results file {p}: {exc}") from exc
