"""Why a claim stands where it stands: the claim's own rule over the settings the paper leaves open.

A *why* explains one claim's verdict in the paper profile.  It rests on runs, never on prose alone:

* **grids** (:class:`WhyGrid`): the claim's own rule (the function of :mod:`fnnbook.rules` that judges it)
  applied over the seeds at every point of a grid; each axis (:class:`Axis`) is named for the silence of the
  paper it probes, with the paper's stated value (``None`` where it states none) and the value the paper
  profile uses. An axis is a *setting* (how the networks are trained or run), a *reading* (how the paper's
  words are scored: a window, a metric, a threshold) or a *usage* (how the networks are used where the paper
  does not say: a cascade's decay, its first estimate). A grid is of our networks or of the authors'
  (``networks``);
* **the authors' networks** (:class:`AuthorsCheck`): the same rule with the networks of the authors' release
  in place of ours;
* **readings**: the verdicts of the claim's readings, from the paper-profile result.

From these, :func:`causes` names the causes by a rule fixed here, before any why run (tested in
``tests/rules/test_why.py``):

* (a) **reading**: the claim's readings do not all give the same verdict, or along a reading or usage axis
  the rule holds at one point and fails at another;
* (b) **open setting**: on some grid of our networks the rule holds at one point and fails at another, along
  a setting axis whose value the paper does not state;
* (c) **implementation**: with the authors' networks the rule gives a better verdict than with ours;
* (d) **does not hold where tested**: only when nothing tried lets the claim hold: no point of any grid, ours
  or the authors', over every setting, reading and usage they vary; no reading of the paper-profile result;
  and not the authors' networks (where evaluated).

A claim may have several causes, or none (then the why reads "robust": the verdict stands at every point).
:func:`summary` writes the one line the scoreboard shows under **Why**, from the numbers alone.

A why task writes its whys with :func:`write_whys` (``whys.json`` in its output folder); the book reads them
with :func:`read_whys`.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fnnlib.io import atomic_write
from fnnbook.results import BETTER, VERDICTS

__all__ = ["AXIS_KINDS", "CAUSES", "WHYS_FILENAME", "Axis", "AuthorsCheck", "Cause", "Why", "WhyGrid", "causes", "read_whys",
           "reproduced", "summary", "write_whys"]

#: the name of a why task's output file
WHYS_FILENAME = "whys.json"

#: the four causes a why can name
CAUSES: Mapping[str, str] = dict(
    a="the reading of the paper's words",
    b="a setting the paper leaves open",
    c="our implementation against the authors'",
    d="the claim does not hold where it was tested",
)

_RANK = {v: i for i, v in enumerate(reversed(VERDICTS))} | {BETTER: 2}  # not reproduced 0 < partly 1 < reproduced 2
_HOLDS = ("reproduced", BETTER)  # the verdicts under which a claim holds

#: what an axis varies: a training or running ``setting``; a ``reading`` of the paper's words (how the result is
#: scored: window, metric, threshold); a ``usage`` of the networks the paper does not state (a cascade's decay,
#: its first estimate)
AXIS_KINDS = ("setting", "reading", "usage")


def _plain(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    return value


def _text(value: Any) -> str:
    """A grid value in short: ``0.003``, ``4.5``, ``adam``, ``[2000, adam]``."""
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_text(v) for v in value) + "]"
    return str(value)


@dataclass(frozen=True)
class Axis:
    """One axis of a why grid.

    Attributes
    ----------
    name : str
        The setting it varies (a notebook parameter's name where there is one: ``noise_std``).
    values : tuple
        The grid values, in the order of the grid's ``holds`` array.
    silence : str
        What the paper leaves open that this axis probes, in a few words ("the measurement noise of
        Fig. 4g is not given").
    paper : Any
        The value the paper states, or ``None`` where it states none.
    ours : Any
        The value the paper profile uses (one of ``values`` where possible).
    kind : str
        One of :data:`AXIS_KINDS`: ``"setting"`` (default), ``"reading"`` or ``"usage"``.
    """

    name: str
    values: tuple[Any, ...]
    silence: str
    paper: Any = None
    ours: Any = None
    kind: str = "setting"

    def __post_init__(self) -> None:
        if not self.name or not self.silence:
            raise ValueError("an axis needs a name and the silence it probes")
        if self.kind not in AXIS_KINDS:
            raise ValueError(f"axis {self.name!r}: kind {self.kind!r} is not one of {AXIS_KINDS}")
        object.__setattr__(self, "values", tuple(_plain(v) for v in self.values))
        if len(self.values) < 2:
            raise ValueError(f"axis {self.name!r}: a grid axis needs at least 2 values, got {len(self.values)}")
        if len({json.dumps(v) for v in self.values}) != len(self.values):
            raise ValueError(f"axis {self.name!r} lists a value twice: {self.values!r}")

    @property
    def open(self) -> bool:
        """Whether the paper leaves this setting open (states no value)."""
        return self.paper is None

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "values": list(self.values), "silence": self.silence,
                "paper": _plain(self.paper), "ours": _plain(self.ours), "kind": self.kind}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Axis:
        return cls(name=data["name"], values=tuple(data["values"]), silence=data["silence"],
                   paper=data.get("paper"), ours=data.get("ours"), kind=data.get("kind", "setting"))


@dataclass(frozen=True)
class WhyGrid:
    """The claim's rule at every point of a grid.

    Attributes
    ----------
    axes : tuple of Axis
    holds : ndarray of bool, shape ``[len(a.values) for a in axes]``
        Whether the claim's own rule holds at each point (applied over the ``n`` units there).
    n : int
        Independent units (seeds, networks, draws) behind each point.
    rule : str
        "the claim holds at a grid point when ...": the claim's rule as applied at each point.
    numbers : mapping of str to nested lists, optional
        Measured values per point (same shape as ``holds``, possibly with a trailing unit axis).
    title : str
        A few words on what the grid varies (named in the summary where a why has several grids).
    unit : str
        What one of the ``n`` units is ("seed", "network", "unit"), in the singular; where units share
        training (one ensemble on shared mini-batches) or a network, the unit says so.
    networks : str
        Whose networks the grid judges: ``"ours"`` or ``"authors"``.
    feasible : ndarray of bool, optional
        Which points can judge the claim at all (same shape as ``holds``; ``None``: every point). A point is
        infeasible where no model can do what the claim compares, by a bound computed from the system, never
        picked (e.g. a thrust bound below what the vehicle needs to follow the reference). Infeasible points
        stay in ``holds`` and the figure, but no count, summary or cause uses them.
    infeasible : str
        Why the excluded points are excluded, with the number that decides it (required when any is).
    """

    axes: tuple[Axis, ...]
    holds: np.ndarray
    n: int
    rule: str
    numbers: Mapping[str, Any] = field(default_factory=dict)
    title: str = ""
    unit: str = "seed"
    networks: str = "ours"
    feasible: np.ndarray | None = None
    infeasible: str = ""

    def __post_init__(self) -> None:
        holds = np.asarray(self.holds)
        shape = tuple(len(a.values) for a in self.axes)
        if not self.axes:
            raise ValueError("a why grid needs at least one axis")
        if holds.shape != shape:
            raise ValueError(f"holds has shape {holds.shape}, the axes give {shape}")
        if holds.dtype != bool:
            raise ValueError(f"holds must be booleans, got dtype {holds.dtype}")
        if int(self.n) < 1:
            raise ValueError(f"n must be at least 1, got {self.n}")
        if not self.rule:
            raise ValueError("a why grid states the rule it applies at each point")
        if self.networks not in ("ours", "authors"):
            raise ValueError(f"networks must be 'ours' or 'authors', got {self.networks!r}")
        feasible = np.ones(shape, bool) if self.feasible is None else np.asarray(self.feasible)
        if feasible.shape != shape or feasible.dtype != bool:
            raise ValueError(f"feasible must be booleans of the grid's shape {shape}, got {feasible.dtype} "
                             f"{feasible.shape}")
        if not feasible.any():
            raise ValueError("a why grid needs at least one feasible point")
        if not feasible.all() and not self.infeasible:
            raise ValueError("a grid that excludes points says why (infeasible), with the number that decides it")
        object.__setattr__(self, "holds", holds)
        object.__setattr__(self, "feasible", feasible)
        object.__setattr__(self, "numbers", {k: _plain(v) for k, v in self.numbers.items()})

    @property
    def held(self) -> int:
        """Feasible points where the rule holds."""
        return int((self.holds & self.feasible).sum())

    @property
    def counted(self) -> int:
        """Feasible points: those every count is over."""
        return int(self.feasible.sum())

    @property
    def excluded(self) -> int:
        return int(self.holds.size - self.counted)

    def count_text(self) -> str:
        """``holds at 5 of 8 points`` or, with excluded points, ``holds at 1 of 2 feasible points``."""
        return f"holds at {self.held} of {self.counted} {'feasible ' if self.excluded else ''}points"

    def holds_at_profile(self) -> bool | None:
        """Whether the rule holds at the paper profile's point (each axis at its ``ours``; every value of an axis
        without one): the grid must give there what the profile's counted reading gave. ``None`` where an axis's
        ``ours`` is not among its values (the profile's point is off the grid)."""
        at = []
        for a in self.axes:
            if a.ours is not None and a.ours not in a.values:
                return None
            at.append(slice(None) if a.ours is None else a.values.index(a.ours))
        return bool(np.all(self.holds[tuple(at)]))

    @property
    def mixed(self) -> bool:
        """The rule holds at some feasible point and fails at another."""
        return bool(0 < self.held < self.counted)

    def _along(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Along axis ``i``, over the feasible points of each line: (holds at every one, at some, has one)."""
        return ((self.holds | ~self.feasible).all(axis=i), (self.holds & self.feasible).any(axis=i),
                self.feasible.any(axis=i))

    def _mixed_along(self, kinds: tuple[str, ...], open_only: bool) -> bool:
        for i, axis in enumerate(self.axes):
            every, some, has = self._along(i)
            if axis.kind in kinds and (axis.open or not open_only) and ((every != some) & has).any():
                return True
        return False

    @property
    def mixed_on_open_axis(self) -> bool:
        """Along some setting axis the paper leaves open, the outcome changes with that axis alone."""
        return self._mixed_along(("setting",), open_only=True)

    @property
    def mixed_on_reading_axis(self) -> bool:
        """Along some reading or usage axis, the outcome changes with that axis alone."""
        return self._mixed_along(("reading", "usage"), open_only=False)

    def to_json(self) -> dict[str, Any]:
        return {"title": self.title, "axes": [a.to_json() for a in self.axes], "holds": self.holds.tolist(),
                "n": int(self.n), "rule": self.rule, "numbers": dict(self.numbers), "unit": self.unit,
                "networks": self.networks, "feasible": self.feasible.tolist(), "infeasible": self.infeasible}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> WhyGrid:
        return cls(axes=tuple(Axis.from_json(a) for a in data["axes"]), holds=np.asarray(data["holds"], bool),
                   n=int(data["n"]), rule=data["rule"], numbers=data.get("numbers") or {},
                   title=data.get("title", ""), unit=data.get("unit", "seed"), networks=data.get("networks", "ours"),
                   feasible=None if data.get("feasible") is None else np.asarray(data["feasible"], bool),
                   infeasible=data.get("infeasible", ""))


@dataclass(frozen=True)
class AuthorsCheck:
    """The claim's rule with the authors' trained networks in place of ours.

    Attributes
    ----------
    verdict : str
        The rule's verdict with the authors' networks.
    ours : str
        The same rule's verdict with ours, on the same evaluation.
    checks : mapping of str to bool
        The rule's checks with the authors' networks.
    networks : str
        Which of the release's networks (file names in its README).
    n : int
        Units behind the verdict (the release has one network per kind, five quadrotor runs).
    shared : str
        What those units share, where they are not independent (e.g. 5 units flying 2 MLPs); "" when nothing.
    """

    verdict: str
    ours: str
    checks: Mapping[str, bool]
    networks: str
    n: int = 1
    shared: str = ""

    def __post_init__(self) -> None:
        for v in (self.verdict, self.ours):
            if v not in _RANK:
                raise ValueError(f"unknown verdict {v!r}; verdicts: {', '.join(_RANK)}")
        object.__setattr__(self, "checks", {str(k): bool(v) for k, v in self.checks.items()})

    @property
    def better(self) -> bool:
        """The authors' networks give a better verdict than ours."""
        return _RANK[self.verdict] > _RANK[self.ours]

    def to_json(self) -> dict[str, Any]:
        return {"verdict": self.verdict, "ours": self.ours, "checks": dict(self.checks),
                "networks": self.networks, "n": int(self.n), "shared": self.shared}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> AuthorsCheck:
        return cls(verdict=data["verdict"], ours=data["ours"], checks=data["checks"], networks=data["networks"],
                   n=int(data.get("n", 1)), shared=data.get("shared", ""))


@dataclass(frozen=True)
class Cause:
    """One cause a why names: its letter (:data:`CAUSES`) and the run that backs it, in one sentence."""

    letter: str
    evidence: str

    def __post_init__(self) -> None:
        if self.letter not in CAUSES:
            raise ValueError(f"unknown cause {self.letter!r}; causes: {', '.join(CAUSES)}")

    @property
    def name(self) -> str:
        return CAUSES[self.letter]


def causes(*, grids: Sequence[WhyGrid], authors: AuthorsCheck | None = None,
           readings: Mapping[str, str] | None = None) -> tuple[Cause, ...]:
    """The causes (a)-(d) that the runs support, by the rule of the module docstring.

    Parameters
    ----------
    grids : sequence of WhyGrid
    authors : AuthorsCheck, optional
    readings : mapping of str to str, optional
        Reading name -> verdict (the counted reading and the others), from the paper-profile result.
    """
    found: list[Cause] = []
    by_reading = [g for g in grids if g.mixed_on_reading_axis]
    if (readings and len(set(readings.values())) > 1) or by_reading:
        parts = ["the readings differ: " + "; ".join(f"{k}: {v}" for k, v in readings.items())] \
            if readings and len(set(readings.values())) > 1 else []
        parts += [f"{_title(g)}: {g.count_text()}, along "
                  f"{', '.join(a.name for a in g.axes if a.kind != 'setting')}" for g in by_reading]
        found.append(Cause("a", "; ".join(parts)))
    mixed = [g for g in grids if g.networks == "ours" and g.mixed_on_open_axis]
    if mixed:
        found.append(Cause("b", "; ".join(f"{_title(g)}: {g.count_text()}" for g in mixed)))
    if authors is not None and authors.better:
        found.append(Cause("c", f"with the authors' networks ({authors.networks}) the rule reads "
                                f"{authors.verdict}; with ours, {authors.ours}"))
    # (d): nothing tried lets the claim hold -- no grid point (ours or the authors', over every setting, reading
    # and usage), no reading of the result, not the authors' networks
    if grids and not any(g.held for g in grids) \
            and not any(v in _HOLDS for v in (readings or {}).values()) \
            and (authors is None or authors.verdict not in _HOLDS):
        kinds = sorted({a.kind for g in grids for a in g.axes})
        what = "; ".join(f"{_title(g)}: at none of {g.counted} {'feasible ' if g.excluded else ''}points"
                         for g in grids)
        what += f" (axes: {', '.join(kinds)})"
        if readings:
            what += "; no reading holds (" + "; ".join(f"{k}: {v}" for k, v in readings.items()) + ")"
        if authors is not None:
            what += f"; nor with the authors' networks ({authors.verdict})"
        found.append(Cause("d", what))
    return tuple(found)


def _title(grid: WhyGrid) -> str:
    return grid.title or _axes_text(grid)


def _axes_text(grid: WhyGrid) -> str:
    return " x ".join(a.name for a in grid.axes)


def _ranges(axis: Axis, ok: np.ndarray, keep: np.ndarray | None = None, *, short: bool = False) -> str:
    """Where along a 1-D axis the rule holds, in words: ``holds for noise_std <= 0.003, fails at 0.01 and
    above``; ``holds at 4, 6, fails at 5``. Only the values where ``keep`` is true (the feasible ones) are
    read; ``short`` writes a line of more than 4 values that holds (or fails) throughout as ``holds at all 12
    level values``."""
    keep = np.ones(len(axis.values), bool) if keep is None else np.asarray(keep, bool)
    vals = [v for v, k in zip(axis.values, keep) if k]
    ok = np.asarray([o for o, k in zip(ok, keep) if k], bool)
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals)
    held = [v for v, o in zip(vals, ok) if o]
    failed = [v for v, o in zip(vals, ok) if not o]
    if len(vals) == 1:
        return f"{'holds' if held else 'fails'} at {axis.name} = {_text(vals[0])}"
    if not failed or not held:
        word = "holds" if not failed else "fails"
        if short and len(vals) > 4:
            return f"{word} at all {len(vals)} {axis.name} values"
        return f"{word} at every {axis.name} ({', '.join(_text(v) for v in vals)})"
    if numeric and vals == sorted(vals):
        k = int(np.argmin(ok)) if ok[0] else int(np.argmax(ok))
        if ok[0] and not ok[k:].any():
            return f"holds for {axis.name} <= {_text(vals[k - 1])}, fails at {_text(vals[k])} and above"
        if not ok[0] and ok[k:].all():
            return f"fails for {axis.name} <= {_text(vals[k - 1])}, holds at {_text(vals[k])} and above"
    return (f"holds at {axis.name} = {', '.join(_text(v) for v in held)}; "
            f"fails at {', '.join(_text(v) for v in failed)}")


def _grid_line(grid: WhyGrid) -> str:
    """A grid in words: its count (over feasible points, the excluded ones counted and explained), then for a
    one-axis grid where it holds; for two axes, the axis that alone decides or else every slice along the
    shorter axis (the profile's marked "ours"); for more, the slices through the profile's point."""
    feasible = grid.feasible
    if len(grid.axes) == 1:
        line = _ranges(grid.axes[0], grid.holds, feasible)
        return f"{line} ({grid.excluded} points excluded: {grid.infeasible})" if grid.excluded else line
    excluded = f"; {grid.excluded} points excluded: {grid.infeasible}" if grid.excluded else ""
    parts = [f"{grid.count_text()} ({_axes_text(grid)}{excluded})"]
    decided = False
    for i, axis in enumerate(grid.axes):
        other = tuple(j for j in range(grid.holds.ndim) if j != i)
        every, some, has = grid._along(other)
        if (every[has] == some[has]).all() and some.any() and not every[has].all():  # this axis alone decides
            parts.append(_ranges(axis, every, has))
            decided = True
    if decided:
        return "; ".join(parts)
    if len(grid.axes) == 2:  # every slice along the shorter axis, so that no slice is left out
        j = 1 if len(grid.axes[1].values) <= len(grid.axes[0].values) else 0
        i, by = 1 - j, grid.axes[j]
        for k, v in enumerate(by.values):
            at = (slice(None), k) if j == 1 else (k, slice(None))
            if not feasible[at].any():
                continue
            mark = " (ours)" if by.ours is not None and v == by.ours else ""
            parts.append(f"at {by.name} = {_text(v)}{mark}: "
                         f"{_ranges(grid.axes[i], grid.holds[at], feasible[at], short=True)}")
        return "; ".join(parts)
    for i, axis in enumerate(grid.axes):
        if all(a.ours in a.values for j, a in enumerate(grid.axes) if j != i):  # the slice through ours
            at = tuple(slice(None) if j == i else a.values.index(a.ours) for j, a in enumerate(grid.axes))
            where = ", ".join(f"{a.name} = {_text(a.ours)}" for j, a in enumerate(grid.axes) if j != i)
            parts.append(f"at {where}: {_ranges(axis, grid.holds[at], feasible[at])}")
    return "; ".join(parts)


def _plural(unit: str, n: int) -> str:
    """``seed`` -> ``seeds``; ``seed (one ensemble)`` -> ``seeds (one ensemble)``; unchanged for n = 1."""
    if n == 1:
        return unit
    head, sep, rest = unit.partition(" (")
    return f"{head}s{sep}{rest}"


def summary(grids: Sequence[WhyGrid], authors: AuthorsCheck | None = None) -> str:
    """The one line under **Why** on the scoreboard, from the numbers alone.

    >>> g = WhyGrid(axes=(Axis("noise_std", (0.001, 0.003, 0.01, 0.03), "noise not given"),),
    ...             holds=np.array([True, True, False, False]), n=5, rule="decay beats the plain ODE")
    >>> summary([g])
    'holds for noise_std <= 0.003, fails at 0.01 and above (5 seeds per point)'
    """
    named = len(grids) > 1  # several grids: each line says which
    lines = [f"{g.title + ': ' if named and g.title else ''}{_grid_line(g)} "
             f"({g.n} {_plural(g.unit, g.n)} per point)" for g in grids]
    if authors is not None:
        shared = f"; n = {authors.n}, {authors.shared}" if authors.shared else ""
        lines.append(f"with the authors' networks: {authors.verdict} (ours: {authors.ours}{shared})")
    return "; ".join(lines)


@dataclass(frozen=True)
class Why:
    """The why of one claim: its ``claim`` ID and ``verdict`` in the paper profile (what is explained;
    ``"reproduced"`` for a thin margin), the runs behind it (``grids``: :class:`WhyGrid`, ``authors``:
    :class:`AuthorsCheck` or None; at least one), the ``readings`` (reading -> verdict, from the paper-profile
    result; empty for a claim with one reading), the grid ``figure`` (relative to the task's output folder, or
    None) and a ``note`` in the notebook's words (shown under the numbers; it never decides anything).
    """

    claim: str
    verdict: str
    grids: tuple[WhyGrid, ...] = ()
    authors: AuthorsCheck | None = None
    readings: Mapping[str, str] = field(default_factory=dict)
    figure: str | None = None
    note: str = ""

    def __post_init__(self) -> None:
        if self.verdict not in _RANK:
            raise ValueError(f"unknown verdict {self.verdict!r}; verdicts: {', '.join(_RANK)}")
        if not self.grids and self.authors is None:
            raise ValueError(f"why of {self.claim}: it needs a grid or the authors' networks (a run), not prose")
        object.__setattr__(self, "grids", tuple(self.grids))
        object.__setattr__(self, "readings", dict(self.readings))

    @property
    def causes(self) -> tuple[Cause, ...]:
        return causes(grids=self.grids, authors=self.authors, readings=self.readings)

    @property
    def summary(self) -> str:
        return summary(self.grids, self.authors)

    def to_json(self) -> dict[str, Any]:
        return {"claim": self.claim, "verdict": self.verdict, "grids": [g.to_json() for g in self.grids],
                "authors": None if self.authors is None else self.authors.to_json(),
                "readings": dict(self.readings), "figure": self.figure, "note": self.note,
                # derived, stored for readers of the file; recomputed (and compared) on reading
                "summary": self.summary, "causes": [[c.letter, c.evidence] for c in self.causes]}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Why:
        why = cls(claim=data["claim"], verdict=data["verdict"],
                  grids=tuple(WhyGrid.from_json(g) for g in data.get("grids") or ()),
                  authors=None if data.get("authors") is None else AuthorsCheck.from_json(data["authors"]),
                  readings=data.get("readings") or {}, figure=data.get("figure"), note=data.get("note", ""))
        stored = [list(c) for c in data.get("causes", [])]
        if "causes" in data and stored != [[c.letter, c.evidence] for c in why.causes]:
            raise ValueError(f"why of {why.claim}: the stored causes differ from the ones its runs give")
        return why


def write_whys(out_dir: str | os.PathLike[str], whys: Sequence[Why]) -> Path:
    """Write ``whys.json`` into ``out_dir`` (atomically); one why per claim."""
    ids = [w.claim for w in whys]
    if len(set(ids)) != len(ids):
        raise ValueError(f"two whys for one claim: {sorted(i for i in ids if ids.count(i) > 1)}")
    path = Path(out_dir) / WHYS_FILENAME
    with atomic_write(path, "w") as fh:
        json.dump({"whys": [w.to_json() for w in whys]}, fh, indent=1, allow_nan=False,
                  default=lambda v: None if isinstance(v, float) and math.isnan(v) else _plain(v))
    return path


def read_whys(path: str | os.PathLike[str]) -> dict[str, Why]:
    """Read a ``whys.json``: claim ID -> :class:`Why`; a malformed file raises ``ValueError`` naming it."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return {w.claim: w for w in (Why.from_json(d) for d in data["whys"])}
    except (KeyError, TypeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not a whys file ({exc!r})") from exc


def reproduced(results: Any) -> np.ndarray:
    """Where each claim result of a grid (nested lists of :class:`~fnnbook.results.ClaimResult`) reads
    *reproduced*: the ``holds`` of a :class:`WhyGrid` whose points are judged by the claim's own rule."""
    return np.array([[r.verdict == "reproduced" for r in row] for row in results], dtype=bool)
