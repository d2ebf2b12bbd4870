"""Learning the quadrotor's aerodynamic residual (App. A.5.2) with App. A.1's training, and the MLP baseline."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor, nn
from tqdm import tqdm

from fnnlib.quadrotor.control.dfbc import DFBC
from fnnlib.data.quadrotor import Flights
from fnnlib.metrics import relative_rmse
from fnnlib.models import ACTIVATIONS
from fnnlib.quadrotor.residual import AeroResidual, EnsembleResidual
from fnnlib.quadrotor.presets import PAPER_RESIDUAL_RECIPE
from fnnlib.seeding import seeded
from fnnlib.quadrotor.system import STATE_GROUPS, Quadrotor
from fnnlib.training.external import InputRecipe, InputTrainHistory, make_segments, rollout, train_with_inputs

__all__ = ["PAPER_RESIDUAL", "EnsembleFit", "ResidualRecipe", "closed_loop_step", "convergence_checks", "predict_flights", "state_group_errors",
           "train_residual_ensemble", "train_single_step"]

#: Loss weights of App. A.1's quadratic loss: the 12 vehicle states count, the 6 controller states do not
#: (as in the authors' release).
STATE_WEIGHTS = [1.0] * 12 + [0.0] * 6


@dataclass(frozen=True)
class ResidualRecipe(InputRecipe):
    """The aerodynamic residual (:class:`~fnnlib.quadrotor.residual.AeroResidual`) and its training by Alg. 3.

    Attributes
    ----------
    segment_length, batch_size, epochs, lr
        As in :class:`~fnnlib.training.external.InputRecipe`.
    hidden : tuple of int
        Hidden layer widths (a list is stored as a tuple).
    activation : str
        One of :data:`fnnlib.models.ACTIVATIONS`.
    """

    hidden: tuple[int, ...]
    activation: str

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "hidden", tuple(self.hidden))
        if not self.hidden or any(isinstance(h, bool) or int(h) != h or h < 1 for h in self.hidden):
            raise ValueError(f"hidden must be one or more positive layer widths, got {self.hidden}")
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(ACTIVATIONS)}, got {self.activation!r}")


#: The paper's residual and training (App. A.5.2; :data:`~fnnlib.quadrotor.presets.PAPER_RESIDUAL_RECIPE`):
#: 36 x 36 tanh, segments of 20 steps, 80 segments per Adam update at 5e-3, 50 epochs.
PAPER_RESIDUAL = ResidualRecipe(**PAPER_RESIDUAL_RECIPE)


def closed_loop_step(residual: Callable[[Tensor], Tensor] | None, controller: DFBC, plant: Quadrotor, *,
                     Ts: float, substeps: int = 1, members: int | None = None) -> Callable[[Tensor, Tensor], Tensor]:
    r"""The discrete closed loop :math:`[x, z]_{i+1} = \Phi^d([x, z]_i, \bar\Psi_i)` of App. A.5.2 with the residual.

    ``step(x, I)``: ``x`` (B, 18) closed-loop states, ``I`` (B, 12) commands. With ``members = E`` (an
    :class:`EnsembleResidual`) the state is (B, 18 E): E closed loops side by side, one per member.
    """
    def step(x: Tensor, I: Tensor) -> Tensor:
        if members is None:
            return controller.closed_loop_step(x, I, plant, Ts=Ts, substeps=substeps, a_res_fn=residual)
        B = x.shape[0]
        xe = x.reshape(B, members, 18)
        Ie = I[:, None, :].expand(B, members, I.shape[-1])
        return controller.closed_loop_step(xe, Ie, plant, Ts=Ts, substeps=substeps,
                                           a_res_fn=residual).reshape(B, members * 18)

    return step


@dataclass
class EnsembleFit:
    """Result of :func:`train_residual_ensemble`.

    ``member_loss[k][e]``: member ``e``'s mean training loss (Eq. (13), per segment) after epoch ``k``
    (row 0 = before training); ``val_loss[k][e]`` on the validation flights at epochs ``val_epochs[k]``.
    """

    members: list[AeroResidual]
    history: InputTrainHistory
    member_loss: list[list[float]] = field(default_factory=list)
    val_loss: list[list[float]] = field(default_factory=list)
    val_epochs: list[int] = field(default_factory=list)
    seconds: float = 0.0


def _member_losses(step: Callable[[Tensor, Tensor], Tensor], x_r: Tensor, I: Tensor, E: int) -> list[float]:
    """Per-member mean loss of Eq. (13) over the segments (rollouts from each segment's first state)."""
    x = rollout(step, x_r[:, 0], I)
    e = (x[:, 1:] - x_r[:, 1:]).reshape(x.shape[0], x.shape[1] - 1, E, 18)[..., :12]
    return (0.5 * (e**2).sum(dim=(1, 3)).mean(dim=0)).tolist()


def train_residual_ensemble(seeds: Sequence[int], train: Flights, recipe: ResidualRecipe, *, controller: DFBC,
                            plant: Quadrotor, val: Flights | None = None, val_every: int = 10,
                            dtype: torch.dtype = torch.float32, substeps: int = 1,
                            progress: bool = True) -> EnsembleFit:
    """Train one residual per seed (its random initialisation) with Alg. 3, all as one batch (Q1, Q6).

    Every member sees the same segment order (shuffled with ``seeds[0]``); they differ in their initial
    weights. Per-member training losses are recorded after every epoch, validation losses (full-length
    rollouts of the validation flights) before training, every ``val_every`` epochs and after the last.
    The paper's recipe is :data:`PAPER_RESIDUAL`.
    """
    if not seeds:
        raise ValueError("need at least one seed")
    if not isinstance(recipe, ResidualRecipe):
        raise TypeError(f"recipe must be a ResidualRecipe, got {type(recipe).__name__}")
    if val is not None and val.Ts != train.Ts:
        raise ValueError(f"validation flights have Ts = {val.Ts}, training flights Ts = {train.Ts}; they must match")
    members = []
    for s in seeds:
        with seeded(int(s)):
            members.append(AeroResidual(recipe.hidden, recipe.activation).to(dtype))
    E = len(members)
    ens = EnsembleResidual(members).to(dtype)
    step = closed_loop_step(ens, controller, plant, Ts=train.Ts, substeps=substeps, members=E)
    tile = lambda X: X.to(dtype).repeat(1, 1, E)  # noqa: E731  (K, T, 18) -> (K, T, 18 E)
    x_r, I = tile(train.x), train.Psi.to(dtype)
    x_seg, I_seg = make_segments(x_r, I, recipe.segment_length)
    fit = EnsembleFit(members=[], history=None)  # type: ignore[arg-type]

    def record(epoch: int, hist: object = None) -> None:
        fit.member_loss.append(_member_losses(step, x_seg, I_seg, E))
        if val is not None and ((epoch + 1) % int(val_every) == 0 or epoch + 1 == recipe.epochs):
            fit.val_epochs.append(epoch + 1)
            fit.val_loss.append(_member_losses(step, tile(val.x), val.Psi.to(dtype), E))

    tic = time.perf_counter()
    record(-1)
    fit.history = train_with_inputs(ens, step, (x_r, I), recipe, W=STATE_WEIGHTS * E, seed=int(seeds[0]),
                                    progress=progress, callback=lambda e, h: record(e))
    fit.seconds = time.perf_counter() - tic
    fit.members = [ens.member(e) for e in range(E)]
    return fit


def predict_flights(residual: Callable[[Tensor], Tensor] | None, flights: Flights, *, controller: DFBC,
                    plant: Quadrotor, substeps: int = 1, dtype: torch.dtype = torch.float64) -> Tensor:
    """Roll the closed loop with the model from each flight's first state, driven by its commands (Q2).

    Returns the predicted closed-loop states (K, T+1, 18).
    """
    step = closed_loop_step(residual, controller, plant, Ts=flights.Ts, substeps=substeps)
    return rollout(step, flights.x[:, 0].to(dtype), flights.Psi.to(dtype))


def state_group_errors(x_pred: Tensor, x_true: Tensor) -> dict[str, float]:
    """Relative RMSE per state group ``p, v, Theta, omega`` (:data:`~fnnlib.quadrotor.system.STATE_GROUPS`), Q2.

    ``x_pred``, ``x_true`` (..., 12); each group's RMSE of the error norm over the RMS norm of its true values.
    """
    return {g: relative_rmse(x_pred[..., sl], x_true[..., sl]) for g, sl in STATE_GROUPS.items()}


def convergence_checks(member_loss: np.ndarray, epochs: int) -> dict[str, bool]:
    """Q1's rule on the per-member training losses ``member_loss`` (epochs + 1, E), row 0 before training.

    Every member: final loss <= 10 % of the initial one, and the last 10 % of epochs change it by < 20 %;
    and the members agree: the largest final loss is at most 2x the smallest.
    """
    final, first = member_loss[-1], member_loss[0]
    tail = member_loss[int(np.floor(0.9 * epochs))]
    return {
        "every initialisation: final <= 10 % of initial loss": bool(np.all(final <= 0.1 * first)),
        "every initialisation: last 10 % of epochs change the loss < 20 %": bool(np.all(np.abs(final - tail) <= 0.2 * tail)),
        "initialisations agree: max/min final loss <= 2": bool(final.max() <= 2 * final.min()),
    }


def train_single_step(net: nn.Module, x: Tensor, labels: Tensor, *, epochs: int, batch_size: int, lr: float,
                      seed: int, progress: bool = False) -> list[float]:
    """Fit a feed-forward residual to single-step labels by mean squared error (the MLP baseline).

    ``x`` (M, 12) states, ``labels`` (M, 3) accelerations; Adam, shuffled mini-batches. Returns the
    per-epoch mean loss. The recipe of the paper run is :data:`~fnnlib.quadrotor.presets.PAPER_MLP_RECIPE`.
    """
    if x.shape[0] != labels.shape[0] or labels.shape[-1] != 3 or x.shape[-1] != 12:
        raise ValueError(f"need x (M, 12) and labels (M, 3), got {tuple(x.shape)} and {tuple(labels.shape)}")
    if not (torch.isfinite(x).all() and torch.isfinite(labels).all()):
        raise ValueError("training pairs hold NaN or inf")
    dtype = next(net.parameters()).dtype
    x, labels = x.to(dtype), labels.to(dtype)
    g = torch.Generator().manual_seed(int(seed))
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    losses = []
    for _ in tqdm(range(int(epochs)), desc="MLP", disable=not progress, leave=False):
        perm = torch.randperm(x.shape[0], generator=g)
        total = 0.0
        for i in range(0, x.shape[0], batch_size):
            idx = perm[i:i + batch_size]
            loss = torch.mean((net(x[idx]) - labels[idx]) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += loss.item() * idx.numel()
        losses.append(total / x.shape[0])
    return losses
