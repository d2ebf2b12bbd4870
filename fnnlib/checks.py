"""Plain checks on setting values: each names the setting and says what it needs, before any work starts.

Every check takes the setting's ``name`` and ``value`` (and, for some, the bound) and returns the value or
raises ``ValueError`` naming it, so a caller can run them over a table of settings:

>>> integer("iterations", 0, minimum=1)
Traceback (most recent call last):
...
ValueError: iterations must be an integer >= 1, got 0
>>> stable_gain("L", 20.0, n=2, Ts=0.01, N=50, beta=0.02)
20.0
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any

from fnnlib.data.bottle import DataError
from fnnlib.io import file_sha256

__all__ = ["MissingDataError", "boolean", "colon_grid", "data_files", "distinct_seeds", "finite", "horizon", "integer",
           "layer_widths", "nonnegative", "number_list", "numbers", "one_of", "positive", "seed", "some_of", "stable_gain"]


class MissingDataError(DataError):
    """Data files a setting needs are not in the data directory (not an error of the setting itself)."""


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def integer(name: str, value: Any, *, minimum: int = 0) -> int:
    """An integer (not a bool) ``>= minimum``: a size, a count, an iteration number."""
    if not (isinstance(value, int) and not isinstance(value, bool) and value >= minimum):
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return value


def finite(name: str, value: Any) -> float:
    """A finite number (a gain, before :func:`stable_gain` checks it against the step)."""
    if not _is_number(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return value


def positive(name: str, value: Any) -> float:
    """A finite number ``> 0``: a step ``Ts``, a learning rate, a tolerance, a factor."""
    if not (_is_number(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return value


def nonnegative(name: str, value: Any) -> float:
    """A finite number ``>= 0``: a decay rate ``beta``, a variance, a spread."""
    if not (_is_number(value) and value >= 0):
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    return value


def boolean(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return value


def one_of(name: str, value: Any, choices: Collection[str]) -> Any:
    """One of a few names (an ODE solver, an activation, an optimizer)."""
    if value not in choices:
        raise ValueError(f"{name} must be one of {', '.join(sorted(map(str, choices)))}; got {value!r}")
    return value


def some_of(name: str, value: Any, choices: Collection[str]) -> list[Any]:
    """One or more of a few names, none twice (the costs a flight test compares)."""
    if (not isinstance(value, list) or not value or len(set(value)) != len(value)
            or not all(v in choices for v in value)):
        raise ValueError(f"{name} must list one or more of {', '.join(sorted(choices))}, none twice; got {value!r}")
    return value


def numbers(name: str, value: Any, n: int | None = None, *, minimum: float | None = None) -> list[float]:
    """A list of ``n`` finite numbers (any length >= 1 when ``n`` is None), each ``>= minimum`` if given."""
    if (not isinstance(value, (list, tuple)) or not value or (n is not None and len(value) != n)
            or not all(_is_number(v) and (minimum is None or v >= minimum) for v in value)):
        size = f"{n} finite numbers" if n is not None else "at least one finite number"
        bound = f", each >= {minimum:g}" if minimum is not None else ""
        raise ValueError(f"{name} must list {size}{bound}, got {value!r}")
    return list(value)


def number_list(name: str, value: Any, *, minimum: float | None = None, distinct: bool = False) -> list[float]:
    """A non-empty list of finite numbers (a sweep), each ``>= minimum``; with ``distinct``, no value twice."""
    numbers(name, value, minimum=minimum)
    if distinct and len(set(value)) != len(value):
        raise ValueError(f"{name} lists a value twice: {value!r}")
    return list(value)


def layer_widths(name: str, value: Any) -> list[int]:
    """Hidden layer widths: a non-empty list of integers >= 1."""
    if (not isinstance(value, (list, tuple)) or not value
            or not all(isinstance(h, int) and not isinstance(h, bool) and h >= 1 for h in value)):
        raise ValueError(f"{name} must list layer widths >= 1, got {value!r}")
    return list(value)


def seed(name: str, value: Any) -> int:
    """A random seed: an integer >= 0 (numpy and torch refuse negative ones)."""
    return integer(name, value, minimum=0)


def distinct_seeds(name: str, value: Any, *, at_least: int = 1) -> list[int]:
    """At least ``at_least`` distinct seeds (a paired comparison over seeds needs two, claim B2)."""
    if (not isinstance(value, list) or len(value) < at_least or len(set(value)) != len(value)
            or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in value)):
        raise ValueError(f"{name} must list at least {at_least} distinct integers >= 0, got {value!r}")
    return value


def colon_grid(name: str, value: Any) -> list[float]:
    """A non-empty grid ``[start, step, stop]`` (MATLAB's ``start:step:stop``, :func:`fnnlib.paper.sweeps.colon_range`)."""
    from fnnlib.paper.sweeps import colon_range  # noqa: PLC0415 (loads torch)

    numbers(name, value, 3)
    try:
        colon_range(*value)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from exc
    return value


def stable_gain(name: str, L: Any, *, n: int, Ts: float, N: int | None = None, beta: float = 0.0) -> Any:
    r"""A gain Theorem 1 and Eq. (25) accept (:func:`fnnlib.feedback.check_gain`), decayed over ``N`` layers by
    Eq. (11) (:func:`fnnlib.feedback.decayed_gains`) when ``N`` is given. Raises ``GainError`` (a ValueError)."""
    from fnnlib.feedback import GainError, check_gain, decayed_gains  # noqa: PLC0415 (loads torch)

    try:
        M = check_gain(L, n, Ts)
        if N is not None:
            decayed_gains(M, N, beta)
    except GainError as exc:
        raise GainError(f"{name}: {exc}") from exc
    return L


def horizon(name: str, N: Any, *, below: int, below_name: str) -> int:
    """A prediction horizon ``1 <= N < below`` (it must fit in the ``below`` samples it predicts over)."""
    if not (isinstance(N, int) and not isinstance(N, bool) and 1 <= N < below):
        raise ValueError(f"{name} must be an integer with 1 <= {name} < {below_name} = {below}, got {N!r}")
    return N


def data_files(folder: str | Path, digests: Mapping[str, str], *, how_to_get: str = "") -> list[Path]:
    """The files ``digests`` names (file name -> SHA-256) in ``folder``, each with its pinned SHA-256.

    Raises
    ------
    MissingDataError
        Naming the files that are not there (``how_to_get`` says where to find them).
    DataError
        Naming a file whose SHA-256 is not the pinned one (corrupt, or another file).
    """
    folder = Path(folder)
    missing = [f for f in digests if not (folder / f).is_file()]
    if missing:
        raise MissingDataError(f"data missing: {', '.join(missing)} not in {folder}. {how_to_get}".rstrip())
    for name, digest in digests.items():
        got = file_sha256(folder / name)
        if got != digest:
            raise DataError(f"data file {folder / name} has SHA-256 {got}, not the pinned {digest} (corrupt or "
                            f"another file). {how_to_get}".rstrip())
    return [folder / f for f in digests]


