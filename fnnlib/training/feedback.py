"""Learning the neural feedback part by domain randomization: Eq. (12) `learn_feedback_part`, Alg. 1."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import torch
from torch import Tensor, nn
from tqdm import tqdm

from fnnlib._validation import as_trajectory, check_uniform_grid
from fnnlib.models.ensemble import stack_members
from fnnlib.observers.neural import feedback_rollout
from fnnlib.training.neural_ode import OPTIMIZERS, Recipe, TrainHistory


@dataclass(frozen=True)
class FeedbackRecipe(Recipe):
    """How the neural feedback is trained by Alg. 1 (App. A.3.3); no defaults.

    Attributes
    ----------
    iterations, batch_size : int
        Descent steps; samples per mini-batch, drawn from all cases.
    lr : float
        Learning rate.
    optimizer : str
        A key of :data:`~fnnlib.training.neural_ode.OPTIMIZERS`.
    refresh_every : int
        Iterations between two rollouts of the current ``h`` (1: Alg. 1 literally).
    """

    iterations: int
    batch_size: int
    lr: float
    optimizer: str
    refresh_every: int

    def __post_init__(self) -> None:
        self._check_descent({"iterations": 1, "batch_size": 1, "refresh_every": 1},
                            "iterations, batch_size and refresh_every >= 1")


#: App. A.3.3: RMSprop (the release's optimizer; Alg. 1 says Adam) at 0.01, batch 100, 2000 iterations,
#: the rollout refreshed every iteration as Alg. 1 writes it.
PAPER_FEEDBACK_RECIPE = FeedbackRecipe(iterations=2000, batch_size=100, lr=0.01, optimizer="rmsprop", refresh_every=1)


def randomized_cases(make_system, low: Sequence[float], high: Sequence[float], n_case: int, x0: Tensor,
                     t: Tensor) -> tuple[Tensor, Tensor]:
    r"""The randomized cases of Alg. 1: ``n_case`` systems with parameters spread evenly from ``low`` to ``high``.

    Case ``i`` has parameters ``low + i (high - low) / (n_case - 1)`` (all parameters move together, as the
    paper's 20 spiral cases do: :math:`\omega` {0.8:0.12:3.08}, :math:`\eta` {0.04:0.005:0.135},
    :math:`\varepsilon` {-24:2.4:21.6}), and is simulated from ``x0`` over ``t``.

    Parameters
    ----------
    make_system : callable
        ``make_system(*params)`` -> a :class:`~fnnlib.systems.DynamicalSystem`, e.g. ``fnnlib.systems.Spiral``.
    low, high : sequence of float
        The parameter range, one entry per parameter.
    n_case : int
        Number of cases (>= 2).
    x0 : Tensor, shape (n,)
    t : Tensor, shape (T,)

    Returns
    -------
    (X, params)
        ``X`` (n_case, T, n) float64, the input of :func:`train_neural_feedback`; ``params`` (n_case, P).
    """
    low, high = torch.as_tensor(low, dtype=torch.float64), torch.as_tensor(high, dtype=torch.float64)
    if low.ndim != 1 or low.shape != high.shape:
        raise ValueError(f"low and high must be 1-D of one length, got {tuple(low.shape)} and {tuple(high.shape)}")
    if int(n_case) != n_case or int(n_case) < 2:
        raise ValueError(f"n_case must be an integer >= 2, got {n_case!r}")
    frac = torch.arange(int(n_case), dtype=torch.float64)[:, None] / (int(n_case) - 1)
    params = low + frac * (high - low)
    X = torch.stack([make_system(*p.tolist()).simulate(x0, t) for p in params])
    return X, params


def feedback_loss(h: nn.Module, x_prev: Tensor, fx_prev: Tensor, e_prev: Tensor, x_next: Tensor, Ts: float, *,
                  members: int = 1) -> Tensor:
    r"""Eq. (12) on a mini-batch: mean of :math:`\|x^*_j - x_j\|` over the batch, one value per member.

    The one-step Euler prediction is
    :math:`x_j = x_{j-1} + T_s (f_{neural}(x_{j-1}) + h_{neural}(x_{j-1} - \hat x_{j-1}))`;
    ``x_prev``, ``fx_prev``, ``e_prev = x_{j-1} - x_hat_{j-1}`` and the label ``x_next`` are (batch, E n):
    the stacked states of ``members`` = E feedbacks side by side (a
    :class:`~fnnlib.models.NeuralFeedbackEnsemble`; E = 1 for one :class:`~fnnlib.models.NeuralFeedback`).
    Returns the E losses, shape (E,); member e's depends on member e's columns only.
    """
    x_pred = x_prev + Ts * (fx_prev + h(e_prev))
    diff = (x_next - x_pred).reshape(x_next.shape[0], int(members), -1)
    return torch.linalg.vector_norm(diff, dim=-1).T.contiguous().mean(-1)  # each member's mean in one contiguous pass


@dataclass
class FeedbackHistory(TrainHistory):
    """What Alg. 1 did: ``loss`` (the members' mean, per iteration), ``member_loss`` (per iteration, one per
    member, in the order of ``seeds``) and the wall time."""

    member_loss: list[list[float]] = field(default_factory=list)
    seeds: list[int] = field(default_factory=list)

    def member(self, e: int) -> list[float]:
        """Member ``e``'s Eq. (12) loss per iteration."""
        return [row[e] for row in self.member_loss]


def train_neural_feedback(
    f: nn.Module,
    h: nn.Module,
    t: Tensor,
    X: Tensor,
    recipe: FeedbackRecipe,
    *,
    seed: int | Sequence[int],
    progress: bool = True,
) -> FeedbackHistory:
    r"""Train the feedback ``h`` on randomized cases with the neural ODE ``f`` frozen (Alg. 1).

    Repeat: run the feedback network (``f`` + current ``h``, Eq. (8)) over all cases at once,
    without gradients, to get :math:`\hat x_{i,j}`; build the data sets
    :math:`\{x_{i,j-1}, \hat x_{i,j-1}, x^*_{i,j}\}`; minimise Eq. (12) on random mini-batches drawn
    from all cases. The rollout is refreshed every ``refresh_every`` iterations.

    Several seeds train side by side: with ``seed`` a list of E seeds, ``f`` and ``h`` act on the stacked
    state (batch, E n) (a :class:`~fnnlib.models.NeuralODEEnsemble` of the frozen models and a
    :class:`~fnnlib.models.NeuralFeedbackEnsemble`), every member sees the same cases ``X``, and member e
    draws its own mini-batches from ``seed[e]``. The members' losses add up and their gradients never
    mix, so member e trains bitwise as it would alone (a one-member ensemble with ``seed=[seed[e]]``).

    ``f`` is frozen: it gets no optimizer, ``requires_grad`` is off while training (and restored
    afterwards), and it is evaluated once on ``X``; its parameters are left bitwise unchanged.

    Parameters
    ----------
    f : nn.Module
        Trained neural ODE ``f(t, x)``, ``x`` (batch, E n).
    h : nn.Module
        Feedback ``h(e)``, ``e`` (batch, E n), e.g. :class:`~fnnlib.models.NeuralFeedback` (E = 1).
    t : Tensor, shape (T,)
        Uniform sample times (step ``Ts``).
    X : Tensor, shape (n_case, T, n)
        One trajectory per randomized case (shared by every member).
    recipe : FeedbackRecipe
        Every training setting, e.g. ``PAPER_FEEDBACK_RECIPE.replace(refresh_every=10)``.
    seed : int or sequence of int
        Seed of the mini-batch draws; one per member (E = its length; an int is one member).
    progress : bool
        As :func:`~fnnlib.training.neural_ode.train_neural_ode`.

    Returns
    -------
    FeedbackHistory
        The Eq. (12) loss per iteration (per member and their mean) and the wall time.
    """
    if not isinstance(recipe, FeedbackRecipe):
        raise TypeError(f"recipe must be a FeedbackRecipe (e.g. PAPER_FEEDBACK_RECIPE), got {type(recipe).__name__}")
    iterations, batch_size, lr, optimizer = recipe.iterations, recipe.batch_size, recipe.lr, recipe.optimizer
    refresh_every = recipe.refresh_every
    seeds = [seed] if isinstance(seed, int) else list(seed)
    if not seeds or not all(isinstance(s, int) for s in seeds) or len(set(seeds)) != len(seeds):
        raise ValueError(f"seed must be an int or a list of distinct ints, got {seed!r}")
    if not isinstance(X, Tensor) or X.ndim != 3:
        raise ValueError(f"X must have shape (n_case, T, n), got {tuple(getattr(X, 'shape', ()))}")
    X = as_trajectory(X, name="X")
    n_case, T, n = X.shape
    E, width = len(seeds), len(seeds) * X.shape[-1]
    Ts = check_uniform_grid(t)
    if t.numel() != T:
        raise ValueError(f"t has {t.numel()} points but X has {T} samples per case")
    if T < 2:
        raise ValueError("each case needs at least 2 samples")
    pool = n_case * (T - 1)  # the recipe's own fields are checked when it is made
    if int(batch_size) > pool:
        raise ValueError(f"batch_size={batch_size} exceeds the {pool} available samples")
    if any(p is q for p in f.parameters() for q in h.parameters()):
        raise ValueError("f and h share parameters; the neural ODE must stay frozen")
    dtype = next(h.parameters()).dtype
    need = f"{E} seed(s) of states of dimension {n} need h to map (batch, {width}) to itself"
    try:
        with torch.no_grad():
            probe = h(torch.zeros(1, width, dtype=dtype))
    except (ValueError, RuntimeError) as exc:
        raise ValueError(f"{need}: {exc}") from exc
    if probe.shape != (1, width):
        raise ValueError(f"{need}, got {tuple(probe.shape)}")

    X = stack_members(X.to(dtype), E)  # (n_case, T, E n): every member sees the same cases
    flags = [p.requires_grad for p in f.parameters()]
    history = FeedbackHistory(seeds=seeds)
    start = time.perf_counter()
    try:
        for p in f.parameters():
            p.requires_grad_(False)
        with torch.no_grad():
            fdtype = next(f.parameters(), X).dtype
            fx = f(0.0, X.to(fdtype).reshape(-1, width)).to(dtype).reshape(n_case, T, width)  # frozen: evaluated once
        x_prev, fx_prev = X[:, :-1].reshape(pool, E, n), fx[:, :-1].reshape(pool, E, n)
        x_next = X[:, 1:].reshape(pool, E, n)  # the labels x*_{i,j}
        opt = OPTIMIZERS[optimizer](h.parameters(), lr=float(lr))
        gens = [torch.Generator().manual_seed(s) for s in seeds]
        members = torch.arange(E)
        e_prev = None
        bar = tqdm(range(int(iterations)), desc="train neural feedback", disable=not progress, leave=False)
        for it in bar:
            if it % int(refresh_every) == 0:
                with torch.no_grad():  # Alg. 1: run the feedback network over all cases, build the data sets
                    x_hat = feedback_rollout(fx, X, h, Ts).x_hat
                e_prev = (X[:, :-1] - x_hat[:, :-1]).reshape(pool, E, n)
            pick = torch.stack([torch.randperm(pool, generator=g)[: int(batch_size)] for g in gens], dim=1)  # (B, E)
            batch = [a[pick, members].reshape(-1, width) for a in (x_prev, fx_prev, e_prev, x_next)]  # own draws
            opt.zero_grad()
            value = feedback_loss(h, *batch[:3], batch[3], Ts, members=E)
            value.sum().backward()
            opt.step()
            history.member_loss.append(value.tolist())
            history.loss.append(sum(history.member_loss[-1]) / E)
            bar.set_postfix(loss=f"{history.loss[-1]:.4f}", refresh=False)
    finally:
        for p, flag in zip(f.parameters(), flags):
            p.requires_grad_(flag)
    history.seconds = time.perf_counter() - start
    return history
