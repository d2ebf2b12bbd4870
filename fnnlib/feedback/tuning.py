r"""The cascade of Sec. 3.3 made differentiable, and ``tune_gains``: L and beta learned from data (claim B1).

The paper names the choice of the gain :math:`L` and the decay rate :math:`\beta` of Eq. (11) its open
problem. Here both are parameters of a module, :class:`CascadeGains`, whose parametrization keeps every
gain admissible by construction:

* diagonal: :math:`L = L_{max}\,\sigma(\ell)` elementwise (:math:`\sigma` the logistic function);
* full: :math:`L = L_{max}\,P(I + P)^{-1}` with :math:`P = M M^T + \varepsilon I`, symmetric with
  eigenvalues :math:`L_{max}\,p/(1+p) \in (0, L_{max})`;
* :math:`\beta = \mathrm{softplus}(b)`.

With :math:`L_{max} = 1/T_s` (the default) every eigenvalue of :math:`T_s L` lies in (0, 1), so
:math:`L` is positive definite (Theorem 1) and :math:`\rho(I - T_s L) < 1` (Eq. (25)) for any raw
parameters, and the error of Eq. (25) decays without oscillating. :func:`cascade_forward` runs the same
layers as :func:`~fnnlib.feedback.cascade.cascade_predict` (one batched network call and one scan per
layer) with gradients to the gains, to ``beta`` and to the model. :func:`tune_gains` descends the N-step
prediction error through it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import torch
from torch import Tensor, nn
from torch.nn import functional as TF

from fnnlib._validation import check_positive
from fnnlib.feedback.cascade import _checked, measured, run_cascade
from fnnlib.feedback.gaps import first_layer, measure_fn, start_state
from fnnlib.feedback.layer import check_inputs, check_model_dtype
from fnnlib.feedback.measured import MeasuredFeedback, check_output_gain
from fnnlib.feedback.options import Gains, Measurement, record_sampling
from fnnlib.feedback.sampling import Steps, longest
from fnnlib.feedback.types import VectorField


def _inverse_softplus(y: float) -> float:
    return y + math.log(-math.expm1(-y))


class CascadeGains(nn.Module):
    r"""Base gain :math:`L` and decay rate :math:`\beta` of Eq. (11) as trainable, always-admissible parameters.

    Parameters
    ----------
    n : int
        State dimension.
    Ts : float
        Sample step; sets the bound :math:`L_{max}` (default :math:`1/T_s`).
    L0 : float or Tensor (n,)
        Initial gain (diagonal; for ``full`` the initial gain is ``L0`` times I). Must lie in (0, L_max).
    beta0 : float
        Initial decay rate, > 0.
    full : bool
        A full symmetric positive-definite gain instead of a diagonal one.
    L_max : float, optional
        Upper bound of the gain's eigenvalues; at most :math:`2/T_s` (Eq. (25)).
    eps : float
        The :math:`\varepsilon` of the full parametrization.
    members : int
        The state is ``members`` equal blocks (the stacked members of an ensemble,
        :class:`~fnnlib.models.scaled.ScaledField`), each with a decay rate of its own: :math:`\beta` is then
        (members,), block ``e`` decays as :math:`L_e e^{-\beta_e i}`. Diagonal gains only, so that the blocks
        never mix and each is tuned as it would be alone.
    """

    def __init__(self, n: int, Ts: float, *, L0: float | Tensor, beta0: float, full: bool = False,
                 L_max: float | None = None, eps: float = 1e-3, members: int = 1):
        super().__init__()
        self.n, self.Ts, self.full, self.eps = int(n), check_positive(Ts, name="Ts"), bool(full), float(eps)
        if isinstance(members, bool) or int(members) != members or members < 1 or self.n % int(members):
            raise ValueError(f"members must be an integer >= 1 dividing n = {self.n}, got {members!r}")
        self.members = int(members)
        if self.members > 1 and self.full:
            raise ValueError("members > 1 needs a diagonal gain (a full gain would mix the members' blocks)")
        self.L_max = 1.0 / self.Ts if L_max is None else check_positive(L_max, name="L_max")
        if self.L_max * self.Ts > 2.0:
            raise ValueError(f"L_max = {self.L_max} allows rho(I - Ts L) >= 1 (Eq. (25)); it must be <= 2/Ts")
        L0 = torch.as_tensor(L0, dtype=torch.float64).expand(self.n).clone()
        if not bool(((L0 > 0) & (L0 < self.L_max)).all()):
            raise ValueError(f"initial gain L0 must lie in (0, L_max = {self.L_max:.4g}), got {L0.tolist()}")
        beta0 = float(beta0)
        if not (beta0 > 0 and math.isfinite(beta0)):
            raise ValueError(f"initial decay rate beta0 must be finite and > 0 (softplus), got {beta0!r}")
        s = L0 / self.L_max  # the fraction of L_max
        if self.full:  # P = M M^T + eps I with eigenvalue p = s / (1 - s) along each axis
            p = (s / (1 - s)).clamp_min(2 * self.eps)
            self.raw_L = nn.Parameter(torch.diag((p - self.eps).sqrt()))
        else:
            self.raw_L = nn.Parameter(torch.log(s / (1 - s)))  # logit
        raw_beta = torch.tensor(_inverse_softplus(beta0), dtype=torch.float64)
        self.raw_beta = nn.Parameter(raw_beta if self.members == 1 else raw_beta.repeat(self.members))

    def L(self) -> Tensor:
        """The base gain: (n,) diagonal, or (n, n) symmetric for ``full``; float64."""
        if not self.full:
            return self.L_max * torch.sigmoid(self.raw_L)
        eye = torch.eye(self.n, dtype=self.raw_L.dtype)
        P = self.raw_L @ self.raw_L.T + self.eps * eye
        G = self.L_max * torch.linalg.solve(eye + P, P)  # L_max P (I + P)^{-1} (P and (I+P)^{-1} commute)
        return 0.5 * (G + G.T)

    def beta(self) -> Tensor:
        """The decay rate, softplus of its raw parameter (float64 scalar; (members,) with ``members > 1``)."""
        return TF.softplus(self.raw_beta)

    def L_stack(self, N: int, dtype: torch.dtype) -> list[Tensor]:
        r"""Eq. (11) with gradients: :math:`L_i = L e^{-\beta i}`, ``i = 0 .. N-1``, in ``dtype``."""
        L, beta = self.L(), self.beta()
        if self.members > 1:  # each block's own decay rate, on its n / members states
            beta = beta.repeat_interleave(self.n // self.members)
        return [(L * torch.exp(-beta * i)).to(dtype) for i in range(int(N))]

    def values(self) -> dict:
        """The current ``L`` (list) and ``beta`` (float; a list of one per member with ``members > 1``)."""
        with torch.no_grad():
            beta = self.beta()
            return {"L": self.L().tolist(), "beta": float(beta) if self.members == 1 else beta.tolist()}


def cascade_forward(f: VectorField, x: Tensor, Ts: float, N: int, gains: CascadeGains, *, u: Tensor | None = None,
                    return_all: bool = False, rows: int | None = None) -> Tensor:
    r"""The N-step cascade of Sec. 3.3 with the gains of ``gains``, differentiable in ``gains``, ``f`` and ``x``.

    The layers and their order of operations are those of
    :func:`~fnnlib.feedback.cascade.cascade_predict` (same math; ``cascade_predict`` runs without a
    graph and checks a fixed gain instead). ``x`` (..., T, n), ``u`` (..., T, m) optional;
    returns (..., T, n), row k predicting :math:`x(t_{k+N})`; with ``rows``, only the first ``rows``
    of them (see :func:`~fnnlib.feedback.cascade.run_cascade`).
    """
    x, Ts, N = _checked(x, Ts, N)
    if x.shape[-1] != gains.n:
        raise ValueError(f"x has state dimension {x.shape[-1]} but the gains are for n = {gains.n}")
    check_model_dtype(f, x)
    if u is not None:
        check_inputs(u, x)
    return run_cascade(f, x, gains.L_stack(N, x.dtype), Ts, diagonal=not gains.full, return_all=return_all, u=u,
                       rows=rows)


class ObserverGain(nn.Module):
    r"""The output gain :math:`L_y` (n, p) of a :class:`~fnnlib.feedback.measured.MeasuredFeedback`, trainable
    and free (it starts from the observer's own, stabilising gain); :func:`tune_gains` checks the result with
    :func:`~fnnlib.feedback.measured.check_output_gain`."""

    def __init__(self, observer: MeasuredFeedback):
        super().__init__()
        self.raw_L = nn.Parameter(observer.L.clone())

    def forward(self) -> Tensor:
        return self.raw_L


#: A closed-loop cost: ``objective(gains, x, u, mask)`` -> a scalar tensor, differentiable in ``gains``
#: (a :class:`CascadeGains`); ``x`` (..., T, n) the tuning data, ``u`` its inputs or ``None``, ``mask`` its gaps or
#: ``None``.
Objective = Callable[["CascadeGains", Tensor, "Tensor | None", "Tensor | None"], Tensor]


@dataclass(frozen=True)
class TuneRecipe:
    """The settings of :func:`tune_gains` in one checked, immutable object.

    The gain ``L`` of Eq. (7) and the decay rate ``beta`` of Eq. (11) are learned through the cascade of Sec. 3.3.

    ``L0`` (scalar or a list of n) and ``beta0``: the initial gain and decay rate (:class:`CascadeGains`);
    ``iterations`` and ``lr``: Adam steps and learning rate; ``full``, ``L_max``: the gain's form and bound;
    ``train_model``: also descend on the model; ``tune_observer``: also descend on the output gain of the
    first layer's observer (partial measurements; off by default: on noisy records it fits the noise of the
    tuning record, measured by ``benchmarks/study_partial_cascade.py``); ``settle``: the first start
    times not scored (an observer's start-up transient, where any large gain helps and which a prediction
    made after it never meets); ``members``: the state is that many stacked members of an ensemble, each tuned
    as it would be alone (:class:`CascadeGains`; their losses add, their gradients never mix); ``objective``:
    a closed-loop cost ``objective(gains, x, u, mask)`` (:data:`Objective`) to descend instead of the N-step
    prediction error, e.g. the error of the loop the gains will serve, on training data. Checked in
    ``__post_init__``; replace a field with ``dataclasses.replace(recipe, lr=0.05)``. :data:`DEFAULT_TUNE_RECIPE` holds the values of the
    own-system chapter.
    """

    L0: float | tuple = 5.0
    beta0: float = 0.05
    iterations: int = 60
    lr: float = 0.1
    full: bool = False
    L_max: float | None = None
    train_model: bool = False
    tune_observer: bool = False
    settle: int = 0
    members: int = 1
    objective: Objective | None = None

    def __post_init__(self):
        L0 = self.L0 if isinstance(self.L0, (int, float)) else _as_tuple(self.L0)
        object.__setattr__(self, "L0", L0)
        vals = [L0] if isinstance(L0, (int, float)) else list(torch.tensor(L0, dtype=torch.float64).abs().reshape(-1).tolist())
        if not vals or not all(math.isfinite(v) and v > 0 for v in vals):
            raise ValueError(f"TuneRecipe.L0 must be > 0 and finite (a scalar or one per state), got {self.L0!r}")
        if not (math.isfinite(float(self.beta0)) and float(self.beta0) > 0):
            raise ValueError(f"TuneRecipe.beta0 must be finite and > 0, got {self.beta0!r}")
        if isinstance(self.iterations, bool) or int(self.iterations) != self.iterations or int(self.iterations) < 1:
            raise ValueError(f"TuneRecipe.iterations must be an integer >= 1, got {self.iterations!r}")
        check_positive(self.lr, name="TuneRecipe.lr")
        if self.L_max is not None:
            check_positive(self.L_max, name="TuneRecipe.L_max")
        if isinstance(self.settle, bool) or not isinstance(self.settle, int) or self.settle < 0:
            raise ValueError(f"TuneRecipe.settle must be an integer >= 0, got {self.settle!r}")
        if isinstance(self.members, bool) or not isinstance(self.members, int) or self.members < 1:
            raise ValueError(f"TuneRecipe.members must be an integer >= 1, got {self.members!r}")
        for name in ("full", "train_model", "tune_observer"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"TuneRecipe.{name} must be a bool, got {getattr(self, name)!r}")
        if self.objective is not None and not callable(self.objective):
            raise TypeError(f"TuneRecipe.objective must be a callable objective(gains, x, u, mask), got "
                            f"{type(self.objective).__name__}")


#: :func:`tune_gains`'s settings of the own-system chapter (L0 = 5, beta0 = 0.05, 60 Adam steps at lr 0.1).
DEFAULT_TUNE_RECIPE = TuneRecipe()

@dataclass
class TunedGains:
    """What :func:`tune_gains` found: the gains module, the tuned base gain ``L`` (the gain of Eq. (7); a float64
    tensor, (n,) diagonal or (n, n)), the decay rate ``beta`` of Eq. (11) (a float; a list of one per member with
    ``members > 1``), the loss per iteration, the seconds taken and the first layer's observer (with one).
    :meth:`schedule` is the :class:`~fnnlib.feedback.options.Gains` the cascade takes."""

    gains: CascadeGains
    L: Tensor
    beta: float | list
    loss: list[float] = field(default_factory=list)
    seconds: float = 0.0
    observer: MeasuredFeedback | None = None

    def schedule(self, *, allow_unstable: bool = False) -> Gains:
        """The tuned gain schedule of Eq. (11), ``Gains(L, beta)``, as :func:`~fnnlib.cascade_predict` takes it
        (one decay rate: with ``members > 1`` each member has its own, and the cascade takes one)."""
        if not isinstance(self.beta, float):
            raise ValueError(f"the gains were tuned per member (beta = {self.beta}); the cascade takes one decay rate")
        return Gains(self.L, self.beta, allow_unstable=allow_unstable)


def prediction_loss(z: Tensor, y: Tensor, N: int) -> Tensor:
    r"""Mean squared N-step error :math:`\|z^{(N)}_k - y_{k+N}\|^2` over every start with a sample N steps later."""
    return (z[..., : y.shape[-2] - N, :] - y[..., N:, :]).pow(2).sum(-1).mean()


def tune_gains(f: VectorField, y: Tensor, Ts: float | None, N: int, recipe: TuneRecipe = DEFAULT_TUNE_RECIPE, *,
               u: Tensor | None = None, measurement: Measurement | None = None,
               observer: MeasuredFeedback | None = None) -> TunedGains:
    r"""Learn the base gain :math:`L` and the decay rate :math:`\beta` of Eq. (11) from measured trajectories (B1).

    Gradient descent (Adam, full batch) on the N-step prediction error of the cascade,
    :func:`prediction_loss` of :func:`cascade_forward` against the measured samples ``y`` N steps later.
    The targets are measurements, noisy like the inputs: with noise independent of the state, the
    expected loss is the error against the truth plus a constant, so minimising it trades the
    correction the feedback brings against the noise it amplifies (:func:`~fnnlib.feedback.noise.noise_amplification`).
    Tune on data kept apart from the data you evaluate on: ``y`` is the tuning set only.

    Parameters
    ----------
    f : callable
        The learned field ``f(t, x)`` (or ``f(t, x, u)`` with ``u``); frozen unless ``recipe.train_model``.
    y : Tensor, shape (T, n) or (B, T, n); (..., T, p) with an ``observer``
        Tuning measurements, in ``f``'s dtype.
    Ts, N
        Sample step (``None`` with ``measurement.t``) and prediction horizon (cascade depth).
    recipe : TuneRecipe
        Every setting of the descent (initial gains, steps, learning rate, the gain's form, what else is
        tuned, the start times not scored, the members, an objective), checked on construction; by default
        :data:`DEFAULT_TUNE_RECIPE`. With ``members > 1`` the state (and the outputs) are that many stacked
        members of an ensemble (e.g. a :class:`~fnnlib.models.scaled.ScaledField` of several seeds with a
        block-diagonal observer), each with its own gains and decay rate; the result's ``beta`` is then a list.
    u : Tensor, shape like ``y`` with m columns, optional
        Inputs of a controlled model.
    measurement : Measurement, optional
        The record's missing samples (``mask``; a NaN in ``y`` means the same: the first layer runs open loop
        through them, :mod:`fnnlib.feedback.gaps`, and the error is scored on present targets only) and its
        sample times ``t`` when they are uneven (:mod:`fnnlib.feedback.sampling`). Its ``C`` and ``x0`` are
        the observer's: give them to the :class:`~fnnlib.feedback.measured.MeasuredFeedback`.
    observer : MeasuredFeedback, optional
        Partial measurements ``y = C x`` (or ``h(x)``): the first layer is this observer, the tuned ``L`` and
        ``beta`` are those of the full-state layers after it (:mod:`fnnlib.feedback.cascade`), and the error is
        that of the predicted outputs. The result's ``observer`` is the one used (tuned with
        ``recipe.tune_observer``).
    """
    if not isinstance(recipe, TuneRecipe):
        raise TypeError(f"recipe must be a TuneRecipe (e.g. fnnlib.DEFAULT_TUNE_RECIPE), got {type(recipe).__name__}")
    objective = recipe.objective
    t, mask = record_sampling(measurement)
    meas, dt, N, n = measured(f, y, Ts, N, t=t, u=u, mask=mask, observer=observer)
    if recipe.tune_observer and observer is None:
        raise ValueError("tune_observer=True needs an observer (the first layer on partial measurements)")
    x = meas.y
    if x.shape[-2] <= N + recipe.settle:
        raise ValueError(f"the tuning data need more than N + settle = {N + recipe.settle} samples per trajectory, "
                         f"got {x.shape[-2]}")
    L0 = recipe.L0 if isinstance(recipe.L0, (int, float)) else torch.tensor(recipe.L0, dtype=torch.float64)
    gains = CascadeGains(n, longest(dt), L0=L0, beta0=recipe.beta0, full=recipe.full, L_max=recipe.L_max,
                         members=recipe.members)
    params = list(gains.parameters())
    obs_gain = None
    if observer is not None:
        observer.gain_for(dt)  # a stabilising start (raises if not)
        if recipe.tune_observer:
            obs_gain = ObserverGain(observer)
            params += list(obs_gain.parameters())
    if recipe.train_model:
        if not isinstance(f, nn.Module):
            raise TypeError("train_model=True needs f to be an nn.Module")
        params += [p for p in f.parameters() if p.requires_grad]
    frozen = [] if recipe.train_model or not isinstance(f, nn.Module) else [p for p in f.parameters() if p.requires_grad]
    opt = torch.optim.Adam(params, lr=float(recipe.lr))
    result = TunedGains(gains, [], 0.0)
    start = time.perf_counter()
    try:
        for p in frozen:  # a frozen model gets no gradient (and keeps no .grad)
            p.requires_grad_(False)
        fixed_first = None
        if observer is not None and obs_gain is None and not recipe.train_model and objective is None:
            with torch.no_grad():  # the observer layer does not change: solve it once
                fixed_first = _observer_layer(f, meas, dt, n, observer, None)
        for _ in range(int(recipe.iterations)):
            opt.zero_grad()
            loss = _loss(f, meas, dt, N, gains, objective, observer, obs_gain, fixed_first, recipe.settle)
            loss.backward()
            opt.step()
            result.loss.append(loss.item())
    finally:
        for p in frozen:
            p.requires_grad_(True)
    result.seconds = time.perf_counter() - start
    if observer is not None:
        result.observer = observer
        if obs_gain is not None:
            with torch.no_grad():
                tuned = obs_gain().detach().clone()
            result.observer = MeasuredFeedback(observer.f, observer.Ts, L=tuned, measurement=observer.measurement,
                                               A=observer._A, allow_unstable=observer._allow)
            result.observer.gain_for(dt)  # still stabilising after the descent (raises if not)
    with torch.no_grad():
        result.L = gains.L().detach().clone()
    result.beta = gains.values()["beta"]
    return result


def _observer_layer(f: VectorField, meas, dt: Steps, n: int, observer: MeasuredFeedback,
                    obs_gain: ObserverGain | None) -> Tensor:
    """The first layer's output (..., T, n): the observer's one-step estimates."""
    L = observer.gain_for(dt) if obs_gain is None else obs_gain()
    _, _, z1, _ = first_layer(f, meas, L.to(meas.y.dtype), dt, start_state(meas, n, observer.x0), diagonal=False)
    return z1


def _loss(f: VectorField, meas, dt: Steps, N: int, gains: CascadeGains, objective: Objective | None,
          observer: MeasuredFeedback | None, obs_gain: ObserverGain | None, fixed_first: Tensor | None,
          settle: int = 0) -> Tensor:
    """One iteration's cost: ``objective``, or the N-step prediction error (through the gaps, on present targets)."""
    x = meas.y
    if objective is not None:
        loss = objective(gains, x, meas.u, meas.mask)
        if not isinstance(loss, Tensor) or loss.numel() != 1 or not loss.requires_grad:
            raise ValueError("the objective must return a scalar tensor differentiable in the gains")
        return loss.reshape(())
    T = x.shape[-2]
    if meas.mask is None and observer is None and settle == 0:
        # only the T - N starts with a target N samples later are run (exact: the cascade is causal)
        return prediction_loss(run_cascade(f, x, gains.L_stack(N, x.dtype), dt, diagonal=not gains.full, u=meas.u,
                                           rows=T - N), x, N)
    L_stack = gains.L_stack(N, x.dtype)
    if observer is not None:
        z1 = fixed_first if fixed_first is not None else _observer_layer(f, meas, dt, gains.n, observer, obs_gain)
    else:
        x0 = start_state(meas, gains.n, None)
        _, _, z1, _ = first_layer(f, meas, L_stack[0], dt, x0, diagonal=not gains.full)
    z = run_cascade(f, z1, L_stack[1:], dt, diagonal=not gains.full, u=meas.u, first_depth=1, rows=T - N)
    measure = measure_fn(meas, x.dtype)
    if measure is not None:
        z = measure(z)  # the predicted outputs
    present = (torch.ones_like(x) if meas.mask is None else meas.mask.to(x.dtype))[..., N:, :]
    if settle:
        present = torch.cat([torch.zeros_like(present[..., :settle, :]), present[..., settle:, :]], -2)
    err = (z - x[..., N:, :]).pow(2) * present  # targets N samples later, measured
    return err.sum() / present.sum().clamp_min(1.0) * x.shape[-1]


def _as_tuple(v) -> tuple:
    """A vector or matrix setting as nested tuples of floats (hashable, for the frozen recipe)."""
    t = torch.as_tensor(v, dtype=torch.float64)
    return tuple(t.tolist()) if t.ndim == 1 else tuple(tuple(r) for r in t.tolist())


@dataclass
class GainSweep:
    """What :func:`sweep_gains` found: the best ``L`` and ``beta``, their ``cost``, and ``table``, the cost of
    every pair (``len(L_grid)`` rows by ``len(beta_grid)`` columns; ``inf`` where the cost was not finite)."""

    L: float
    beta: float | list
    cost: float
    L_grid: list[float]
    beta_grid: list[float]
    table: list[list[float]]

    def as_dict(self) -> dict:
        """Plain values, for a results file."""
        return {"L": self.L, "beta": self.beta, "cost": self.cost, "L_grid": self.L_grid,
                "beta_grid": self.beta_grid, "table": self.table}


def sweep_gains(cost: Callable[[float, float], float], L_grid, beta_grid) -> GainSweep:
    r"""A grid search over the scalar gain :math:`L` and the decay rate :math:`\beta` of Eq. (11).

    What an engineer does by hand (a few values of each, kept where the cost on *training* data is lowest),
    or a batched closed-loop tuning where ``cost`` is the loop's error (e.g. the tracking error of flights).
    ``cost(L, beta)`` -> a float (lower is better); a non-finite cost (a diverged run) counts as ``inf``
    and is never kept. Ties go to the first pair in row-major order (``L`` outer). Raises ``ValueError``
    before any call on an empty grid, a gain <= 0 or a decay < 0, and when no pair has a finite cost.
    """
    if not callable(cost):
        raise TypeError(f"cost must be a callable cost(L, beta) -> float, got {type(cost).__name__}")
    Ls, betas = ([float(v) for v in torch.as_tensor(g, dtype=torch.float64).reshape(-1).tolist()]
                 for g in (L_grid, beta_grid))
    if not Ls or not betas:
        raise ValueError(f"sweep_gains needs non-empty grids, got L_grid {Ls}, beta_grid {betas}")
    if not all(math.isfinite(v) and v > 0 for v in Ls):
        raise ValueError(f"every gain of L_grid must be finite and > 0, got {Ls}")
    if not all(math.isfinite(v) and v >= 0 for v in betas):
        raise ValueError(f"every decay rate of beta_grid must be finite and >= 0, got {betas}")
    table = []
    for L in Ls:
        row = [float(cost(L, b)) for b in betas]
        table.append([c if math.isfinite(c) else math.inf for c in row])
    i, j = min(((i, j) for i in range(len(Ls)) for j in range(len(betas))), key=lambda ij: table[ij[0]][ij[1]])
    if not math.isfinite(table[i][j]):
        raise ValueError("sweep_gains: no pair of the grid has a finite cost")
    return GainSweep(Ls[i], betas[j], table[i][j], Ls, betas, table)


@dataclass(frozen=True)
class GainChoice:
    """What :func:`choose_gain` kept: ``index`` (the candidate kept), ``best`` (the candidate of lowest mean
    error), ``improvement`` (the mean over the windows of the reference's error minus ``best``'s), ``se`` (its
    standard error over the windows), ``windows`` (how many), and ``means`` (each candidate's mean error)."""

    index: int
    best: int
    improvement: float
    se: float
    windows: int
    means: tuple[float, ...]


def choose_gain(errors: Tensor, *, reference: int = 0, windows: int = 8, z: float = 2.0) -> GainChoice:
    r"""Keep a feedback gain only where it earns its place on the tuning record, else the reference.

    The errors are N-step errors of the cascade of Sec. 3.3, one row per gain of Eq. (7) (with the decay of
    Eq. (11)); the reference row is typically the feedback switched off, the rollout of Eq. (2).

    A gain chosen by the lowest error on a noisy tuning record can lose to the feedback switched off on the
    next record: its gain on the tuning record was the noise's. The rule: cut the start times into ``windows``
    consecutive windows (the N-step errors of nearby start times are correlated, windows much less so), take
    each candidate's mean error per window, and keep the candidate of lowest overall mean only when its paired
    improvement over ``reference`` (e.g. ``L = 0``: the open-loop rollout from the observer, the first layer)
    exceeds ``z`` standard errors over the windows. Otherwise keep ``reference``.

    Parameters
    ----------
    errors : Tensor, shape (K, T) or (K, B, T)
        Each candidate's error per start time on the *tuning* data (per record with B), NaN where its target
        is missing (such start times are left out of every window's mean).
    reference : int
        The candidate kept unless another one beats it beyond the spread.
    windows : int
        Windows per record (>= 2).
    z : float
        How many standard errors the improvement must exceed (>= 0).
    """
    e = torch.as_tensor(errors, dtype=torch.float64)
    if e.ndim == 2:
        e = e[:, None]
    if e.ndim != 3 or e.shape[0] < 1:
        raise ValueError(f"errors must be (K, T) or (K, B, T), one row per candidate; got shape {tuple(e.shape)}")
    K, B, T = e.shape
    if not 0 <= int(reference) < K:
        raise ValueError(f"reference must index one of the {K} candidates, got {reference}")
    if int(windows) < 2 or T < int(windows):
        raise ValueError(f"need 2 <= windows <= T start times per record; got windows={windows}, T={T}")
    if not (math.isfinite(z) and z >= 0):
        raise ValueError(f"z must be finite and >= 0, got {z}")
    if bool(torch.isinf(e).any()) or bool(torch.isnan(e).all(-1).any()):
        raise ValueError("errors must be finite where given (NaN marks a missing target), with some per record")
    cuts = torch.linspace(0, T, int(windows) + 1).round().long().tolist()
    per = torch.stack([e[..., a:b].nanmean(-1) for a, b in zip(cuts[:-1], cuts[1:])], -1).reshape(K, -1)
    if bool(torch.isnan(per).any()):
        raise ValueError("a window holds no present target: use fewer windows")
    means = per.mean(-1)
    best = int(means.argmin())
    d = per[int(reference)] - per[best]
    imp = float(d.mean())
    se = float(d.std(unbiased=True) / math.sqrt(d.numel()))
    keep = best if best != int(reference) and imp > z * se else int(reference)
    return GainChoice(keep, best, imp, se, int(d.numel()), tuple(float(m) for m in means))
