r"""The neural feedback network: a frozen neural ODE corrected by a learned h_neural (Sec. 4).

Eq. (7) with the linear term replaced by a network,
:math:`\\hat f_k = f_{neural}(x_k) + h_{neural}(x_k - \\hat x_k)`, and Eq. (8)
`sys2_2`, :math:`\\hat x_{k+1} = \\hat x_k + T_s \\hat f_k`. The recursion for
:math:`\\hat x` is nonlinear, so it runs as a loop over time, batched over all
leading axes (cases, levels, start times); the N-step cascade of Sec. 3.3 runs
its layers as anti-diagonal wavefronts (T + N - 1 sequential steps, not T * N).

With the sample times ``t`` (..., T) instead of ``Ts`` every step is its own interval,
:math:`\hat x_{k+1} = \hat x_k + \Delta_k \hat f_k` (:mod:`fnnlib.feedback.sampling`); layer ``i`` of the
cascade moves row ``k`` from :math:`t_{k+i}` to :math:`t_{k+i+1}`, so every cell of a wavefront ``w = i + k``
steps by the same :math:`\Delta_w` (past the record's end the last interval is repeated). The decay
:math:`e^{-\beta i}` is read per layer, as for Eq. (11) (:mod:`fnnlib.feedback.sampling`).
"""

from __future__ import annotations

import torch
from torch import Tensor

from fnnlib._validation import as_trajectory, check_positive
from fnnlib.feedback.decay import check_beta, check_N, decay_factors
from fnnlib.feedback.layer import eval_field
from fnnlib.feedback.sampling import Steps
from fnnlib.feedback.types import Estimate, Feedback, VectorField
from fnnlib.observers.augmented import observer_steps



def _flat_steps(dt: Steps, lead: tuple[int, ...], T: int, dtype: torch.dtype) -> Steps:
    """``Ts`` as it is, or the intervals (..., T-1) expanded to the records' leading axes and flattened, (B, T-1)."""
    if not isinstance(dt, Tensor):
        return dt
    return dt.to(dtype).expand(*lead, T - 1).reshape(-1, T - 1)


def feedback_rollout(fx: Tensor, x: Tensor, h: Feedback, Ts: Steps) -> Estimate:
    r"""Run the neural feedback along measurements ``x`` (..., T, n), all leading axes at once.

    ``fx = f_neural(x)`` (same shape) is given, so the frozen model is evaluated once, outside
    the loop. For k = 0 .. T-1, with :math:`\hat x_0 = x_0`:

    * :math:`\hat f_k = f_{neural}(x_k) + h_{neural}(x_k - \hat x_k)`  (Eq. (7), neural form)
    * :math:`\hat x_{k+1} = \hat x_k + T_s \hat f_k`  (Eq. (8) `sys2_2`)

    ``Ts`` is the step, or the intervals :math:`\Delta_k` (..., T-1) of uneven times (leading axes ``x``'s or
    none): :math:`\hat x_{k+1} = \hat x_k + \Delta_k \hat f_k`. Gradients flow through ``h`` unless the
    caller disables them.

    Returns
    -------
    Estimate
        ``x_hat`` and ``f_hat``, both (..., T, n).
    """
    lead, (T, n) = x.shape[:-2], x.shape[-2:]
    xs = x.reshape(-1, T, n)
    fs = fx.reshape(-1, T, n)
    dts = _flat_steps(Ts, lead, T, x.dtype)
    x_hat_k = xs[:, 0]
    x_hats, f_hats = [], []
    for k in range(T):
        f_hat_k = fs[:, k] + h(xs[:, k] - x_hat_k)  # f_hat = f_neural(x) + h_neural(x - x_hat)
        x_hats.append(x_hat_k)
        f_hats.append(f_hat_k)
        step = dts if not isinstance(dts, Tensor) else dts[:, min(k, T - 2), None]
        x_hat_k = x_hat_k + step * f_hat_k  # x_hat += Delta_k * f_hat   (Eq. 8)
    x_hat = torch.stack(x_hats, dim=1).reshape(*lead, T, n)
    f_hat = torch.stack(f_hats, dim=1).reshape(*lead, T, n)
    return Estimate(x_hat, f_hat)


class NeuralFeedbackObserver:
    r"""A frozen neural ODE with a learned neural feedback, behind the :class:`~fnnlib.observers.Observer` interface.

    Parameters
    ----------
    f : callable
        The learned vector field ``f(t, x)``, ``x`` of shape (batch, n) (frozen).
    Ts : float
        Sampling step of the measurements (also the prediction step).
    h : callable
        The feedback ``h(e)``, ``e = x - x_hat`` of shape (batch, n), e.g. a
        :class:`~fnnlib.models.NeuralFeedback`.
    n : int, optional
        State dimension; by default ``f.n`` (a :class:`~fnnlib.models.NeuralODE` or a system has it).
    beta : float
        Decay of the feedback along the cascade, the analogue of Eq. (11): layer ``i`` uses
        :math:`e^{-\beta i} h_{neural}`. 0 (the default) keeps the learned feedback unchanged.
    """

    def __init__(self, f: VectorField, Ts: float, *, h: Feedback, n: int | None = None, beta: float = 0.0):
        self.f = f
        self.h = h
        self.Ts = check_positive(Ts, name="Ts")
        n = n if n is not None else getattr(f, "n", None)
        if n is None:
            raise ValueError("pass the state dimension n (f has no `n` attribute to take it from)")
        self.n = int(n)
        self.beta = check_beta(beta)

    def steps(self, x: Tensor, t: Tensor | None) -> Steps:
        """``Ts``, or the checked intervals (..., T-1) of the sample times ``t`` of ``x``."""
        return observer_steps(t, self.Ts, x, name="x")

    @torch.no_grad()
    def observe(self, x: Tensor, *, t: Tensor | None = None) -> Estimate:
        """State and change-rate estimates along measurements ``x`` (..., T, n), each (..., T, n).

        ``t`` (..., T): the sample times instead of ``Ts`` (module docstring)."""
        x = as_trajectory(x, self.n)
        dt = self.steps(x, t)  # checked before the model runs
        return feedback_rollout(eval_field(self.f, x), x, self.h, dt)

    @torch.no_grad()
    def predict(self, x: Tensor, N: int, *, t: Tensor | None = None) -> Tensor:
        r"""N-step prediction from every sample of ``x`` (..., T, n) by the cascade of Sec. 3.3.

        Layer ``i`` takes the previous layer's one-step predictions :math:`z^{(i)}_k`
        (:math:`z^{(0)} = x`), keeps its own :math:`\hat x^{(i)}` (started at :math:`z^{(i)}_0`)
        and outputs :math:`z^{(i+1)}_k = z^{(i)}_k + T_s \hat f^{(i)}_k`. Layer ``i`` at time ``k``
        needs layer ``i-1`` at time ``k`` and itself at ``k-1``, so every cell with ``i + k = w``
        is computed at once: T + N - 1 batched steps. Row k of the result predicts ``x(t_{k+N})``.
        With ``t`` (..., T) the cells of wavefront ``w`` step by :math:`\Delta_w` (module docstring).
        """
        N = check_N(N)
        x = as_trajectory(x, self.n)
        lead, (T, n) = x.shape[:-2], x.shape[-2:]
        dts = _flat_steps(self.steps(x, t), lead, T, x.dtype)
        xs = x.reshape(-1, T, n)
        B = xs.shape[0]
        decay = decay_factors(self.beta, N)[0].to(x.dtype)[:, None, None]  # (N, 1, 1): e^{-beta i}   (Eq. 11)
        z_in = xs.new_zeros(N, B, n)  # z_in[i]: layer i's input at its current time w - i
        x_hat = xs.new_zeros(N, B, n)  # x_hat[i]: layer i's estimate at its current time
        out = torch.empty_like(xs)
        for w in range(T + N - 1):
            lo, hi = max(0, w - T + 1), min(N - 1, w)  # active layers: 0 <= w - i <= T - 1
            if w < T:
                z_in[0] = xs[:, w]
            if hi == w:
                x_hat[w] = z_in[w]  # a layer's estimate starts at its first input
            z = z_in[lo:hi + 1].clone()
            m = hi + 1 - lo
            e = z - x_hat[lo:hi + 1]
            f_hat = (self.f(0.0, z.reshape(-1, n)) + self.h(e.reshape(-1, n))
                     * decay[lo:hi + 1].expand(m, B, 1).reshape(-1, 1)).reshape(m, B, n)
            step = dts if not isinstance(dts, Tensor) else dts[:, min(w, T - 2), None]  # Delta_{k+i}, k + i = w
            x_hat[lo:hi + 1] += step * f_hat  # x_hat^(i) += Ts * f_hat^(i)   (Eq. 8)
            z_next = z + step * f_hat  # z^(i+1)_k = z^(i)_k + Ts * f_hat^(i)_k
            if hi == N - 1:
                out[:, w - N + 1] = z_next[-1]
                z_next = z_next[:-1]
            z_in[lo + 1:lo + 1 + z_next.shape[0]] = z_next
        return out.reshape(*lead, T, n)

    @torch.no_grad()
    def predict_loop(self, x: Tensor, N: int, *, t: Tensor | None = None) -> Tensor:
        """Reference for :meth:`predict`: a plain loop over start times and depths; ``x`` (T, n), ``t`` (T,)."""
        N = check_N(N)
        x = as_trajectory(x, self.n)
        dt = self.steps(x, t)
        decay = decay_factors(self.beta, N)[0].tolist()
        if x.ndim != 2:
            raise ValueError(f"the loop reference takes one trajectory of shape (T, n), got {tuple(x.shape)}")
        x_hat: list[Tensor] = []
        out = torch.empty_like(x)
        for k in range(x.shape[0]):
            z = x[k]
            for i in range(N):
                if k == 0:
                    x_hat.append(z.clone())
                f_hat = self.f(0.0, z[None])[0] + decay[i] * self.h((z - x_hat[i])[None])[0]
                h = dt if not isinstance(dt, Tensor) else float(dt[min(k + i, x.shape[0] - 2)])
                x_hat[i] = x_hat[i] + h * f_hat
                z = z + h * f_hat
            out[k] = z
        return out
