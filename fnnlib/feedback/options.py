r"""The option objects of the feedback functions: the gain schedule of Eq. (11), the rollout's solver, a measurement.

Both are small frozen dataclasses that check themselves on construction, so a wrong value is refused with a
clear error before any work (before a model is evaluated or a tuner started):

* :class:`Gains`: the base gain :math:`L` and the decay rate :math:`\beta` of Eq. (11),
  :math:`L_i = L e^{-\beta i}`, the schedule of the cascade of Sec. 3.3 and of the linear feedback of
  Eqs. (7)-(8) (``allow_unstable`` accepts a gain failing Theorem 1 or Eq. (25), to show divergence).
* :class:`Solver`: the torchdiffeq method of the open-loop rollout of Eq. (2) and, for an adaptive one, its
  tolerances.
* :class:`Measurement`: :math:`y_k = C x_k` (or :math:`h(x_k)`), the missing samples (``mask``), the first
  estimate :math:`\hat x_0` (``x0``) and the sample times ``t``. The measurement model (``C``, ``x0``) belongs
  to the observer that reads it (:class:`~fnnlib.feedback.measured.MeasuredFeedback`); the record's gaps and
  times (``mask``, ``t``) go with the record to the functions that run on it
  (:func:`~fnnlib.feedback.cascade.cascade_predict`, :func:`~fnnlib.feedback.tuning.tune_gains`).

Checks that need the data or the step (the shape of ``C`` against the measurements, Theorem 1 and Eq. (25)
for ``L`` at ``Ts``) are made where those are known, still before any work.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor

from fnnlib.feedback.gains import GainError, as_gain

#: A measurement function ``h(x)``, ``x`` (batch, n) -> (batch, p).
OutputMap = Callable[[Tensor], Tensor]


@dataclass(frozen=True, eq=False)
class Gains:
    r"""The gain schedule of Eq. (11): base gain ``L`` and decay rate ``beta``, layer ``i`` using
    :math:`L_i = L e^{-\beta i}`.

    ``L``: a scalar (``L I``), a vector (n,) (diagonal) or an (n, n) matrix, stored as a float64 tensor;
    ``beta``: finite and >= 0 (0 keeps every layer at ``L``); ``allow_unstable``: accept a gain that is not
    positive definite (Theorem 1) or has :math:`\rho(I - T_s L) \ge 1` (Eq. (25)), which are checked where
    ``Ts`` is known (:func:`~fnnlib.feedback.gains.check_gain`). Refuses text, NaN, infinities, a negative
    or non-finite ``beta`` and a non-square matrix on construction.
    """

    L: Tensor | float
    beta: float = 0.0
    allow_unstable: bool = False

    def __post_init__(self):
        L = as_gain(self.L)  # refuses text and what is no number with a TypeError naming L
        try:
            L = torch.as_tensor(L, dtype=torch.float64)
        except (TypeError, ValueError, RuntimeError):
            raise TypeError(f"Gains.L must be a number, a vector or a matrix of numbers, got {self.L!r}") from None
        if L.ndim > 2 or (L.ndim == 2 and L.shape[0] != L.shape[1]) or L.numel() == 0:
            raise ValueError(f"Gains.L must be a scalar, a vector (n,) or a square matrix (n, n), got shape "
                             f"{tuple(L.shape)}")
        if not bool(torch.isfinite(L).all()):
            raise GainError(f"Gains.L holds NaN or infinite entries: {L.tolist()}")
        object.__setattr__(self, "L", L)
        if isinstance(self.beta, bool) or not isinstance(self.beta, (int, float)) and not (
                isinstance(self.beta, Tensor) and self.beta.numel() == 1):
            raise TypeError(f"Gains.beta must be one number (the decay rate of Eq. (11)), got {self.beta!r}")
        beta = float(self.beta)
        if not (math.isfinite(beta) and beta >= 0):
            raise ValueError(f"Gains.beta: the decay rate beta must be finite and >= 0 (Eq. (11)), got "
                             f"{self.beta!r}")
        object.__setattr__(self, "beta", beta)
        if not isinstance(self.allow_unstable, bool):
            raise TypeError(f"Gains.allow_unstable must be a bool, got {self.allow_unstable!r}")

    @classmethod
    def sweep(cls, L, beta=0.0, *, allow_unstable: bool = False) -> tuple[Gains, ...]:
        """Gain schedules for :func:`~fnnlib.feedback.cascade.cascade_sweep`: ``L`` a scalar, G scalar gains (G,)
        or G diagonal gains (G, n), paired with the decay rates ``beta`` (a scalar or (B,)) by broadcasting (one
        of either, or as many of each)."""
        Lt = torch.as_tensor(as_gain(L), dtype=torch.float64)
        if Lt.ndim == 0:
            Lt = Lt.reshape(1)
        if Lt.ndim > 2 or Lt.shape[0] == 0:
            raise ValueError(f"a gain sweep L must be a scalar, shape (G,) (scalar gains) or (G, n) (diagonal "
                             f"gains); got shape {tuple(Lt.shape)}")
        betas = torch.as_tensor(beta, dtype=torch.float64).reshape(-1)
        G, B = Lt.shape[0], betas.shape[0]
        if B == 0 or (B != 1 and G != 1 and B != G):
            raise ValueError(f"{G} gains and {B} decay rates do not pair up (give one of either, or as many)")
        return tuple(cls(Lt[0 if G == 1 else g], float(betas[0 if B == 1 else g]), allow_unstable=allow_unstable)
                     for g in range(max(G, B)))


@dataclass(frozen=True, eq=False)
class Measurement:
    r"""How a record was measured: :math:`y_k = C x_k` (or :math:`h(x_k)`) at the times ``t``, with gaps: what the
    feedback of Eqs. (7)-(8) corrects with.

    ``C``: a (p, n) matrix, a callable ``h(x)`` (batch, n) -> (batch, p), or ``None`` (every state measured);
    ``mask``: a boolean tensor (..., T) or (..., T, p), ``False`` where no sample was taken (a NaN in the
    record means the same); ``x0``: the first estimate :math:`\hat x_0` (n,) (default: the least-squares state
    of the first sample; required with ``h``, which cannot be inverted); ``t``: the sample times (..., T),
    strictly increasing, when they are uneven (:mod:`fnnlib.feedback.sampling`; then no ``Ts`` is given).

    Checked on construction (types, finiteness, ``C``'s and ``x0``'s shapes and the times' order); shapes
    against the record are checked where it is known.
    """

    C: Tensor | OutputMap | None = None
    mask: Tensor | None = None
    x0: Tensor | None = None
    t: Tensor | None = None

    def __post_init__(self):
        C = self.C
        if C is not None and not (callable(C) and not isinstance(C, Tensor)):
            C = torch.as_tensor(C)
            if C.is_complex() or not (C.is_floating_point() or C.dtype in (torch.int32, torch.int64)):
                raise TypeError(f"Measurement.C must be a real (p, n) matrix or a callable h(x), got dtype {C.dtype}")
            if C.ndim != 2 or C.numel() == 0:
                raise ValueError(f"Measurement.C must be a (p, n) matrix (p outputs of n states), got shape "
                                 f"{tuple(C.shape)}")
            if not bool(torch.isfinite(C).all()):
                raise ValueError("Measurement.C holds NaN or infinite entries")
            object.__setattr__(self, "C", C.to(torch.float64))
        if self.mask is not None and (not isinstance(self.mask, Tensor) or self.mask.dtype != torch.bool
                                      or self.mask.ndim < 1):
            raise TypeError(f"Measurement.mask must be a boolean tensor of shape (..., T) or (..., T, p), got "
                            f"{type(self.mask).__name__} {getattr(self.mask, 'dtype', '')}")
        if self.x0 is not None:
            x0 = torch.as_tensor(self.x0)
            n = C.shape[1] if isinstance(C, Tensor) else None
            if (not (x0.is_floating_point() or x0.dtype in (torch.int32, torch.int64)) or x0.ndim != 1
                    or not x0.numel() or (n is not None and x0.shape[0] != n)):
                want = "(n,)" if n is None else f"({n},)"
                raise ValueError(f"Measurement.x0 must be a real vector of shape {want} (one entry per state of C), "
                                 f"got shape {tuple(x0.shape)}")
            if not bool(torch.isfinite(x0).all()):
                raise ValueError(f"Measurement.x0 holds NaN or infinite entries: {x0.tolist()}")
        elif self.C is not None and callable(self.C) and not isinstance(self.C, Tensor):
            raise ValueError("with a measurement function h give the first estimate x0 (n,): h cannot be inverted, "
                             "and its Jacobian at x0 is what a gain is checked against")
        t = self.t
        if t is not None:
            if not isinstance(t, Tensor) or not t.is_floating_point() or t.ndim < 1:
                raise TypeError(f"Measurement.t must be a floating-point tensor of shape (..., T), got "
                                f"{type(t).__name__} {getattr(t, 'dtype', '')}")
            if t.shape[-1] < 2:
                raise ValueError("Measurement.t needs at least 2 sample times to define a step")
            if not bool(torch.isfinite(t).all()):
                raise ValueError("Measurement.t: the sample times t hold a NaN or an infinite time; drop that "
                                 "sample instead")
            if bool((torch.diff(t, dim=-1) <= 0).any()):
                raise ValueError("Measurement.t: the sample times t must be strictly increasing; sort the record "
                                 "or drop repeated times")



#: torchdiffeq's fixed-step methods: they step at ``Ts`` (or each interval) and take no tolerances.
FIXED_METHODS = ("euler", "midpoint", "rk4")
#: torchdiffeq's adaptive methods: they take ``rtol`` and ``atol``.
ADAPTIVE_METHODS = ("dopri5", "dopri8", "bosh3", "fehlberg2", "adaptive_heun")


@dataclass(frozen=True)
class Solver:
    """How the open-loop neural ODE of Eq. (2) is integrated by :func:`~fnnlib.feedback.rollout.rollout_predict`.

    ``method``: a torchdiffeq method; a fixed-step one (``"euler"``, the discretisation the cascade uses,
    ``"midpoint"``, ``"rk4"``, ...) steps at the sample step, an adaptive one (``"dopri5"``, ...) integrates to
    the tolerances ``rtol`` and ``atol`` (default 1e-7 and 1e-9), which a fixed-step method refuses.
    """

    method: str = "euler"
    rtol: float | None = None
    atol: float | None = None

    def __post_init__(self):
        if self.method not in FIXED_METHODS + ADAPTIVE_METHODS:
            raise ValueError(f"Solver.method must be one of {FIXED_METHODS + ADAPTIVE_METHODS}, got {self.method!r}")
        adaptive = self.method in ADAPTIVE_METHODS
        for name, default in (("rtol", 1e-7), ("atol", 1e-9)):
            v = getattr(self, name)
            if v is None:
                object.__setattr__(self, name, default if adaptive else None)
                continue
            if not adaptive:
                raise ValueError(f"Solver.{name}: the fixed-step method {self.method!r} takes no tolerance (it steps "
                                 "at the sample step); tolerances are for the adaptive methods")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ValueError(f"Solver.{name} must be a finite number > 0, got {v!r}")
            object.__setattr__(self, name, float(v))

    @property
    def fixed(self) -> bool:
        """Whether the method steps at a fixed step (and takes no tolerance)."""
        return self.method in FIXED_METHODS


def record_sampling(measurement: Measurement | None) -> tuple[Tensor | None, Tensor | None]:
    """A record's sample times and gaps, ``(t, mask)``, from the ``measurement`` a function on records takes.

    Its ``C`` and ``x0`` describe the first layer's observer and are given to it
    (:class:`~fnnlib.feedback.measured.MeasuredFeedback`), so a function on records refuses them here, before
    any work, rather than ignore them.
    """
    if measurement is None:
        return None, None
    if not isinstance(measurement, Measurement):
        raise TypeError(f"measurement must be a fnnlib.Measurement, got {type(measurement).__name__}")
    if measurement.C is not None or measurement.x0 is not None:
        raise ValueError("the measurement's C and x0 belong to the first layer's observer: build "
                         "MeasuredFeedback(f, Ts, L=..., measurement=Measurement(C=..., x0=...)) and pass it as "
                         "observer=, with the record's mask and t in this measurement")
    return measurement.t, measurement.mask
