r"""The linear feedback network, Eqs. (7)-(8), behind the :class:`~fnnlib.observers.Observer` interface.

With the sample times ``t`` (..., T) instead of ``Ts`` Eq. (8) steps by each interval,
:math:`\hat x_{k+1} = \hat x_k + \Delta_k \hat f_k` (:mod:`fnnlib.feedback.sampling`), the cascade predicts
along the record's own times, and Eq. (25)'s condition :math:`\rho(I - \Delta L) < 1` is checked at the
longest interval (where it is strictest).
"""

from __future__ import annotations

import torch
from torch import Tensor

from fnnlib._validation import as_trajectory, check_positive
from fnnlib.feedback.cascade import cascade_predict
from fnnlib.feedback.options import Gains, Measurement
from fnnlib.feedback.gains import check_gain, gain_compact, implied_n
from fnnlib.feedback.layer import eval_field, feedback_layer
from fnnlib.feedback.sampling import longest, row_steps
from fnnlib.observers.augmented import observer_steps
from fnnlib.feedback.types import Estimate, VectorField


class LinearFeedback:
    r"""Neural ODE with a linear feedback, Eqs. (7)-(8).

    Every observer is built as ``(f, Ts, *, ...)``: the model and the nominal sample step by position, the rest
    by name.

    Parameters
    ----------
    f : callable
        The learned vector field ``f(t, x)``, ``x`` of shape (batch, n).
    Ts : float
        Sampling step of the measurements.
    gains : Gains
        Base feedback gain ``L`` (scalar, diagonal or full; checked by :func:`~fnnlib.feedback.gains.check_gain`
        unless ``gains.allow_unstable``, which accepts a gain that is not positive definite or has
        :math:`\rho(I - T_s L) \ge 1`) and the decay rate ``beta`` of Eq. (11) used by :meth:`predict`.
    n : int, optional
        State dimension; not needed when ``L`` is a vector or matrix or ``f`` has an ``n`` attribute
        (a :class:`~fnnlib.models.NeuralODE` or a :class:`~fnnlib.systems.DynamicalSystem`).

    Attributes
    ----------
    L : Tensor, shape (n, n), float64
        The base gain (layer 0 of the cascade; :meth:`observe` uses it alone).
    """

    def __init__(self, f: VectorField, Ts: float, *, gains: Gains, n: int | None = None):
        if not isinstance(gains, Gains):
            raise TypeError(f"gains must be a fnnlib.Gains(L, beta), got {type(gains).__name__}")
        self.f = f
        self.Ts = check_positive(Ts, name="Ts")
        self.n = implied_n(gains.L, n if n is not None else getattr(f, "n", None))
        self.L = check_gain(gains.L, self.n, self.Ts, allow_unstable=gains.allow_unstable)  # (n, n) float64
        self.allow_unstable = gains.allow_unstable
        self.beta = gains.beta

    def observe(self, x: Tensor, u: Tensor | None = None, *, t: Tensor | None = None) -> Estimate:
        """Run the feedback network along measurements ``x`` (..., T, n) (inputs ``u`` (..., T, m) of a controlled model).

        Returns ``x_hat`` (the estimate of Eq. (8)) and ``f_hat`` (the
        corrected change rate of Eq. (7)), both (..., T, n). ``t`` (..., T): the sample times instead of ``Ts``.
        """
        x = as_trajectory(x, self.n)
        dt = self.steps(x, t)
        with torch.no_grad():
            fx = eval_field(self.f, x, u)
        step = row_steps(dt, 0, x.shape[-2])
        if isinstance(step, Tensor):
            step = step.to(x.dtype)
        return feedback_layer(fx, x, gain_compact(self.L, self.n, dtype=x.dtype), step)

    def steps(self, x: Tensor, t: Tensor | None):
        """``Ts``, or the intervals (..., T-1) of the times ``t`` of ``x``, the gain checked at the longest (Eq.
        (25))."""
        if t is None:
            return self.Ts
        dt = observer_steps(t, self.Ts, x, name="x")
        check_gain(self.L, self.n, longest(dt), allow_unstable=self.allow_unstable)
        return dt

    def predict(self, x: Tensor, N: int, u: Tensor | None = None, *, t: Tensor | None = None) -> Tensor:
        """N-step prediction from every sample of ``x`` (..., T, n) by the cascade of Sec. 3.3.

        :func:`~fnnlib.feedback.cascade.cascade_predict` with this base gain and the decay
        ``beta`` of Eq. (11); row k predicts the state at ``t_{k+N}`` (with ``t``, the record's own).
        """
        return cascade_predict(self.f, x, None if t is not None else self.Ts, N,
                               Gains(self.L, self.beta, allow_unstable=self.allow_unstable), u=u,
                               measurement=None if t is None else Measurement(t=t))
