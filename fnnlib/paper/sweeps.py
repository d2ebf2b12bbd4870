"""Sweep grids and uncertainty levels of the ablations (Sec. 3.4, App. A.3), and the sweeps run on them.

The paper writes its grids in MATLAB colon form ``{start: +step: stop}``
(:func:`colon_range`) and pairs them into uncertainty levels
(:func:`paired_levels`); the batched runs over many gains and decay rates are
:func:`fnnlib.feedback.observe_gains` and :func:`fnnlib.feedback.cascade_sweep`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor

from fnnlib.feedback.options import Gains
from fnnlib.feedback.tuning import GainSweep, TunedGains, TuneRecipe
from fnnlib.feedback.types import VectorField
from fnnlib.metrics import ahead_position_errors, ahead_position_loss, n_step_errors
from fnnlib.models.ensemble import NeuralODEEnsemble, stack_members
from fnnlib.systems.base import DynamicalSystem
from fnnlib.systems.spiral import Spiral
from fnnlib.systems.switched import SwitchedSystem


def colon_range(start: float, step: float, stop: float) -> Tensor:
    """The paper's grid ``{start: +step: stop}`` (MATLAB ``start:step:stop``), stop included.

    Returns a float64 tensor ``start + step * i`` for ``i = 0 .. floor((stop - start) / step)``
    (with a 1e-9 relative tolerance, so ``{0.04: 0.02: 0.22}`` has 10 values, not 9).

    Examples
    --------
    >>> colon_range(0, 5, 45).tolist()[-1]
    45.0
    """
    start, step, stop = float(start), float(step), float(stop)
    if not all(math.isfinite(v) for v in (start, step, stop)):
        raise ValueError(f"grid {{{start}: {step}: {stop}}} holds a non-finite value")
    if step == 0 or (stop - start) * step < 0:
        raise ValueError(f"grid {{{start}: {step}: {stop}}} is empty: step must be non-zero and point from "
                         "start towards stop")
    count = math.floor((stop - start) / step * (1 + 1e-9) + 1e-9) + 1
    return start + step * torch.arange(count, dtype=torch.float64)


def paired_levels(*grids: Sequence[float] | Tensor) -> Tensor:
    """Stack grids of equal length column-wise: level ``i`` takes the ``i``-th value of every grid.

    The paper's uncertainty levels pair their parameters this way (App. A.3.4:
    level ``i`` is ``(omega_i, eta_i, eps_i)``). Returns shape (levels, len(grids)).
    """
    cols = [torch.as_tensor(g, dtype=torch.float64).reshape(-1) for g in grids]
    if not cols:
        raise ValueError("paired_levels needs at least one grid")
    counts = [c.numel() for c in cols]
    if len(set(counts)) != 1:
        raise ValueError(f"grids paired into levels must have the same length, got lengths {counts}")
    return torch.stack(cols, dim=-1)


def simulate_levels(systems: Sequence[DynamicalSystem], x0: Tensor, t: Tensor, *, exact: bool = False) -> Tensor:
    """Simulate each system from ``x0`` on the grid ``t``; stack on a leading axis.

    With ``exact`` each system's closed form ``exact_solution`` is used instead of
    the ODE solver. Returns float64 of shape (len(systems), ..., T, n) for ``x0`` of shape (..., n).
    """
    if len(systems) == 0:
        raise ValueError("simulate_levels needs at least one system")
    if exact and not all(hasattr(s, "exact_solution") for s in systems):
        raise ValueError("exact=True needs systems with a closed form (an exact_solution method)")
    return torch.stack([s.exact_solution(x0, t) if exact else s.simulate(x0, t) for s in systems])


def offset_spirals(base: Sequence[float], offsets: Tensor) -> list[Spiral]:
    """The spirals ``base + offsets[j]`` in (omega, eta, eps), one per row of ``offsets`` (levels, 3).

    The 12 learning-residual levels of App. A.7.1 (S8, Fig. S9 and S10) are the
    nominal spiral plus the paired offsets of :func:`paired_levels`.
    """
    offsets = torch.as_tensor(offsets, dtype=torch.float64)
    if offsets.ndim != 2 or offsets.shape[1] != 3 or len(base) != 3:
        raise ValueError(f"need a base (omega, eta, eps) and offsets of shape (levels, 3); got base {list(base)}, "
                         f"offsets {tuple(offsets.shape)}")
    return [Spiral(*(torch.tensor(base, dtype=torch.float64) + d).tolist()) for d in offsets]


def residual_level_runs(base: Sequence[float], offsets: Tensor, x0: Tensor, t: Tensor) -> tuple[Tensor, Tensor]:
    """The runs of the learning-residual levels (App. A.7.1; S8, Fig. S9): each spiral ``base + offsets[j]``
    (:func:`offset_spirals`) simulated from ``x0`` on ``t``, and its true change rate along that run.

    Returns ``(x, f)``, both float32 of shape (levels, T, 2): the states as the networks read them, and Eq. (26)'s
    rate evaluated at those float32 states (the reference the feedback's estimate and the network are scored on).
    """
    systems = offset_spirals(base, offsets)
    x = simulate_levels(systems, x0, t).float()
    return x, torch.stack([s.rate(xj) for s, xj in zip(systems, x)])


def switched_spiral_run(before: Sequence[float], after: Sequence[float], t_switch: float, x0: Tensor,
                        t: Tensor) -> tuple[Tensor, Tensor]:
    """The run of S10 (App. A.7.2): the spiral Eq. (26) with parameters ``before`` (omega, eta, eps) until
    ``t_switch`` and ``after`` from then on, simulated from ``x0`` on ``t`` (dopri5 restarted at the switch).

    Returns ``(x, f)``, both float32 of shape (T, 2): the states, and the true rate of the system in force at each
    time (computed on the float64 run, then rounded).
    """
    sw = SwitchedSystem([Spiral(*before), Spiral(*after)], [t_switch])
    x = sw.simulate(x0, t)
    return x.float(), sw.rate(t, x).float()


def n_step_rmse(pred: Tensor, truth: Tensor, N: int, dim: int | tuple[int, ...] = -1) -> Tensor:
    """The root mean square of the :func:`n_step_errors` of ``pred``, over the axes ``dim`` (the starts, and
    any noise draws or levels pooled with them): the N-step RMSE of Fig. S11 (S9)."""
    return n_step_errors(pred, truth, N).pow(2).mean(dim).sqrt()


def sweep_errors(ensemble: NeuralODEEnsemble, z: Tensor, truth: Tensor, Ts: float, N: int, L: float | Tensor,
                 beta: float | Tensor = 0.0) -> Tensor:
    """The mean N-step error of every member of ``ensemble`` at every (gain, decay rate) pair of
    :func:`fnnlib.feedback.cascade_sweep` (Eq. (11)), from the stacked measurements ``z`` (T, E n) of the
    trajectory ``truth`` (T, n): shape (E, G), one cell per member and gain of the maps of Fig. 3 (S7)."""
    from fnnlib.feedback.cascade import cascade_sweep  # noqa: PLC0415 (the sweeps need no cascade to import)

    return n_step_errors(ensemble.split(cascade_sweep(ensemble, z, Ts, N, Gains.sweep(L, beta))), truth, N).mean(-1)


def cascade_position_errors(f: VectorField, x: Tensor, Ts: float, N: int, L: float | Tensor,
                            beta: float = 0.0) -> Tensor:
    """O1's error (Sec. 5.1) of the N-step cascade (Eq. (11), gain ``L``, decay ``beta``; ``L = 0`` is the open-loop
    Euler rollout) on the trajectories ``x`` (K, T, n): each one's mean position error N samples ahead over every
    start (:func:`fnnlib.metrics.ahead_position_errors`), shape (K,); with a :class:`NeuralODEEnsemble` ``f``
    every member's on the same measurements, (E, K). The cascade is causal: it runs on the first T - N rows."""
    from fnnlib.feedback.cascade import cascade_predict  # noqa: PLC0415 (the sweeps need no cascade to import)

    if isinstance(f, NeuralODEEnsemble):
        z = cascade_predict(f, stack_members(x, f.size)[:, :-N], Ts, N, Gains(L, beta))
        return ahead_position_errors(f.split(z), x, N)
    return ahead_position_errors(cascade_predict(f, x[:, :-N], Ts, N, Gains(L, beta)), x, N)


def n_step_gain_sweep(f: VectorField, y: Tensor, Ts: float, N: int, L_grid: Sequence[float], beta_grid: Sequence[float],
                      u: Tensor | None = None) -> GainSweep:
    """Gains picked by hand (B1): the (L, beta) of the grid whose N-step cascade (Eq. (11)) has the lowest mean
    N-step error (:func:`n_step_errors`, every state) on the tuning measurements ``y`` (..., T, n), inputs ``u``
    where the model takes them (:func:`fnnlib.feedback.sweep_gains`)."""
    from fnnlib.feedback.cascade import cascade_predict  # noqa: PLC0415
    from fnnlib.feedback.tuning import sweep_gains  # noqa: PLC0415

    def cost(L: float, beta: float) -> float:
        with torch.no_grad():
            return float(n_step_errors(cascade_predict(f, y, Ts, N, Gains(L, beta), u=u), y, N).mean())
    return sweep_gains(cost, L_grid, beta_grid)


def position_gain_sweep(f: VectorField, x: Tensor, Ts: float, N: int, L_grid: Sequence[float],
                        beta_grid: Sequence[float]) -> GainSweep:
    """Gains tuned by hand on O1's error (B1): the (L, beta) of the grid whose N-step cascade (Eq. (11)) has the
    lowest mean position error N samples ahead (:func:`fnnlib.metrics.ahead_position_loss`) on the trajectories
    ``x`` (K, T, n) (:func:`fnnlib.feedback.sweep_gains`)."""
    from fnnlib.feedback.cascade import cascade_predict  # noqa: PLC0415
    from fnnlib.feedback.tuning import sweep_gains  # noqa: PLC0415

    def cost(L: float, beta: float) -> float:
        with torch.no_grad():
            return float(ahead_position_loss(x, cascade_predict(f, x[..., :-N, :], Ts, N, Gains(L, beta)), N))
    return sweep_gains(cost, L_grid, beta_grid)


def position_gain_tuning(f: VectorField, x: Tensor, Ts: float, N: int, *, L0: Any, beta0: float, iterations: int,
                         lr: float) -> TunedGains:
    """Gains tuned by gradient on O1's error (B1): :func:`fnnlib.feedback.tune_gains` from ``(L0, beta0)`` with the
    mean position error N samples ahead of the cascade on the trajectories ``x`` as its objective."""
    from fnnlib.feedback.tuning import cascade_forward, tune_gains  # noqa: PLC0415

    def objective(gains, x_, u, mask):  # the judged metric on the tuning trajectories, differentiable in the gains
        return ahead_position_loss(x_, cascade_forward(f, x_, Ts, N, gains, rows=x_.shape[-2] - N), N)
    return tune_gains(f, x, Ts, N,
                      recipe=TuneRecipe(L0=L0, beta0=beta0, objective=objective, iterations=iterations, lr=lr))


def level_errors(f: NeuralODEEnsemble, neural_feedback: Any, x_levels: Tensor, f_levels: Tensor, Ts: float, N: int,
                 L: float | Tensor, beta: float = 0.0) -> tuple[dict[str, Tensor], dict[str, Tensor], float]:
    """The neural ODE ``f``, its neural feedback (an observer of Eq. (12) with ``observe`` and ``predict``, run on
    the stacked state of ``f``'s members) and the linear feedback of Eq. (7) at gain ``L`` on noise-free
    trajectories ``x_levels`` (levels, T, n) with true rates ``f_levels`` (S8, Fig. S10).

    Returns, per member and level (E, levels): the change-rate RMSE of each (the linear feedback's without
    decay), the mean N-step error of each (the Euler rollout, the neural feedback's cascade, the linear cascade
    decayed by ``beta``), and the seconds of the neural feedback's predictions.
    """
    from fnnlib.feedback import cascade_predict, eval_field, rollout_predict  # noqa: PLC0415
    from fnnlib.metrics import rmse_over_time  # noqa: PLC0415
    from fnnlib.observers.linear import LinearFeedback  # noqa: PLC0415

    E = f.size
    xs = stack_members(x_levels, E)
    with torch.no_grad():
        f_nn = f.split(eval_field(f, xs))
    fhat = {"neural_ode": f_nn, "neural_feedback": f.split(neural_feedback.observe(xs).f_hat),
            "linear_feedback": f.split(LinearFeedback(f, Ts, gains=Gains(L), n=2 * E).observe(xs).f_hat)}
    rate = {k: rmse_over_time(v, f_levels.expand_as(v)) for k, v in fhat.items()}
    t0 = time.perf_counter()
    z_nf = f.split(neural_feedback.predict(xs, N))
    seconds = time.perf_counter() - t0
    z = {"neural_ode": f.split(rollout_predict(f, xs, Ts, N)), "neural_feedback": z_nf,
         "linear_feedback": f.split(cascade_predict(f, xs, Ts, N, Gains(L, beta)))}
    return rate, {k: n_step_errors(v, x_levels, N).mean(-1) for k, v in z.items()}, seconds


def outward_increase_fraction(err: Tensor, center: int) -> Tensor:
    """Fraction of steps away from level ``center`` along the last axis where ``err`` increases.

    For levels ordered by a parameter that is nominal at index ``center``
    (uncertainty grows both left and right of it), each adjacent pair
    ``(j, j+1)`` right of the centre counts as increasing if
    ``err[j+1] > err[j]``, and each pair left of it if ``err[j-1] > err[j]``.
    Returns the fraction per leading index, shape ``err.shape[:-1]``.
    """
    m = err.shape[-1]
    if not 0 <= int(center) < m or m < 2:
        raise ValueError(f"centre level {center} must index one of {m} >= 2 levels")
    c = int(center)
    right = err[..., c + 1:] > err[..., c:-1]
    left = err[..., :c] > err[..., 1:c + 1]
    steps = torch.cat([left, right], dim=-1)
    return steps.double().mean(dim=-1)
