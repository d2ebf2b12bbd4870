"""Open-loop neural-ODE prediction, Eq. (2): the baseline every cascade is compared to."""

from __future__ import annotations

import torch
from torch import Tensor
from torchdiffeq import odeint

from fnnlib._validation import as_trajectory
from fnnlib.feedback.decay import check_N
from fnnlib.feedback.layer import shift_inputs
from fnnlib.feedback.measurement import check_measurements
from fnnlib.feedback.options import Measurement, Solver, record_sampling
from fnnlib.feedback.sampling import check_times, row_steps
from fnnlib.feedback.types import VectorField


@torch.no_grad()
def rollout_predict(f: VectorField, x: Tensor, Ts: float | None, N: int, *, solver: Solver = Solver(),
                    u: Tensor | None = None, measurement: Measurement | None = None) -> Tensor:
    """N-step open-loop neural-ODE prediction (Eq. (2)) from every sample of ``x``.

    Parameters
    ----------
    x : Tensor, shape (..., T, n)
        Start states.
    Ts : float or None
        Sample step; ``None`` with ``measurement.t``.
    N : int
        Prediction steps.
    solver : Solver
        The torchdiffeq method: ``Solver("euler")`` (the default) steps at ``Ts`` (the discretisation the
        cascade uses), an adaptive one (``Solver("dopri5", rtol=..., atol=...)``) integrates accurately.
    u : Tensor, shape (..., T, m), optional
        Inputs of a controlled model ``f(t, x, u)``: step ``j`` from start ``k`` holds ``u_{k+j}``
        (the last one held), integrated one sample interval at a time.
    measurement : Measurement, optional
        The sample times ``t`` (..., T) instead of ``Ts`` (uneven sampling): step ``j`` from start ``k``
        integrates over :math:`[t_{k+j}, t_{k+j+1}]` (the last interval repeated past the record's end), so row k
        predicts the state at the record's own :math:`t_{k+N}`. The rollout starts from every sample, so it
        takes no gaps (``mask``).

    Returns
    -------
    Tensor, shape (..., T, n): row k predicts ``t_{k+N}``. :func:`rollout_depths` returns every step.
    """
    return _rollout(f, x, Ts, N, solver, u, measurement, return_all=False)


@torch.no_grad()
def rollout_depths(f: VectorField, x: Tensor, Ts: float | None, N: int, *, solver: Solver = Solver(),
                   u: Tensor | None = None, measurement: Measurement | None = None) -> Tensor:
    """Every step of :func:`rollout_predict` (same arguments), shape (N+1, ..., T, n); step 0 is ``x``."""
    return _rollout(f, x, Ts, N, solver, u, measurement, return_all=True)


def _rollout(f: VectorField, x: Tensor, Ts: float | None, N: int, solver: Solver, u: Tensor | None,
             measurement: Measurement | None, *, return_all: bool) -> Tensor:
    """Eq. (2) from every sample, for :func:`rollout_predict` and :func:`rollout_depths`."""
    if not isinstance(solver, Solver):
        raise TypeError(f"solver must be a fnnlib.Solver(method, rtol, atol), got {type(solver).__name__}")
    t, mask = record_sampling(measurement)
    if mask is not None:
        raise ValueError("the open-loop rollout starts from every sample and takes no gaps (mask)")
    method, rtol, atol = solver.method, solver.rtol, solver.atol
    N = check_N(N)
    x = as_trajectory(x, x.shape[-1] if isinstance(x, Tensor) else None)
    meas = check_measurements(x, x.shape[-1], u=u, f=f, missing=False, name="x")
    dt = check_times(t, Ts, x, name="x")
    n = x.shape[-1]
    if isinstance(dt, Tensor):
        return _rollout_times(f, x, meas.u, dt, N, method, return_all, rtol, atol)
    Ts = dt
    if u is not None:
        return _rollout_inputs(f, x, meas.u, Ts, N, method, return_all, rtol, atol)
    grid = torch.arange(N + 1, dtype=x.dtype) * Ts
    fixed = method in {"euler", "midpoint", "rk4"}
    kwargs = {"options": {"step_size": Ts}} if fixed else {"rtol": rtol, "atol": atol}
    sol = odeint(f, x.reshape(-1, n), grid, method=method, **kwargs)  # (N+1, M, n)
    sol = sol.reshape(N + 1, *x.shape)
    return sol if return_all else sol[-1]


def _rollout_inputs(f: VectorField, x: Tensor, u: Tensor, Ts: float, N: int, method: str, return_all: bool,
                    rtol: float, atol: float) -> Tensor:
    """:func:`rollout_predict` of a controlled model: one ``odeint`` per sample interval, the input held (zero-order hold)."""
    fixed = method in {"euler", "midpoint", "rk4"}
    kwargs = {"options": {"step_size": Ts}} if fixed else {"rtol": rtol, "atol": atol}
    n, m = x.shape[-1], u.shape[-1]
    lead = torch.broadcast_shapes(x.shape[:-1], u.shape[:-1])
    z = x.expand(*lead, n).reshape(-1, n)
    grid = torch.tensor([0.0, Ts], dtype=x.dtype)
    sol = [z]
    for j in range(N):
        uj = shift_inputs(u, j).expand(*lead, m).reshape(-1, m)
        z = odeint(lambda t, s, uj=uj: f(t, s, uj), z, grid, method=method, **kwargs)[-1]
        sol.append(z)
    out = torch.stack(sol).reshape(N + 1, *lead, n)
    return out if return_all else out[-1]


def _rollout_times(f: VectorField, x: Tensor, u: Tensor | None, dt: Tensor, N: int, method: str, return_all: bool,
                   rtol: float, atol: float) -> Tensor:
    r""":func:`rollout_predict` along uneven times: each step integrates the field scaled by its interval over
    :math:`s \in [0, 1]` (:math:`dx/ds = \Delta_{k+j} f(x, u_{k+j})`), so every start moves by its own interval
    in one batched ``odeint`` call per step."""
    fixed = method in {"euler", "midpoint", "rk4"}
    kwargs = {"options": {"step_size": 1.0}} if fixed else {"rtol": rtol, "atol": atol}
    n, T = x.shape[-1], x.shape[-2]
    lead = torch.broadcast_shapes(x.shape[:-1], dt.shape[:-1] + (T,), *(() if u is None else (u.shape[:-1],)))
    z = x.expand(*lead, n).reshape(-1, n)
    grid = torch.tensor([0.0, 1.0], dtype=x.dtype)
    sol = [z]
    for j in range(N):
        h = row_steps(dt, j, T).expand(*lead, 1).reshape(-1, 1)
        if u is None:
            field = lambda s, v, h=h: h * f(s, v)  # noqa: E731
        else:
            uj = shift_inputs(u, j).expand(*lead, u.shape[-1]).reshape(-1, u.shape[-1])
            field = lambda s, v, h=h, uj=uj: h * f(s, v, uj)  # noqa: E731
        z = odeint(field, z, grid, method=method, **kwargs)[-1]
        sol.append(z)
    out = torch.stack(sol).reshape(N + 1, *lead, n)
    return out if return_all else out[-1]
