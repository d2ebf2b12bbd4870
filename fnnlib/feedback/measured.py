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
from fnnlib.feedback.gaps import measure_fn, start_state, step_layer
from fnnlib.feedback.layer import eval_field, shift_inputs
from fnnlib.feedback.measurement import DetectabilityError, check_detectable, check_measurements, check_output_matrix
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
    r"""The linear feedback of Eqs. (7)-(8) on partial measurements ``y = C x`` (module docstring).

    Parameters
    ----------
    f : callable
        The learned field ``f(t, x)`` or, with inputs, ``f(t, x, u)``.
    L : Tensor, shape (n, p)
        Output-feedback gain, checked by :func:`check_output_gain` (with ``A`` when given).
    C : Tensor, shape (p, n)
        Measurement matrix.
    Ts : float
        Sample step.
    A : Tensor, shape (n, n), optional
        The model's Jacobian for the detectability and stability check.
    allow_unstable : bool
        Skip the stability checks.
    """

    def __init__(self, f: VectorField, L: Tensor, C: Tensor, Ts: float, *, A: Tensor | None = None,
                 allow_unstable: bool = False):
        self.f, self.Ts = f, check_positive(Ts, name="Ts")
        self.L, self.C = check_output_gain(L, C, self.Ts, A=A, allow_unstable=allow_unstable)
        self.p, self.n = self.C.shape

    def _measurements(self, y: Tensor, u: Tensor | None, mask: Tensor | None):
        """The one check of ``y``, ``u`` and ``mask`` (:func:`~fnnlib.feedback.measurement.check_measurements`)."""
        return check_measurements(y, self.n, C=self.C, u=u, mask=mask, f=self.f)

    def observe(self, y: Tensor, u: Tensor | None = None, *, x0: Tensor | None = None,
                mask: Tensor | None = None) -> Estimate:
        r"""``x_hat``, ``f_hat`` (..., T, n) along measurements ``y`` (..., T, p); a loop over time.

        :math:`\hat x_0` = ``x0`` or, by default, the least-squares state :math:`C^+ y_0`. A NaN in ``y``
        or a ``False`` in ``mask`` ((..., T) or (..., T, p)) is a missing sample: no correction there
        (:mod:`fnnlib.feedback.gaps`).
        """
        meas = self._measurements(y, u, mask)
        return self._observe(meas, x0)

    def _observe(self, meas, x0: Tensor | None) -> Estimate:
        L = self.L.to(meas.y.dtype)
        start = start_state(meas, self.n, x0)
        est, _ = step_layer(self.f, meas.y, L, self.Ts, start, mask=meas.mask, u=meas.u,
                            measure=measure_fn(meas, meas.y.dtype))
        return est

    @torch.no_grad()
    def predict(self, y: Tensor, N: int, u: Tensor | None = None, *, x0: Tensor | None = None,
                mask: Tensor | None = None) -> Tensor:
        """N-step predictions of the state (..., T, n) from every sample: Euler rollouts of the model from ``x_hat``."""
        N = check_N(N)
        meas = self._measurements(y, u, mask)
        z = self._observe(meas, x0).x_hat
        for j in range(N):
            z = z + self.Ts * eval_field(self.f, z, shift_inputs(meas.u, j))  # x_{j+1} = x_j + Ts f(x_j, u_j)
        return z
