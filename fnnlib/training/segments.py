r"""Training a neural field from outputs alone *without* feedback: each training segment starts from an initial
state that is a free parameter, learned with the model (multiple shooting on the simulation error).

The baseline a reviewer asks for beside training through the observer: "feedback, or just a better initial
state?". The record (T, p) of a partly measured plant :math:`y = C x` with inputs ``u`` is cut into
segments of ``horizon`` samples starting every ``stride`` samples; segment ``w`` starts from its own
:math:`x_{0,w}` (a parameter, initialised so that :math:`C x_{0,w}` is the measured :math:`y` there) and is
rolled out open loop with Euler steps, :math:`x_{k+1} = x_k + T_s f(t_k, x_k, u_k)` (the step the feedback
layers of Eq. (8) take, without their correction). The loss is the mean squared output error over every
segment's samples; Adam descends on the model's parameters and the initial states together, full batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

__all__ = ["SegmentFit", "train_free_initial_states"]


@dataclass(frozen=True)
class SegmentFit:
    """What :func:`train_free_initial_states` returns.

    Attributes
    ----------
    loss : list of float
        The mean squared output error per iteration.
    x0 : Tensor, shape (W, n)
        The learned initial state of each segment.
    starts : list of int
        The first sample of each segment.
    """

    loss: list[float]
    x0: Tensor
    starts: list[int]


def train_free_initial_states(f: nn.Module, y: Tensor, u: Tensor, Ts: float, C: Tensor, *, horizon: int,
                              stride: int | None = None, iterations: int = 100, lr: float = 0.01,
                              x0_guess: Tensor | None = None) -> SegmentFit:
    """Train ``f(t, x, u)`` (in place) on one record by multiple shooting with free initial states (module
    docstring).

    Parameters
    ----------
    f : nn.Module
        The field, ``f(t, x, u)`` with ``x`` (batch, n), ``u`` (batch, m).
    y : Tensor, shape (T, p)
        The measured outputs (finite).
    u : Tensor, shape (T, m)
        The inputs, row k held over the step from sample k.
    Ts : float
        Sample step.
    C : Tensor, shape (p, n)
        The measurement.
    horizon : int
        Samples per segment (>= 2).
    stride : int, optional
        Samples between segment starts (default: ``horizon``, segments side by side).
    iterations, lr : int, float
        Adam steps and learning rate.
    x0_guess : Tensor, shape (n,), optional
        The unmeasured part of every initial state at the start (default 0); the measured part is set so
        that :math:`C x_{0,w} = y_{s_w}` (least squares).

    Returns
    -------
    SegmentFit
    """
    y, u, C = torch.as_tensor(y), torch.as_tensor(u), torch.as_tensor(C)
    if y.ndim != 2 or u.ndim != 2 or y.shape[0] != u.shape[0]:
        raise ValueError(f"y must be (T, p) and u (T, m) of one length, got {tuple(y.shape)} and {tuple(u.shape)}")
    if not torch.isfinite(y).all() or not torch.isfinite(u).all():
        raise ValueError("y and u must be finite (this trainer takes no gaps)")
    T, (p, n) = y.shape[0], C.shape
    if y.shape[1] != p:
        raise ValueError(f"y has {y.shape[1]} outputs, C measures {p}")
    stride = horizon if stride is None else stride
    for name, v, low in (("horizon", horizon, 2), ("stride", stride, 1), ("iterations", iterations, 1)):
        if isinstance(v, bool) or int(v) != v or v < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {v!r}")
    if horizon > T or not lr > 0 or not Ts > 0:
        raise ValueError(f"need horizon <= T = {T}, lr > 0 and Ts > 0; got {horizon}, {lr}, {Ts}")
    starts = list(range(0, T - horizon + 1, int(stride)))
    idx = torch.tensor(starts)[:, None] + torch.arange(horizon)[None, :]  # (W, horizon)
    base = torch.zeros(n, dtype=y.dtype) if x0_guess is None else torch.as_tensor(x0_guess, dtype=y.dtype)
    pinv = torch.linalg.pinv(C.to(y.dtype))
    x0 = base + (y[starts] - base @ C.T.to(y.dtype)) @ pinv.T  # C x0 = y at each start
    x0 = nn.Parameter(x0.clone())
    opt = torch.optim.Adam([*f.parameters(), x0], lr=float(lr))
    y_seg, u_seg, Cd = y[idx], u[idx], C.to(y.dtype)
    losses = []
    for _ in range(int(iterations)):
        opt.zero_grad()
        x, outs = x0, []
        for k in range(horizon):
            outs.append(x @ Cd.T)
            if k < horizon - 1:
                x = x + Ts * f(0.0, x, u_seg[:, k])  # Euler: Eq. (8) without its correction term
        loss = ((torch.stack(outs, 1) - y_seg) ** 2).mean()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    return SegmentFit(losses, x0.detach(), starts)
