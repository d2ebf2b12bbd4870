"""The checks the notebooks' settings share, each written once: ``check(name, value)`` raises ``ValueError``
naming the setting; and the helpers of the checks between values (``need``, ``gain``, ``horizon``).

Built from the plain checks of :mod:`fnnlib.checks`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from functools import partial
from typing import Any

from fnnlib import checks as C
from fnnlib.models import ACTIVATIONS

Check = Callable[[str, Any], Any]


def need(condition: bool, message: str) -> None:
    """Raise ``ValueError(message)`` unless ``condition``."""
    if not condition:
        raise ValueError(message)


def vec(n: int | None = None, minimum: float | None = None) -> Check:
    """``n`` finite numbers (any number of them when ``n`` is None), each >= ``minimum`` when given."""
    return partial(C.numbers, n=n, minimum=minimum)


def choice(*choices: str) -> Check:
    """One of ``choices``."""
    return partial(C.one_of, choices=choices)


def some(*choices: str) -> Check:
    """One or more distinct ones of ``choices``."""
    return partial(C.some_of, choices=choices)


def lazy_choice(choices: Callable[[], tuple[str, ...]]) -> Check:
    """One of the names ``choices()`` gives when the check runs (a library loaded only then)."""
    return lambda name, value: C.one_of(name, value, choices())


def _ode_methods() -> tuple[str, ...]:
    from torchdiffeq._impl.odeint import SOLVERS  # noqa: PLC0415 (torchdiffeq's solver names; no public list)

    return tuple(SOLVERS)


def cvxpy_solvers() -> tuple[str, ...]:
    """The QP solvers cvxpy has installed."""
    import cvxpy  # noqa: PLC0415

    return tuple(cvxpy.installed_solvers())


def from_mpc(attribute: str, module: str) -> Check:
    """One of the names a table of :mod:`fnnlib.quadrotor.mpc` holds (imported on use: the MPC loads numba)."""
    return lazy_choice(lambda: tuple(getattr(importlib.import_module(f"fnnlib.quadrotor.mpc.{module}"), attribute)))


def changes(name: str, value: Any) -> Mapping[str, Any]:
    """One-factor changes to a training recipe: a mapping (its keys are checked with the other settings)."""
    if not isinstance(value, Mapping):
        raise ValueError(f"{name} must be a mapping of changes, got {value!r}")
    return value


def fraction(name: str, value: Any) -> float:
    """A share in [0, 1), e.g. of the samples a sensor loses."""
    share = C.nonnegative(name, value)
    if share >= 1:
        raise ValueError(f"{name} must lie in [0, 1), got {value!r}")
    return share


def synthetic_sizes(name: str, value: Any) -> list[int]:
    """``[training throws, test throws, samples per throw]`` of the synthetic stand-in: >= 1, >= 1, >= 2."""
    if not (isinstance(value, list) and len(value) == 3):
        raise ValueError(f"{name} must be [training throws, test throws, samples per throw], got {value!r}")
    for what, size, minimum in zip(("training throws", "test throws", "samples per throw"), value, (1, 1, 2)):
        C.integer(f"{name} ({what})", size, minimum=minimum)
    return value


def why_axis(name: str, value: Any, *, positive: bool = False) -> list[float]:
    """A why grid's axis: at least 2 distinct finite numbers (each > 0 with ``positive``)."""
    values = C.number_list(name, value, distinct=True)
    need(len(values) >= 2, f"{name}: a grid axis needs at least 2 values, got {value!r}")
    need(not positive or min(values) > 0, f"{name} must list values > 0, got {value!r}")
    return values


def horizons(name: str, value: Any) -> list[int]:
    """Prediction horizons: distinct integers >= 1."""
    values = C.number_list(name, value, minimum=1.0, distinct=True)
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
        raise ValueError(f"{name} must list distinct integers >= 1, got {value!r}")
    return [int(v) for v in values]


SEED, BOOL, POS, NONNEG = C.seed, C.boolean, C.positive, C.nonnegative
SEEDS1, SEEDS2 = partial(C.distinct_seeds, at_least=1), partial(C.distinct_seeds, at_least=2)
N0, N1, N2 = (partial(C.integer, minimum=m) for m in (0, 1, 2))
WIDTHS, GRID = C.layer_widths, C.colon_grid  # hidden widths; a [start, step, stop] grid
SPIRAL3 = vec(3)  # (omega, eta, eps) of the spiral Eq. (26)
X0 = vec(2)
ACT = choice(*ACTIVATIONS)
METHOD = lazy_choice(_ode_methods)
OPTIMIZER = choice("rmsprop", "adam")
SWEEP0 = partial(C.number_list, minimum=0.0, distinct=True)
GAIN = C.finite  # a gain L: stable at the step Ts (each class's check_relations)
GAINS = C.number_list  # scalar gains, each stable at the step Ts (check_relations)
GRID0 = vec(minimum=0.0)  # a list of gains (or decay rates) >= 0
WHY_AXIS, WHY_AXIS_POS = why_axis, partial(why_axis, positive=True)


def gain(s: Any, n: int, Ts: float, N: int | None, *, L: str = "L", beta: str = "beta") -> None:
    """A gain that Theorem 1 / Eq. (25) accept at the step ``Ts``, and a decay Eq. (11) accepts over N layers."""
    C.stable_gain(L, getattr(s, L), n=n, Ts=Ts, N=N, beta=getattr(s, beta, 0.0))


def horizon(s: Any) -> None:
    """A horizon ``N`` shorter than the trajectory (``n_samples``)."""
    C.horizon("N", s.N, below=s.n_samples, below_name="n_samples")


def why_grid(s: Any, *names: str) -> None:
    """A why grid's axes: at least 2 values each (a grid passes through the profile's point and leaves it)."""
    for name in names:
        need(len(getattr(s, name)) >= 2, f"{name} must list at least 2 values (a grid axis), got {getattr(s, name)}")
