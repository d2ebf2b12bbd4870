r"""Training neural ODEs with external inputs by an explicit adjoint (App. A.1, Eqs. (13)-(18), Algs. 2-3).

The discrete model is a callable ``step(x, I) -> x_next`` with ``x`` of shape
``(B, n)`` and ``I`` of shape ``(B, m)``: one fixed-step integration
:math:`x_{i+1} = f^d_{neural}(x_i, I_i, \theta)` of a closed loop whose
parameters :math:`\theta` live in a torch ``nn.Module`` (e.g. an RK4 step of
nominal dynamics plus a residual MLP under a baseline controller).

Learning is the optimal-control problem of Eqs. (13)-(14) `eq:oc`,

.. math::
    \min_\theta J = \sum_i l_i(x_i, x_i^r)
    \quad \text{s.t.} \quad x_{i+1} = f^d(x_i, I_i, \theta),

solved with the first-order conditions of its Hamiltonian
:math:`H = J + \sum_i \lambda_{i+1}^\top f^d(x_i, I_i, \theta)`, Eq. (15):
a forward rollout of the state, Eq. (16) `rollout`, a backward rollout of
the costate :math:`\lambda`, Eq. (17) `adjoint`, and the parameter
gradient, Eq. (18) `gradient` (Alg. 2). Alg. 3 feeds that gradient to Adam
over shuffled trajectory segments.

Indices follow the paper (1-based): a segment of ``T`` steps holds the states
:math:`x_1, \dots, x_{T+1}` and inputs :math:`I_1, \dots, I_T`; in code they
are ``x[:, 0..T]`` and ``I[:, 0..T-1]``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import torch
from torch import Tensor, nn
from tqdm import tqdm

from fnnlib._validation import as_trajectory, check_finite, check_positive
from fnnlib.training.neural_ode import Recipe, TrainHistory

#: a discrete model ``x_{i+1} = f^d(x_i, I_i, theta)``: ``(B, n), (B, m) -> (B, n)``
Step = Callable[[Tensor, Tensor], Tensor]

__all__ = ["InputRecipe", "InputTrainHistory", "Step", "adjoint_gradient", "evaluate_loss", "make_segments", "rollout",
           "train_with_inputs", "trajectory_loss"]


@dataclass
class InputTrainHistory(TrainHistory):
    """What :func:`train_with_inputs` did.

    Attributes
    ----------
    loss : list of float
        Loss ``J`` of every Adam update (mean over that update's segments),
        in order; ``len(loss)`` is the number of updates.
    seconds : float
        Total wall time of training.
    epoch_loss : list of float
        Mean loss ``J`` per segment over each epoch (updates weighted by
        their number of segments).
    epoch_seconds : list of float
        Wall time of each epoch.
    segments : int
        Number M of training segments.
    batch_size : int
        Segments per update.
    """

    epoch_loss: list[float] = field(default_factory=list)
    epoch_seconds: list[float] = field(default_factory=list)
    segments: int = 0
    batch_size: int = 0

    @property
    def n_updates(self) -> int:
        """Number of Adam updates taken."""
        return len(self.loss)

    @property
    def ms_per_update(self) -> float:
        """Mean wall time per update in milliseconds."""
        return self.ms_per_iteration


# ----------------------------------------------------------------------------------------------------------------
# checks
# ----------------------------------------------------------------------------------------------------------------


def _check_pair(x_r: Tensor, I: Tensor) -> tuple[int, int, int, int]:
    """Check reference states ``x_r`` (B, T+1, n) against inputs ``I`` (B, T, m); return (B, T, n, m)."""
    as_trajectory(x_r, name="x_r")
    as_trajectory(I, name="I")
    if x_r.ndim != 3:
        raise ValueError(f"x_r must have shape (B, T+1, n), got {tuple(x_r.shape)}")
    if I.ndim != 3:
        raise ValueError(f"I must have shape (B, T, m), got {tuple(I.shape)}")
    B, T1, n = x_r.shape
    if I.shape[0] != B:
        raise ValueError(f"x_r holds {B} trajectories but I holds {I.shape[0]} (shapes {tuple(x_r.shape)} "
                         f"and {tuple(I.shape)})")
    if I.shape[1] != T1 - 1:
        raise ValueError(f"x_r has T+1 = {T1} states per trajectory, so I needs T = {T1 - 1} inputs, got "
                         f"{I.shape[1]} (shapes {tuple(x_r.shape)} and {tuple(I.shape)})")
    if T1 < 2:
        raise ValueError(f"trajectories need at least one step (T >= 1), got shape {tuple(x_r.shape)}")
    return B, T1 - 1, n, I.shape[2]


def _check_W(W: Tensor | Sequence[float] | None, n: int, like: Tensor) -> Tensor:
    """The diagonal weight vector ``W`` of shape (n,), non-negative and finite, on ``like``'s dtype/device."""
    if W is None:
        return torch.ones(n, dtype=like.dtype, device=like.device)
    W = torch.as_tensor(W, dtype=like.dtype, device=like.device)
    if W.ndim != 1 or W.shape[0] != n:
        raise ValueError(f"W must be a weight vector of shape (n,) = ({n},) (the diagonal of the loss weight), "
                         f"got shape {tuple(W.shape)}")
    check_finite(W, name="W")
    if bool((W < 0).any()):
        raise ValueError("W must be non-negative")
    return W


def _trainable_params(params: Iterable[Tensor]) -> list[Tensor]:
    params = [p for p in params if p.requires_grad]
    if not params:
        raise ValueError("no trainable parameters (none with requires_grad=True)")
    return params


def _step(step: Step, x: Tensor, I: Tensor) -> Tensor:
    """One model step with a shape check on what it returns."""
    out = step(x, I)
    if not isinstance(out, Tensor) or out.shape != x.shape:
        got = tuple(out.shape) if isinstance(out, Tensor) else type(out).__name__
        raise ValueError(f"step(x, I) must return the next state of shape {tuple(x.shape)}, got {got}")
    return out


# ----------------------------------------------------------------------------------------------------------------
# Alg. 2: forward rollout, adjoint backward rollout, analytic gradient
# ----------------------------------------------------------------------------------------------------------------


def rollout(step: Step, x1: Tensor, I: Tensor) -> Tensor:
    """Forward rollout of the discrete model, Eq. (16) `rollout`, without a graph.

    ``x_{i+1} = f^d(x_i, I_i, theta)`` for ``i = 1..T`` from ``x_1 = x1``, all
    ``B`` segments at once, under ``torch.no_grad()``.

    Parameters
    ----------
    step : callable
        ``step(x, I) -> x_next``: ``x`` (B, n), ``I`` (B, m) -> (B, n).
    x1 : Tensor, shape (B, n)
        Initial states.
    I : Tensor, shape (B, T, m)
        External inputs.

    Returns
    -------
    Tensor, shape (B, T+1, n)
        ``x[:, 0] = x1`` and ``x[:, i] = x_{i+1}``.
    """
    if x1.ndim != 2 or I.ndim != 3 or I.shape[0] != x1.shape[0]:
        raise ValueError(f"need x1 of shape (B, n) and I of shape (B, T, m) with the same B, got "
                         f"{tuple(x1.shape)} and {tuple(I.shape)}")
    T = I.shape[1]
    x = x1.new_empty(x1.shape[0], T + 1, x1.shape[1])
    x[:, 0] = x1
    with torch.no_grad():
        for i in range(T):
            # x_{i+1} = f^d(x_i, I_i, theta)   (Eq. 16)
            x[:, i + 1] = _step(step, x[:, i], I[:, i])
    return x


def trajectory_loss(x: Tensor, x_r: Tensor, W: Tensor) -> Tensor:
    """The loss ``J`` of Eq. (13) `eq:oc` for a batch of rollouts, averaged over the batch.

    ``J = (1/B) sum_b sum_{i=2}^{T+1} 0.5 (x_i - x_r_i)^T diag(W) (x_i - x_r_i)``;
    ``i = 1`` is left out because ``x_1 = x_r_1``.

    Parameters
    ----------
    x, x_r : Tensor, shape (B, T+1, n)
        Rollout and recorded states.
    W : Tensor, shape (n,)
        Diagonal of the weight matrix.

    Returns
    -------
    Tensor, shape ()
    """
    e = x[:, 1:] - x_r[:, 1:]
    return 0.5 * (e * e * W).sum() / x.shape[0]


def adjoint_gradient(step: Step, params: Iterable[Tensor], x1: Tensor, I: Tensor, x_r: Tensor,
                     W: Tensor | Sequence[float] | None = None) -> tuple[Tensor, list[Tensor], Tensor]:
    """Loss and its parameter gradient by the explicit adjoint method, Alg. 2 (Eqs. (15)-(18)).

    The loss is

    ``J = (1/B) sum_{b=1}^{B} sum_{i=2}^{T+1} l_i,  l_i = 0.5 (x_i - x_r_i)^T diag(W) (x_i - x_r_i)``,

    the per-step terms of Eq. (13) `eq:oc` with ``L_i = diag(W)/2``, summed
    over the segment and averaged over the ``B`` segments (``l_1`` is constant
    since ``x_1 = x_r_1`` is given). Steps:

    1. forward rollout ``x_{i+1} = f^d(x_i, I_i, theta)`` without a graph,
       Eq. (16) `rollout`;
    2. backward rollout of the costate from ``lambda_{T+1} = grad l_{T+1}``,
       ``lambda_i = grad_x l_i + (df^d/dx)^T lambda_{i+1}``, Eq. (17)
       `adjoint`, one step at a time: step ``i`` recomputes
       ``f^d(x_i, I_i, theta)`` from the stored ``x_i`` and takes
       ``(df^d/dx)^T lambda_{i+1}`` and ``lambda_{i+1}^T df^d/dtheta`` in one
       vector-Jacobian product;
    3. ``dH/dtheta = sum_i grad_theta l_i + lambda_{i+1}^T grad_theta f^d``,
       Eq. (18) `gradient` (here ``grad_theta l_i = 0``).

    Memory: the rollout (B, T+1, n), the costate (B, n) and the graph of one
    step; no graph is kept across steps.

    Parameters
    ----------
    step : callable
        ``step(x, I) -> x_next``: ``x`` (B, n), ``I`` (B, m) -> (B, n),
        differentiable in ``x`` and in ``params``.
    params : iterable of Tensor
        theta, e.g. ``model.parameters()``; those without ``requires_grad``
        are skipped.
    x1 : Tensor, shape (B, n)
        Initial states (usually ``x_r[:, 0]``).
    I : Tensor, shape (B, T, m)
        External inputs.
    x_r : Tensor, shape (B, T+1, n)
        Recorded states.
    W : Tensor or sequence of float, shape (n,), optional
        Diagonal loss weights (default ones), e.g. ones on the plant states
        and zeros on controller states.

    Returns
    -------
    loss : Tensor, shape ()
        ``J`` (detached).
    grads : list of Tensor
        ``dJ/dtheta``, one per trainable parameter, shaped like it (zeros
        for parameters ``step`` does not use).
    x : Tensor, shape (B, T+1, n)
        The rollout.
    """
    params = _trainable_params(params)
    B, T, n, _ = _check_pair(x_r, I)
    if x1.shape != (B, n):
        raise ValueError(f"x1 must have shape (B, n) = ({B}, {n}), got {tuple(x1.shape)}")
    W = _check_W(W, n, x_r)

    x = rollout(step, x1.detach(), I)  # (B, T+1, n)   Eq. (16)
    loss = trajectory_loss(x, x_r, W)

    def grad_l(i: int) -> Tensor:
        # grad_x l_i = diag(W) (x_i - x_r_i) / B   (per-segment term of J, batch mean)
        return W * (x[:, i] - x_r[:, i]) / B

    grads = [torch.zeros_like(p) for p in params]
    # lambda_{T+1} = dl_{T+1}/dx_{T+1}   (Eq. 17)
    lambda_ = grad_l(T)
    for i in range(T - 1, -1, -1):
        need_x = i > 0  # x_1 is data: its costate is not needed
        with torch.enable_grad():
            x_i = x[:, i].detach().requires_grad_(need_x)
            x_next = step(x_i, I[:, i])  # f^d(x_i, I_i, theta) recomputed with a one-step graph
            if not x_next.requires_grad:
                raise ValueError("step(x, I) does not depend on x or on params; is it built on the model?")
            inputs = [x_i, *params] if need_x else params
            vjp = torch.autograd.grad(x_next, inputs, grad_outputs=lambda_, allow_unused=True)
        vjp_theta = vjp[1:] if need_x else vjp
        for g, v in zip(grads, vjp_theta):
            if v is not None:
                # dH/dtheta += lambda_{i+1}^T grad_theta f^d(x_i, I_i, theta)   (Eq. 18)
                g.add_(v)
        if need_x:
            # lambda_i = grad_x l_i + (df^d/dx)^T lambda_{i+1}   (Eq. 17)
            lambda_ = grad_l(i) + vjp[0]
    return loss.detach(), grads, x


def evaluate_loss(step: Step, x_r: Tensor, I: Tensor, W: Tensor | Sequence[float] | None = None) -> float:
    """Validation loss: roll out from ``x_r[:, 0]`` and return ``J`` (no gradient).

    ``J = (1/B) sum_b sum_{i=2}^{T+1} 0.5 (x_i - x_r_i)^T diag(W) (x_i - x_r_i)``,
    the loss of :func:`adjoint_gradient`, with the rollout of Eq. (16)
    `rollout` over the whole trajectories.

    Parameters
    ----------
    step : callable
        ``step(x, I) -> x_next``: ``x`` (B, n), ``I`` (B, m) -> (B, n).
    x_r : Tensor, shape (B, T+1, n)
        Recorded states.
    I : Tensor, shape (B, T, m)
        External inputs.
    W : Tensor or sequence of float, shape (n,), optional
        Diagonal loss weights (default ones).

    Returns
    -------
    float
    """
    _, _, n, _ = _check_pair(x_r, I)
    W = _check_W(W, n, x_r)
    x = rollout(step, x_r[:, 0], I)
    return float(trajectory_loss(x, x_r, W))


# ----------------------------------------------------------------------------------------------------------------
# Alg. 3: Adam over shuffled segments
# ----------------------------------------------------------------------------------------------------------------


def make_segments(x_r: Tensor, I: Tensor, segment_length: int) -> tuple[Tensor, Tensor]:
    """Slice trajectories into consecutive segments of ``segment_length`` steps (Alg. 3, line 0).

    Trajectory ``k`` gives segments ``j = 0, 1, ...`` holding states
    ``x_r[k, s j : s j + s + 1]`` and inputs ``I[k, s j : s j + s]`` with
    ``s = segment_length``: each starts from the recorded state at its start,
    and neighbours share their boundary state (a 200-step trajectory gives two
    segments of 100). A remainder of fewer than ``s`` steps at the end of each
    trajectory is dropped.

    Parameters
    ----------
    x_r : Tensor, shape (K, T+1, n)
    I : Tensor, shape (K, T, m)
    segment_length : int
        Steps per segment, ``1 <= s <= T``.

    Returns
    -------
    x_seg : Tensor, shape (K * (T // s), s+1, n)
    I_seg : Tensor, shape (K * (T // s), s, m)
        Segments ordered trajectory by trajectory.
    """
    K, T, n, m = _check_pair(x_r, I)
    s = int(segment_length)
    if not 1 <= s <= T:
        raise ValueError(f"segment_length must be between 1 and the trajectory length T = {T}, got {segment_length}")
    per = T // s
    starts = torch.arange(per) * s  # (per,)
    idx_x = starts[:, None] + torch.arange(s + 1)  # (per, s+1)
    idx_I = starts[:, None] + torch.arange(s)  # (per, s)
    x_seg = x_r[:, idx_x].reshape(K * per, s + 1, n)
    I_seg = I[:, idx_I].reshape(K * per, s, m)
    return x_seg, I_seg


@dataclass(frozen=True)
class InputRecipe(Recipe):
    """How Alg. 3 trains on trajectories with external inputs (:func:`train_with_inputs`); checked when made.

    Attributes
    ----------
    segment_length : int
        Steps per segment ``s``, ``1 <= s <= T`` (the paper splits 200-node
        trajectories into two segments of 100).
    batch_size : int or None
        Segments per Adam update, ``1 <= batch_size <= M``. 1
        is Alg. 3 read literally (one update per segment); ``None`` takes all
        ``M`` segments in one batch (one update per epoch).
    epochs : int
        Passes over the segments (the paper runs 50).
    lr : float
        Adam learning rate.
    """

    segment_length: int
    batch_size: int | None
    epochs: int
    lr: float

    def __post_init__(self) -> None:
        if int(self.segment_length) < 1:
            raise ValueError(f"segment_length must be between 1 and the trajectory length T, got {self.segment_length}")
        if self.batch_size is not None and int(self.batch_size) < 1:
            raise ValueError(f"batch_size must be between 1 and the number of segments M, got {self.batch_size}")
        if int(self.epochs) < 1:
            raise ValueError(f"epochs must be >= 1, got {self.epochs}")
        check_positive(self.lr, name="lr")


def train_with_inputs(
    model: nn.Module,
    step: Step,
    trajectories: tuple[Tensor, Tensor],
    recipe: InputRecipe,
    *,
    seed: int,
    W: Tensor | Sequence[float] | None = None,
    progress: bool = True,
    callback: Callable[[int, InputTrainHistory], bool | None] | None = None,
) -> InputTrainHistory:
    """Train ``model``'s parameters theta on trajectories with external inputs, Alg. 3.

    The trajectories are sliced into ``M`` segments of ``recipe.segment_length``
    steps (:func:`make_segments`). Every epoch shuffles the segments with a
    generator seeded by ``seed`` and walks through them ``recipe.batch_size`` at a
    time; each batch gets the adjoint gradient of Alg. 2
    (:func:`adjoint_gradient`, all its segments rolled out together from their
    recorded first states) and one Adam step
    ``theta <- theta - alpha dH/dtheta`` (``alpha = recipe.lr``). The last batch of
    an epoch may be smaller.

    Parameters
    ----------
    model : nn.Module
        Holds theta (its parameters with ``requires_grad``); trained in place.
    step : callable
        ``step(x, I) -> x_next``: ``x`` (B, n), ``I`` (B, m) -> (B, n), the
        discrete closed loop built on ``model``.
    trajectories : (Tensor, Tensor)
        ``(x_r, I)``: recorded states of shape (K, T+1, n) and inputs of shape
        (K, T, m). Cast to the dtype and device of ``model``'s parameters.
    recipe : InputRecipe
        Segment length, batch size, epochs and learning rate (the paper's, with the network's:
        :data:`~fnnlib.quadrotor.training.PAPER_RESIDUAL`).
    W : Tensor or sequence of float, shape (n,), optional
        Diagonal loss weights (default ones), e.g. ones on the 12 quadrotor
        states and zeros on the 6 controller states.
    seed : int
        Seeds the segment shuffling; the model's initial parameters are the
        caller's. Same seed and initial parameters give bitwise identical
        histories and parameters.
    progress : bool
        Show a tqdm bar over epochs with the epoch loss.
    callback : callable, optional
        ``callback(epoch, history)`` after each epoch (``epoch`` from 0), e.g.
        to record a validation loss with :func:`evaluate_loss`; a truthy
        return value stops training.

    Returns
    -------
    InputTrainHistory
        Per-update and per-epoch losses, wall times, number of updates.
    """
    if not isinstance(model, nn.Module):
        raise TypeError(f"model must be an nn.Module holding theta, got {type(model).__name__}")
    if not callable(step):
        raise TypeError(f"step must be callable as step(x, I), got {type(step).__name__}")
    if not isinstance(trajectories, (tuple, list)) or len(trajectories) != 2:
        raise TypeError("trajectories must be a pair (x_r of shape (K, T+1, n), I of shape (K, T, m))")
    if not isinstance(recipe, InputRecipe):
        raise TypeError(f"recipe must be an InputRecipe, got {type(recipe).__name__}")
    params = _trainable_params(model.parameters())
    x_r, I = trajectories
    _, T, n, _ = _check_pair(x_r, I)
    epochs, lr = int(recipe.epochs), float(recipe.lr)
    dtype, device = params[0].dtype, params[0].device
    x_r, I = x_r.to(dtype=dtype, device=device), I.to(dtype=dtype, device=device)
    W = _check_W(W, n, x_r)
    x_seg, I_seg = make_segments(x_r, I, recipe.segment_length)
    M = x_seg.shape[0]
    bs = M if recipe.batch_size is None else int(recipe.batch_size)
    if not 1 <= bs <= M:
        raise ValueError(f"batch_size must be between 1 and the number of segments M = {M}, got {recipe.batch_size}")

    opt = torch.optim.Adam(params, lr=lr)
    gen = torch.Generator().manual_seed(int(seed))
    history = InputTrainHistory(segments=M, batch_size=bs)
    start = time.perf_counter()
    bar = tqdm(range(epochs), desc="train with inputs", disable=not progress, leave=False)
    for epoch in bar:
        t0 = time.perf_counter()
        order = torch.randperm(M, generator=gen).to(device)
        total = 0.0
        for b in range(math.ceil(M / bs)):
            pick = order[b * bs:(b + 1) * bs]
            xb, Ib = x_seg[pick], I_seg[pick]
            loss, grads, _ = adjoint_gradient(step, params, xb[:, 0], Ib, xb, W)  # Alg. 2
            for p, g in zip(params, grads):
                p.grad = g
            value = float(loss)
            if not math.isfinite(value):
                raise FloatingPointError(f"loss became {value} at epoch {epoch}, update {b}; the rollout diverged "
                                         "(try a smaller lr or shorter segments)")
            # theta <- theta - alpha dH/dtheta, alpha from Adam   (Alg. 3)
            opt.step()
            history.loss.append(value)
            total += value * pick.numel()
        history.epoch_loss.append(total / M)
        history.epoch_seconds.append(time.perf_counter() - t0)
        history.seconds = time.perf_counter() - start
        bar.set_postfix(loss=f"{history.epoch_loss[-1]:.4g}", refresh=False)
        if callback is not None and callback(epoch, history):
            break
    opt.zero_grad(set_to_none=True)
    history.seconds = time.perf_counter() - start
    return history
