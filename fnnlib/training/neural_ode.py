"""Training a neural ODE on random trajectory segments (Chen et al. 2018; App. A.3.2)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import torch
from torch import Tensor, nn
from torchdiffeq import odeint, odeint_adjoint
from tqdm import tqdm

from fnnlib._validation import as_trajectory, check_positive, check_uniform_grid

OPTIMIZERS: dict[str, type[torch.optim.Optimizer]] = {
    "rmsprop": torch.optim.RMSprop,
    "adam": torch.optim.Adam,
}
LOSSES = {
    "l1": lambda pred, true: (pred - true).abs().mean(),
    "mse": lambda pred, true: (pred - true).pow(2).mean(),
}
#: fixed-step solvers need a step size; adaptive ones take tolerances
FIXED_STEP_METHODS = {"euler", "midpoint", "rk4", "explicit_adams", "implicit_adams"}
ADAPTIVE_METHODS = {"dopri5", "dopri8", "bosh3", "fehlberg2", "adaptive_heun", "tsit5"}


@dataclass
class TrainHistory:
    """What training did: the loss per iteration and the wall time."""

    loss: list[float] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def ms_per_iteration(self) -> float:
        return 1000.0 * self.seconds / max(1, len(self.loss))


def sample_segments(x: Tensor, batch_size: int, batch_time: int, generator: torch.Generator) -> Tensor:
    """Draw ``batch_size`` random segments of ``batch_time`` samples.

    Parameters
    ----------
    x : Tensor, shape (n_traj, T, n)

    Returns
    -------
    Tensor, shape (batch_time, batch_size, n): segments stacked along time,
    as torchdiffeq returns solutions.
    """
    n_traj, T, _ = x.shape
    n_starts = T - batch_time + 1
    total = n_traj * n_starts
    if batch_size > total:
        raise ValueError(f"batch_size={batch_size} exceeds the {total} available segments")
    pick = torch.randperm(total, generator=generator)[:batch_size]
    traj, start = pick // n_starts, pick % n_starts
    idx = start[None, :] + torch.arange(batch_time)[:, None]  # (batch_time, batch)
    return x[traj[None, :].expand_as(idx), idx]


def train_neural_ode(
    model: nn.Module,
    t: Tensor,
    x: Tensor,
    *,
    iterations: int = 400,
    batch_size: int = 20,
    batch_time: int = 10,
    lr: float = 1e-3,
    optimizer: str = "rmsprop",
    loss: str = "l1",
    method: str = "dopri5",
    adjoint: bool = True,
    adjoint_seminorm: bool = True,
    rtol: float = 1e-7,
    atol: float = 1e-9,
    seed: int = 0,
    progress: bool = True,
) -> TrainHistory:
    """Fit ``model`` (a vector field ``f(t, x)``) to trajectories by ODE rollouts.

    Each iteration draws ``batch_size`` random segments of ``batch_time``
    samples, integrates the model from each segment's first state over the
    segment's time grid, and descends the mean ``loss`` between rollout and
    data (the torchdiffeq recipe the paper cites).

    Parameters
    ----------
    model : nn.Module
        Vector field called as ``model(t, x)``, ``x`` of shape (batch, n).
    t : Tensor, shape (T,)
        Uniform sample times.
    x : Tensor, shape (T, n) or (n_traj, T, n)
        Training trajectories.
    method : str
        torchdiffeq solver; fixed-step solvers step at the data interval.
    adjoint : bool
        Backpropagate with the adjoint method (``odeint_adjoint``) rather
        than through the solver's operations.
    adjoint_seminorm : bool
        With the adjoint, measure the backward solve's step error on the
        state and adjoint only, not on the parameter-gradient integral
        (Kidger, Chen & Lyons 2021); same gradients up to the tolerance,
        about 4x fewer backward steps here.

    Returns
    -------
    TrainHistory
    """
    x = as_trajectory(x, name="x")
    if x.ndim == 2:
        x = x[None]
    if x.ndim != 3:
        raise ValueError(f"x must have shape (T, n) or (n_traj, T, n), got {tuple(x.shape)}")
    Ts = check_uniform_grid(t)
    if t.numel() != x.shape[1]:
        raise ValueError(f"t has {t.numel()} points but x has {x.shape[1]} samples")
    if optimizer not in OPTIMIZERS:
        raise ValueError(f"unknown optimizer {optimizer!r}; choose one of {sorted(OPTIMIZERS)}")
    if loss not in LOSSES:
        raise ValueError(f"unknown loss {loss!r}; choose one of {sorted(LOSSES)}")
    if method not in FIXED_STEP_METHODS | ADAPTIVE_METHODS:
        raise ValueError(f"unknown solver {method!r}; choose one of {sorted(FIXED_STEP_METHODS | ADAPTIVE_METHODS)}")
    if adjoint and not isinstance(model, nn.Module):
        raise TypeError("the adjoint method needs model to be an nn.Module")
    if int(iterations) < 1 or int(batch_size) < 1 or not 2 <= int(batch_time) <= x.shape[1]:
        raise ValueError(f"need iterations >= 1, batch_size >= 1 and 2 <= batch_time <= T; got "
                         f"{iterations}, {batch_size}, {batch_time} (T = {x.shape[1]})")
    check_positive(lr, name="lr")

    dtype = next(model.parameters()).dtype
    x = x.to(dtype)
    t_seg = (torch.arange(int(batch_time), dtype=dtype) * Ts)
    options = {"step_size": Ts} if method in FIXED_STEP_METHODS else None
    kwargs: dict = {} if method in FIXED_STEP_METHODS else {"rtol": rtol, "atol": atol}
    if adjoint:
        solve = odeint_adjoint
        if adjoint_seminorm and method not in FIXED_STEP_METHODS:
            kwargs["adjoint_options"] = {"norm": "seminorm"}
    else:
        solve = odeint
    opt = OPTIMIZERS[optimizer](model.parameters(), lr=float(lr))
    loss_fn = LOSSES[loss]
    gen = torch.Generator().manual_seed(int(seed))

    history = TrainHistory()
    start = time.perf_counter()
    bar = tqdm(range(int(iterations)), desc="train neural ODE", disable=not progress, leave=False)
    for _ in bar:
        seg = sample_segments(x, int(batch_size), int(batch_time), gen)  # (bt, B, n)
        opt.zero_grad()
        pred = solve(model, seg[0], t_seg, method=method, options=options, **kwargs)
        value = loss_fn(pred, seg)
        value.backward()
        opt.step()
        history.loss.append(value.item())
        bar.set_postfix(loss=f"{history.loss[-1]:.4f}", refresh=False)
    history.seconds = time.perf_counter() - start
    return history
