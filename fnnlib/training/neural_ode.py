"""Training a neural ODE on random trajectory segments (Chen et al. 2018; App. A.3.2)."""

from __future__ import annotations

import time
import dataclasses
from dataclasses import dataclass, field

import torch
from torch import Tensor, nn
from torchdiffeq import odeint, odeint_adjoint
from tqdm import tqdm

from fnnlib._validation import as_trajectory, check_positive, check_uniform_grid
from fnnlib.feedback.sampling import check_times

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


class Recipe:
    """What every training recipe (a frozen dataclass of settings) can do."""

    def replace(self, **changes):
        """A copy with some settings changed (e.g. a notebook's parameters over a preset)."""
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict:
        """The settings as plain values (for checkpoint metadata); ``type(self)(**d)`` rebuilds it."""
        return dataclasses.asdict(self)

    def _check_descent(self, minimum: dict[str, int], need: str) -> None:
        """The checks every gradient-descent recipe shares, in one place.

        ``self.optimizer`` a key of :data:`OPTIMIZERS`, each field named in ``minimum`` at least its value
        (else ``ValueError("need <need>; got <values>")``), ``self.lr`` finite and positive.
        """
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"unknown optimizer {self.optimizer!r}; choose one of {sorted(OPTIMIZERS)}")
        if any(int(getattr(self, name)) < low for name, low in minimum.items()):
            raise ValueError(f"need {need}; got " + ", ".join(str(getattr(self, name)) for name in minimum))
        check_positive(self.lr, name="lr")


@dataclass(frozen=True)
class ODERecipe(Recipe):
    """How a neural ODE is trained on random segments (the torchdiffeq recipe, App. A.3.2); no defaults.

    Attributes
    ----------
    iterations, batch_size, batch_time : int
        Descent steps; segments per mini-batch; samples per segment.
    lr : float
        Learning rate.
    optimizer : str
        A key of :data:`OPTIMIZERS`.
    loss : str
        A key of :data:`LOSSES`.
    method : str
        torchdiffeq solver; fixed-step solvers step at the data interval.
    adjoint : bool
        Backpropagate with the adjoint method (``odeint_adjoint``) rather
        than through the solver's operations.
    rtol, atol : float
        Adaptive solver tolerances (unused by fixed-step solvers).
    adjoint_seminorm : bool
        With the adjoint, measure the backward solve's step error on the
        state and adjoint only, not on the parameter-gradient integral
        (Kidger, Chen & Lyons 2021); same gradients up to the tolerance,
        about 4x fewer backward steps here.
    """

    iterations: int
    batch_size: int
    batch_time: int
    lr: float
    optimizer: str
    loss: str
    method: str
    adjoint: bool
    rtol: float
    atol: float
    adjoint_seminorm: bool

    def __post_init__(self) -> None:
        if self.loss not in LOSSES:
            raise ValueError(f"unknown loss {self.loss!r}; choose one of {sorted(LOSSES)}")
        if self.method not in FIXED_STEP_METHODS | ADAPTIVE_METHODS:
            raise ValueError(f"unknown solver {self.method!r}; choose one of "
                             f"{sorted(FIXED_STEP_METHODS | ADAPTIVE_METHODS)}")
        self._check_descent({"iterations": 1, "batch_size": 1, "batch_time": 2},
                            "iterations >= 1, batch_size >= 1 and 2 <= batch_time <= T")


#: The spiral's recipe (App. A.3.2 and the authors' release): RMSprop at 1e-3 on the L1 loss, 400 iterations of
#: 20 segments of 10 samples, dopri5 with the adjoint method (seminorm backward) at rtol 1e-5, atol 1e-6.
PAPER_SPIRAL_RECIPE = ODERecipe(iterations=400, batch_size=20, batch_time=10, lr=1e-3, optimizer="rmsprop",
                                loss="l1", method="dopri5", adjoint=True, rtol=1e-5, atol=1e-6,
                                adjoint_seminorm=True)

#: The thrown bottle's recipe (Sec. 5.1 and the authors' release): Adam at 1e-3 on the L1 loss, 1000 iterations of
#: 20 segments of 10 samples, dopri5 with direct back-propagation at rtol 1e-7, atol 1e-9.
PAPER_BOTTLE_RECIPE = ODERecipe(iterations=1000, batch_size=20, batch_time=10, lr=1e-3, optimizer="adam",
                                loss="l1", method="dopri5", adjoint=False, rtol=1e-7, atol=1e-9,
                                adjoint_seminorm=True)


#: A first try on your own system, in seconds rather than minutes: fixed-step RK4 at the data interval,
#: direct back-propagation (no adjoint), Adam at 1e-2 on the MSE, 200 iterations of 20 segments of 10 samples.
#: Move to a paper recipe (dopri5, adjoint, more iterations) once this one works.
QUICK_RECIPE = ODERecipe(iterations=200, batch_size=20, batch_time=10, lr=1e-2, optimizer="adam", loss="mse",
                         method="rk4", adjoint=False, rtol=1e-7, atol=1e-9, adjoint_seminorm=False)


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
    traj, idx = segment_indices(x.shape[0], x.shape[1], batch_size, batch_time, generator)
    return x[traj, idx]


def segment_indices(n_traj: int, T: int, batch_size: int, batch_time: int,
                    generator: torch.Generator) -> tuple[Tensor, Tensor]:
    """The (trajectory, time) indices of :func:`sample_segments`, each (batch_time, batch_size)."""
    n_starts = T - batch_time + 1
    total = n_traj * n_starts
    if batch_size > total:
        raise ValueError(f"batch_size={batch_size} exceeds the {total} available segments")
    pick = torch.randperm(total, generator=generator)[:batch_size]
    traj, start = pick // n_starts, pick % n_starts
    idx = start[None, :] + torch.arange(batch_time)[:, None]  # (batch_time, batch)
    return traj[None, :].expand_as(idx), idx


class ScaledField(nn.Module):
    r"""A segment on uneven times as an ODE in sample units :math:`s`: :math:`dx/ds = \Delta_{\lfloor s\rfloor} f(x, u_{\lfloor s\rfloor})`.

    Sample ``j`` of every segment sits at :math:`s = j`, whatever its own interval, so one solver call on the
    grid ``0, 1, .., batch_time - 1`` integrates a batch of segments with different times.
    ``dt`` (batch_time - 1, batch) the intervals, ``u`` (batch_time, batch, m) or ``None``.
    """

    def __init__(self, model: nn.Module, dt: Tensor, u: Tensor | None):
        super().__init__()
        self.model, self.dt, self.u = model, dt, u

    def forward(self, s: Tensor | float, x: Tensor) -> Tensor:
        k = min(max(int(float(s) + 1e-6), 0), self.dt.shape[0] - 1)
        out = self.model(s, x) if self.u is None else self.model(s, x, self.u[k])
        return self.dt[k][:, None] * out


class HeldInputs(nn.Module):
    """``model(t, x, u(t))`` as an autonomous field for the solver: the inputs of a segment held per sample.

    ``u`` (batch_time, batch, m) holds the input from each sample time ``k Ts`` to the next (zero-order hold).
    """

    def __init__(self, model: nn.Module, u: Tensor, Ts: float):
        super().__init__()
        self.model, self.u, self.Ts = model, u, float(Ts)

    def forward(self, t: Tensor | float, x: Tensor) -> Tensor:
        k = min(max(int(float(t) / self.Ts + 1e-6), 0), self.u.shape[0] - 1)
        return self.model(t, x, self.u[k])


def _inputs_like(u: Tensor, x: Tensor) -> Tensor:
    """``u`` (T, m), shared by every trajectory as :meth:`~fnnlib.systems.base.System.simulate` shares it, or
    (n_traj, T, m), one per trajectory, as (n_traj, T, m) for ``x`` (n_traj, T, n); else a ValueError naming both."""
    n_traj, T = x.shape[:2]
    if u.ndim == 2 and u.shape[0] == T:
        return u.expand(n_traj, T, u.shape[1])
    if u.ndim == 3 and u.shape[:2] == (n_traj, T):
        return u
    raise ValueError(f"u must have shape (T, m) = ({T}, m), shared by every trajectory, or (n_traj, T, m) = "
                     f"({n_traj}, {T}, m), one per trajectory, for x of shape {tuple(x.shape)}; got u of shape "
                     f"{tuple(u.shape)}")


def train_neural_ode(
    model: nn.Module,
    t: Tensor,
    x: Tensor,
    recipe: ODERecipe,
    *,
    seed: int,
    progress: bool = True,
    u: Tensor | None = None,
) -> TrainHistory:
    """Fit ``model`` (a vector field ``f(t, x)``, or ``f(t, x, u)`` with inputs) to trajectories by ODE rollouts.

    Learns :math:`f_{neural}` of Eq. (3) so that the integral of Eq. (2) follows the data.

    For a first try use :data:`QUICK_RECIPE` (RK4, no adjoint, 200 iterations: seconds);
    the paper's recipes (:data:`PAPER_SPIRAL_RECIPE`, dopri5 with the adjoint, 400 iterations)
    take about a minute and a half.

    Each iteration draws ``batch_size`` random segments of ``batch_time``
    samples, integrates the model from each segment's first state over the
    segment's time grid, and descends the mean ``loss`` between rollout and
    data (the torchdiffeq recipe the paper cites).

    Parameters
    ----------
    model : nn.Module
        Vector field called as ``model(t, x)``, ``x`` of shape (batch, n).
    t : Tensor, shape (T,) or (n_traj, T)
        Sample times: uniform (the paper's setting), or uneven, one grid for all or one per trajectory; then
        every segment is integrated along its own intervals (:class:`ScaledField`, the solver's step one sample).
    x : Tensor, shape (T, n) or (n_traj, T, n)
        Training trajectories.
    recipe : ODERecipe
        Every training setting, e.g. ``PAPER_SPIRAL_RECIPE.replace(iterations=...)``.
    seed : int
        Seed of the mini-batch draws.
    progress : bool
        Show a progress bar.
    u : Tensor, shape (T, m) or (n_traj, T, m), optional
        Inputs of a controlled model, row k held over the step after sample k; a (T, m) ``u`` is shared
        by every trajectory (as ``simulate`` broadcasts it).

    Returns
    -------
    TrainHistory
    """
    if not isinstance(recipe, ODERecipe):
        raise TypeError(f"recipe must be an ODERecipe (e.g. PAPER_SPIRAL_RECIPE), got {type(recipe).__name__}")
    r = recipe
    iterations, batch_size, batch_time, lr, optimizer, loss = (r.iterations, r.batch_size, r.batch_time, r.lr,
                                                               r.optimizer, r.loss)
    method, adjoint, rtol, atol = r.method, r.adjoint, r.rtol, r.atol
    x = as_trajectory(x, name="x")
    if x.ndim == 2:
        x = x[None]
    if x.ndim != 3:
        raise ValueError(f"x must have shape (T, n) or (n_traj, T, n), got {tuple(x.shape)}")
    if not isinstance(t, Tensor) or not t.is_floating_point():
        raise TypeError(f"t must be a floating-point tensor of sample times, got {type(t).__name__}")
    if t.shape[-1] != x.shape[1]:
        raise ValueError(f"t has {t.shape[-1]} points but x has {x.shape[1]} samples")
    steps = check_times(t, None, x)  # increasing, finite, one time per sample
    Ts = None
    if t.ndim == 1:
        try:
            Ts, steps = check_uniform_grid(t), None  # the paper's uniform grid: the path as it always was
        except ValueError:
            pass
    if steps is not None:
        steps = steps.to(next(model.parameters()).dtype).expand(x.shape[0], x.shape[1] - 1)
    if adjoint and not isinstance(model, nn.Module):
        raise TypeError("the adjoint method needs model to be an nn.Module")
    if int(batch_time) > x.shape[1]:  # the recipe's own fields are checked when it is made
        raise ValueError(f"need 2 <= batch_time <= T; got {batch_time} (T = {x.shape[1]})")

    dtype = next(model.parameters()).dtype
    x = x.to(dtype)  # the data follow the model's precision (simulate returns float64)
    if u is not None:
        u = _inputs_like(as_trajectory(u, name="u").to(dtype), x)
    t_seg = torch.arange(int(batch_time), dtype=dtype) * (Ts if steps is None else 1.0)
    options = {"step_size": Ts if steps is None else 1.0} if method in FIXED_STEP_METHODS else None
    kwargs: dict = {} if method in FIXED_STEP_METHODS else {"rtol": rtol, "atol": atol}
    if adjoint:
        solve = odeint_adjoint
        if r.adjoint_seminorm and method not in FIXED_STEP_METHODS:
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
        traj, idx = segment_indices(x.shape[0], x.shape[1], int(batch_size), int(batch_time), gen)
        seg = x[traj, idx]  # (bt, B, n)
        if steps is not None:  # uneven times: each segment along its own intervals
            field = ScaledField(model, steps[traj[:-1], idx[:-1]], None if u is None else u[traj, idx])
        else:
            field = model if u is None else HeldInputs(model, u[traj, idx], Ts)
        opt.zero_grad()
        pred = solve(field, seg[0], t_seg, method=method, options=options, **kwargs)
        value = loss_fn(pred, seg)
        value.backward()
        opt.step()
        history.loss.append(value.item())
        bar.set_postfix(loss=f"{history.loss[-1]:.4f}", refresh=False)
    history.seconds = time.perf_counter() - start
    return history
