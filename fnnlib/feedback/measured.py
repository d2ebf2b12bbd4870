r"""The linear feedback of Eqs. (7)-(8) when only :math:`y = C x` (+ noise) is measured.

With a full-state measurement (:math:`C = I`) the paper evaluates the learned field at the measurement. With
a partial one it cannot: the field is evaluated at the estimate, and the gain :math:`L` (n x p) acts on the
output error,

.. math::
    \hat f_k = f_{neural}(\hat x_k, u_k) + L\,(y_k - C\hat x_k), \qquad
    \hat x_{k+1} = \hat x_k + T_s \hat f_k,

a discrete Luenberger observer on the learned model. Linearised at a Jacobian :math:`A = \partial f/\partial x`
its error obeys :math:`\tilde x_{k+1} = (I + T_s(A - LC))\tilde x_k + T_s\Delta f_k`, the analogue of Eq. (25).
:func:`check_output_gain` checks that matrix's spectral radius and the detectability of :math:`(I + T_s A, C)`;
without a Jacobian it can only check :math:`\rho(I - T_s L C) < 1`, which needs every state measured
(:math:`LC` of full rank).
"""

from __future__ import annotations

import torch
from torch import Tensor

from fnnlib._validation import check_positive
from fnnlib.feedback.decay import check_N
from fnnlib.feedback.gains import GainError, spectral_radius
from fnnlib.feedback.gains import as_gain
from fnnlib.feedback.gaps import first_layer, layer_loop, measure_fn, start_state
from fnnlib.feedback.layer import eval_field, shift_inputs
from fnnlib.feedback.measurement import (
    DetectabilityError,
    check_detectable,
    check_measurements,
    check_output_matrix,
    output_jacobian,
)
from fnnlib.feedback.options import Measurement
from fnnlib.feedback.sampling import Steps, check_times, longest, row_steps
from fnnlib.feedback.types import Estimate, VectorField

F64 = torch.float64


def check_output_gain(L: Tensor, C: Tensor, Ts: float, *, A: Tensor | None = None,
                      allow_unstable: bool = False) -> tuple[Tensor, Tensor]:
    r"""Validate an output-feedback gain ``L`` (n, p) for measurements ``y = C x``, ``C`` (p, n); float64 copies.

    * With the model's Jacobian ``A`` (n, n) (continuous time, e.g. at an operating point): the pair
      :math:`(I + T_s A, C)` must be detectable (every mode with :math:`|\lambda| \ge 1` observable, PBH
      test), else no gain helps; and :math:`\rho(I + T_s(A - LC)) < 1`.
    * Without ``A``: :math:`\rho(I - T_s L C) < 1` (the model's own dynamics neglected, as Eq. (25)
      does); with fewer measurements than states :math:`LC` is singular and this is impossible, so pass ``A``.

    Raises :class:`~fnnlib.feedback.gains.GainError` naming what fails, unless ``allow_unstable``
    (shapes are always checked).
    """
    Ts = check_positive(Ts, name="Ts")
    L_shape = tuple(torch.as_tensor(L).shape)
    C = check_output_matrix(C, L_shape[0]) if len(L_shape) == 2 else torch.as_tensor(C, dtype=F64)
    if C.ndim != 2:
        raise ValueError(f"C must be a (p, n) matrix, got shape {tuple(C.shape)}")
    p, n = C.shape
    L = torch.as_tensor(L, dtype=F64)
    if L.shape != (n, p):
        raise ValueError(f"output gain L must have shape (n, p) = ({n}, {p}) for C of shape ({p}, {n}), "
                         f"got {tuple(L.shape)}")
    if not (bool(torch.isfinite(L).all()) and bool(torch.isfinite(C).all())):
        raise ValueError("L and C must hold finite values")
    eye = torch.eye(n, dtype=F64)
    if A is None:
        if allow_unstable:
            return L, C
        rho = spectral_radius(eye - Ts * L @ C)
        if rho >= 1:
            rank = int(torch.linalg.matrix_rank(L @ C))
            why = (f"L C has rank {rank} < n = {n}: {n - rank} direction(s) are not corrected by the feedback and "
                   "only the model can make their error decay; pass the model's Jacobian A to check detectability"
                   if rank < n else "lower L")
            raise GainError(f"rho(I - Ts L C) = {rho:.4g} >= 1 with Ts = {Ts}; {why}")
        return L, C
    A = torch.as_tensor(A, dtype=F64)
    if A.shape != (n, n):
        raise ValueError(f"Jacobian A must have shape ({n}, {n}), got {tuple(A.shape)}")
    Ad = eye + Ts * A
    try:
        check_detectable(Ad, C, labels=[f"x{i}" for i in range(n)], what="(I + Ts A, C)")
    except DetectabilityError as err:
        raise GainError(str(err)) from None
    rho = spectral_radius(Ad - Ts * L @ C)
    if rho >= 1 and not allow_unstable:
        raise GainError(f"rho(I + Ts (A - L C)) = {rho:.4g} >= 1 with Ts = {Ts}: the observer error does not decay; "
                        "choose L so that every eigenvalue of I + Ts (A - L C) lies inside the unit disc "
                        "(e.g. fnnlib.place_observer_gain on (I + Ts A, Ts C))")
    return L, C


class MeasuredFeedback:
    r"""The linear feedback of Eqs. (7)-(8) on partial measurements ``y = C x`` or ``h(x)`` (module docstring).

    A discrete Luenberger observer on the learned model, solved for all times at once
    (:mod:`fnnlib.feedback.gaps`); also the first layer of :func:`~fnnlib.cascade_predict` with partial
    measurements (``observer=``).

    Parameters
    ----------
    f : callable
        The learned field ``f(t, x)`` or, with inputs, ``f(t, x, u)``.
    Ts : float or None
        Sample step; ``None`` when every call gives the sample times ``t``.
    L : Tensor, shape (n, p)
        Output-feedback gain, checked by :func:`check_output_gain` (with ``A`` when given).
    measurement : Measurement
        ``C`` (p, n), or a measurement function ``h`` (batch, n) -> (batch, p) linearised at ``x0`` for the
        checks; ``x0`` (n,) the first estimate (default: the least-squares state of the first sample,
        :math:`C^+ y_0`; required with ``h``). A record's gaps and times go to :meth:`observe` and
        :meth:`predict` (``mask=``, ``t=``), so here they are refused.
    A : Tensor, shape (n, n), optional
        The model's Jacobian for the detectability and stability check.
    allow_unstable : bool
        Skip the stability checks.
    """

    def __init__(self, f: VectorField, Ts: float | None, *, L: Tensor, measurement: Measurement,
                 A: Tensor | None = None, allow_unstable: bool = False):
        if not isinstance(measurement, Measurement):
            raise TypeError(f"measurement must be a fnnlib.Measurement(C=..., x0=...), got "
                            f"{type(measurement).__name__}")
        if measurement.C is None:
            raise ValueError("MeasuredFeedback needs the measurement's C (p, n) or h(x); with every state measured "
                             "use LinearFeedback")
        if measurement.mask is not None or measurement.t is not None:
            raise ValueError("a record's mask and sample times t go to observe / predict (mask=, t=), not to the "
                             "observer's measurement model")
        self.f = f
        self.Ts = None if Ts is None else check_positive(Ts, name="Ts")
        self.measurement = measurement
        C, x0 = measurement.C, measurement.x0
        self.h = C if callable(C) and not isinstance(C, Tensor) else None
        L_in = torch.as_tensor(as_gain(L), dtype=F64)
        if L_in.ndim != 2:
            raise ValueError(f"the output gain L must be an (n, p) matrix, got shape {tuple(L_in.shape)}")
        n = int(L_in.shape[0])
        self.x0 = None if x0 is None else _check_x0(x0, n)
        if self.h is not None:
            C_lin = output_jacobian(self.h, self.x0[None])[0].double()
        else:
            C_lin = C
        self._A, self._allow = A, allow_unstable
        self.L, self.C = check_output_gain(L_in, C_lin, 1.0, allow_unstable=True)  # shapes here; stability per step
        self.p, self.n = self.C.shape
        self._checked: dict[float, Tensor] = {}
        if self.Ts is not None:
            self.gain_for(self.Ts)

    @property
    def output(self):
        """What :func:`~fnnlib.feedback.measurement.check_measurements` takes: ``h`` or ``C``."""
        return self.h if self.h is not None else self.C

    def gain_for(self, dt: Steps) -> Tensor:
        """The gain, checked (:func:`check_output_gain`) at the longest step of ``dt`` (a float, or intervals)."""
        h = longest(dt)
        if h not in self._checked:
            self._checked[h] = check_output_gain(self.L, self.C, h, A=self._A, allow_unstable=self._allow)[0]
        return self._checked[h]

    def _measurements(self, y: Tensor, u: Tensor | None, mask: Tensor | None, t: Tensor | None):
        """The one check of ``y``, ``u``, ``mask`` and the times, before any work."""
        meas = check_measurements(y, self.n, C=self.output, u=u, mask=mask, f=self.f)
        return meas, check_times(t, None if t is not None else self.Ts, meas.y)

    def observe(self, y: Tensor, u: Tensor | None = None, *, t: Tensor | None = None,
                mask: Tensor | None = None) -> Estimate:
        r"""``x_hat``, ``f_hat`` (..., T, n) along measurements ``y`` (..., T, p), all times at once.

        :math:`\hat x_0` = ``x0`` or, by default, the least-squares state :math:`C^+ y_0`. A NaN in ``y``
        or a ``False`` in ``mask`` ((..., T) or (..., T, p)) is a missing sample: no correction there.
        ``t`` (..., T): the sample times, when they are uneven (each step by its own interval).
        """
        meas, dt = self._measurements(y, u, mask, t)
        est, _, _, _ = first_layer(self.f, meas, self.gain_for(dt).to(meas.y.dtype), dt,
                                   start_state(meas, self.n, self.x0), diagonal=False)
        return est

    def observe_loop(self, y: Tensor, u: Tensor | None = None, *, t: Tensor | None = None,
                     mask: Tensor | None = None) -> Estimate:
        """The sequential reference of :meth:`observe` (a Python loop over time), for tests and benchmarks."""
        meas, dt = self._measurements(y, u, mask, t)
        steps = row_steps(dt, 0, meas.y.shape[-2])
        est, _ = layer_loop(self.f, meas.y, self.gain_for(dt).to(meas.y.dtype), steps,
                            start_state(meas, self.n, self.x0), mask=meas.mask, u=meas.u,
                            measure=measure_fn(meas, meas.y.dtype), diagonal=False)
        return est

    @torch.no_grad()
    def predict(self, y: Tensor, N: int, u: Tensor | None = None, *, t: Tensor | None = None,
                mask: Tensor | None = None) -> Tensor:
        r"""N-step predictions of the state (..., T, n) from every sample: row k rolls the model out (Euler, along
        the record's own steps) from the observer's latest estimate, :math:`\hat x_{k+1}` (it has seen
        :math:`y_k`), to :math:`t_{k+N}`. The open-loop baseline of the cascade; with ``L = 0`` after the observer
        the cascade equals it."""
        N = check_N(N)
        meas, dt = self._measurements(y, u, mask, t)
        _, _, z, _ = first_layer(self.f, meas, self.gain_for(dt).to(meas.y.dtype), dt,
                                 start_state(meas, self.n, self.x0), diagonal=False)
        T = meas.y.shape[-2]
        for j in range(1, N):
            z = z + row_steps(dt, j, T) * eval_field(self.f, z, shift_inputs(meas.u, j))  # x_{j+1} = x_j + h f(x_j, u_j)
        return z


def _check_x0(x0, n: int) -> Tensor:
    """A first estimate: a finite (n,) vector."""
    x0 = torch.as_tensor(x0)
    if not (x0.is_floating_point() or x0.dtype in (torch.int32, torch.int64)) or x0.ndim != 1 or x0.shape[0] != n:
        raise ValueError(f"the first estimate x0 must be a real vector of shape ({n},) (one entry per state), got "
                         f"shape {tuple(x0.shape)}")
    if not bool(torch.isfinite(x0).all()):
        raise ValueError(f"the first estimate x0 holds NaN or infinite entries: {x0.tolist()}")
    return x0.to(F64)
