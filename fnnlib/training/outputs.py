r"""A neural ODE learned from measured outputs only: each segment starts at the feedback estimate (Sec. 3's idea).

A plant whose states are not all measured cannot be fitted state to state. The paper's own device solves it:
the feedback observer of Eqs. (7)-(8), run on the learned model itself over a segment's first ``burn``
samples (:class:`~fnnlib.feedback.measured.MeasuredFeedback`, here with ``y = Cx`` or ``h(x)``), gives the
state the segment starts from; the model is then rolled out open loop over the next ``horizon`` samples and
the output error :math:`\|C\hat x_k - y_k\|^2` over the present samples is descended, through the observer
(its batched solve is differentiable, :mod:`fnnlib.feedback.gaps`) and the rollout. The output gain is fixed
or trained (``train_gain``).

The baselines a reviewer asks for ("feedback, or just a better initial state?") share everything but the start:

* ``start="free"``: the state at each segment's start is a free parameter, fitted with the model (the segments
  are then fixed: the record cut into consecutive windows);
* ``start="encoder"``: an MLP maps the segment's first ``burn`` outputs and inputs (a missing output as 0 with
  a presence flag) to the start state, the encoder networks of system identification.

All three predict the same samples from the same information (the ``burn`` samples before them), so their
errors compare the start alone. Rollouts are Euler steps at the record's own intervals, the discretisation
the cascade uses; uneven times are taken as ``t``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import torch
from torch import Tensor, nn
from tqdm import tqdm

from fnnlib._validation import check_positive
from fnnlib.feedback.gaps import first_layer, measure_fn, start_state
from fnnlib.feedback.layer import eval_field
from fnnlib.feedback.measured import MeasuredFeedback
from fnnlib.feedback.measurement import Measurements, check_measurements
from fnnlib.feedback.options import Measurement, record_sampling
from fnnlib.feedback.sampling import Steps, check_times, row_steps
from fnnlib.models.neural_ode import init_parameters, mlp
from fnnlib.training.neural_ode import OPTIMIZERS, Recipe

STARTS = ("feedback", "free", "encoder")


@dataclass(frozen=True)
class OutputRecipe(Recipe):
    """The settings of :func:`train_from_outputs`, checked when made.

    Its output gain is the ``L`` of Eq. (7) on ``y = C x`` or ``h(x)``, the feedback that starts each segment
    (Eqs. (7)-(8)).

    Attributes
    ----------
    start : str
        ``"feedback"`` (the observer's estimate), ``"free"`` or ``"encoder"`` (module docstring).
    iterations, lr, optimizer
        Descent steps, learning rate (cosine-annealed to 1 % of it), ``"adam"`` or ``"rmsprop"``.
    burn, horizon : int
        Samples the start is estimated from, and samples predicted after them.
    batch : int
        Segments per iteration (``"free"``: every segment each iteration).
    L : tuple (n x p), optional
        The observer's output gain (``"feedback"``), e.g. from :func:`~fnnlib.place_observer_gain` on a rough
        model; required with ``start="feedback"``.
    train_gain : bool
        Also descend on the output gain.
    encoder_hidden : tuple of int
        Hidden layers of the encoder (``"encoder"``).
    seed : int
        Seeds the draws of the training (segments, the encoder's and the free starts' initial values).
    """

    start: str = "feedback"
    iterations: int = 300
    lr: float = 0.01
    optimizer: str = "adam"
    burn: int = 20
    horizon: int = 40
    batch: int = 32
    L: tuple | None = None
    train_gain: bool = False
    encoder_hidden: tuple = (64,)
    seed: int = 0

    def __post_init__(self):
        if self.start not in STARTS:
            raise ValueError(f"OutputRecipe.start must be one of {STARTS}, got {self.start!r}")
        for name, low in (("iterations", 1), ("burn", 1), ("horizon", 1), ("batch", 1), ("seed", 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < low:
                raise ValueError(f"OutputRecipe.{name} must be an integer >= {low}, got {v!r}")
        self._check_descent({}, "")
        if self.start == "feedback" and self.L is None:
            raise ValueError("OutputRecipe(start='feedback') needs the observer's output gain L (n x p)")
        if self.L is not None:
            L = torch.as_tensor(self.L, dtype=torch.float64)
            if L.ndim != 2 or not bool(torch.isfinite(L).all()):
                raise ValueError(f"OutputRecipe.L must be a finite (n, p) matrix, got {self.L!r}")
            object.__setattr__(self, "L", tuple(tuple(r) for r in L.tolist()))
        object.__setattr__(self, "encoder_hidden", tuple(int(h) for h in self.encoder_hidden))


@dataclass
class OutputFit:
    """What :func:`train_from_outputs` returns: the trained model, the observer (``"feedback"``), the encoder
    (``"encoder"``), the loss per iteration and the wall time."""

    model: nn.Module
    observer: MeasuredFeedback | None
    encoder: nn.Module | None
    recipe: OutputRecipe
    loss: list[float] = field(default_factory=list)
    seconds: float = 0.0


def _segments(T: int, B: int, W: int, starts: Tensor | None, batch: int, gen: torch.Generator) -> tuple[Tensor, Tensor]:
    """(record, time) indices of ``batch`` random windows of ``W`` samples, each (batch, W)."""
    n_starts = T - W + 1
    if n_starts < 1:
        raise ValueError(f"the records have T = {T} samples but a segment needs burn + horizon = {W}")
    pick = torch.randint(B * n_starts, (batch,), generator=gen) if starts is None else starts
    rec, s = pick // n_starts, pick % n_starts
    return rec[:, None].expand(-1, W), s[:, None] + torch.arange(W)[None, :]


def _take(v: Tensor | None, rec: Tensor, idx: Tensor) -> Tensor | None:
    return None if v is None else v[rec, idx]


def _rollout(model: nn.Module, x: Tensor, u: Tensor | None, steps: Steps, first: int, count: int) -> Tensor:
    """Euler rollout of ``count`` states from ``x`` (S, n) at sample ``first`` of segments (S, W, .): (S, count, n)."""
    out = [x]
    for k in range(first, first + count - 1):
        uk = None if u is None else u[:, k:k + 1]
        h = steps[:, k:k + 1] if isinstance(steps, Tensor) else steps
        x = x + (h[:, 0] if isinstance(h, Tensor) else h) * eval_field(model, x[:, None], uk)[:, 0]
        out.append(x)
    return torch.stack(out, 1)


def _output_loss(model, meas_seg: Measurements, x_pred: Tensor, first: int) -> Tensor:
    """Mean squared output error over the present samples ``first ..`` of the segments."""
    measure = measure_fn(meas_seg, x_pred.dtype)
    y_pred = measure(x_pred) if measure is not None else x_pred
    y = meas_seg.y[:, first:first + x_pred.shape[1]]
    present = (torch.ones_like(y) if meas_seg.mask is None else meas_seg.mask[:, first:first + x_pred.shape[1]].to(y.dtype))
    return ((y_pred - y).pow(2) * present).sum() / present.sum().clamp_min(1.0)


def train_from_outputs(model: nn.Module, y: Tensor, C, recipe: OutputRecipe, *, Ts: float | None = None,
                       u: Tensor | None = None, measurement: Measurement | None = None,
                       progress: bool = True) -> OutputFit:
    r"""Train ``model`` (``f(t, x)`` or ``f(t, x, u)``) from outputs ``y`` (B, T, p) or (T, p) alone (module docstring).

    Each segment starts at the estimate of the feedback of Eqs. (7)-(8) on the measured outputs;
    :math:`f_{neural}` of Eq. (3) is fitted through it.

    ``C`` (p, n) or ``h(x)``; ``Ts``, or the times ``t`` ((T,) or (B, T)) of ``measurement``; ``u`` (B, T, m)
    or (T, m); a NaN in ``y`` or ``False`` in the ``measurement``'s ``mask`` is a missing sample (the
    measurement carries the record's ``t`` and ``mask`` only: its ``C`` is the argument here). Checked before
    any work; every record needs a present output. Returns an :class:`OutputFit`; ``recipe.seed`` seeds it.
    """
    if not isinstance(recipe, OutputRecipe):
        raise TypeError(f"recipe must be an OutputRecipe, got {type(recipe).__name__}")
    if not isinstance(model, nn.Module):
        raise TypeError("model must be an nn.Module (its parameters are trained)")
    t, mask = record_sampling(measurement)
    n = _state_dim(model, C, recipe)
    y = y[None] if isinstance(y, Tensor) and y.ndim == 2 else y
    u = u[None].expand(y.shape[0], *u.shape) if isinstance(u, Tensor) and u.ndim == 2 else u
    meas = check_measurements(y, n, C=C, u=u, mask=mask, f=model)
    dt = check_times(t, Ts, meas.y)
    B, T = meas.y.shape[:2]
    r = recipe
    W = r.burn + r.horizon
    if T < W:
        raise ValueError(f"the records have T = {T} samples but a segment needs burn + horizon = {W}")
    dtype = meas.y.dtype
    steps = row_steps(dt, 0, T)
    steps = steps.expand(B, T, 1) if isinstance(steps, Tensor) else steps
    gen = torch.Generator().manual_seed(int(r.seed))
    params = [p for p in model.parameters() if p.requires_grad]
    observer, encoder, x_free, L_y, fixed = None, None, None, None, None
    if r.start == "feedback":
        L_y = nn.Parameter(torch.tensor(r.L, dtype=dtype), requires_grad=r.train_gain)
        if r.train_gain:
            params.append(L_y)
    elif r.start == "encoder":
        encoder = mlp(r.burn * (2 * meas.p + (0 if meas.u is None else meas.u.shape[-1])), n, r.encoder_hidden, "tanh")
        encoder = encoder.to(dtype)
        init_parameters(encoder, gen)
        params += list(encoder.parameters())
    else:  # free: consecutive windows, each with its own start state
        n_starts = T - W + 1
        offsets = torch.arange(0, n_starts, r.horizon)
        fixed = (torch.arange(B)[:, None] * n_starts + offsets[None, :]).reshape(-1)
        rec, idx = _segments(T, B, W, fixed, len(fixed), gen)
        seg = _seg_meas(meas, rec, idx)
        x_free = nn.Parameter(_least_squares_start(seg, n, r.burn).detach().clone())
        params.append(x_free)
    opt = OPTIMIZERS[r.optimizer](params, lr=float(r.lr))
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, int(r.iterations), eta_min=0.01 * float(r.lr))
    fit = OutputFit(model, None, encoder, r)
    start = time.perf_counter()
    bar = tqdm(range(int(r.iterations)), desc=f"train from outputs ({r.start})", disable=not progress, leave=False)
    for _ in bar:
        if r.start == "free":
            rec, idx = _segments(T, B, W, fixed, len(fixed), gen)
        else:
            rec, idx = _segments(T, B, W, None, int(r.batch), gen)
        seg = _seg_meas(meas, rec, idx)
        h = steps[rec, idx] if isinstance(steps, Tensor) else steps
        opt.zero_grad()
        x_start = _start(model, seg, h, n, r, L_y, encoder, x_free)
        x_pred = _rollout(model, x_start, seg.u, h, r.burn, r.horizon)
        loss = _output_loss(model, seg, x_pred, r.burn)
        loss.backward()
        opt.step()
        sched.step()
        fit.loss.append(loss.item())
        bar.set_postfix(loss=f"{fit.loss[-1]:.4g}", refresh=False)
    fit.seconds = time.perf_counter() - start
    if r.start == "feedback":
        fit.observer = MeasuredFeedback(model, Ts, L=L_y.detach().double(), measurement=Measurement(C=C),
                                        allow_unstable=True)
    return fit


def _state_dim(model: nn.Module, C, recipe: OutputRecipe) -> int:
    """The state dimension: the model's ``n``, its ``n_state`` (times ``n_members`` for a stacked ensemble,
    :class:`~fnnlib.models.scaled.ScaledField`), else ``C``'s columns, else ``L``'s rows."""
    if isinstance(getattr(model, "n", None), int):
        return int(model.n)
    if isinstance(getattr(model, "n_state", None), int):
        return int(model.n_state) * int(getattr(model, "n_members", 1))
    if isinstance(C, Tensor) and C.ndim == 2:
        return int(C.shape[1])
    if recipe.L is not None:
        return len(recipe.L)
    raise ValueError("cannot tell the state dimension: give a model with .n, a matrix C or the recipe's L")


def _seg_meas(meas: Measurements, rec: Tensor, idx: Tensor) -> Measurements:
    return meas._replace(y=meas.y[rec, idx], mask=_take(meas.mask, rec, idx), u=_take(meas.u, rec, idx))


def _least_squares_start(seg: Measurements, n: int, at: int) -> Tensor:
    """The least-squares state of sample ``at``'s outputs (0 where unseen), the free starts' initial value."""
    one = seg._replace(y=seg.y[:, at:at + 1], mask=_take(seg.mask, slice(None), slice(at, at + 1))
                       if seg.mask is not None else None)
    if seg.C is None and seg.h is None:
        return one.y[:, 0]
    if seg.h is not None:
        return torch.zeros(seg.y.shape[0], n, dtype=seg.y.dtype)
    return start_state(one, n, None)


def _start(model, seg: Measurements, h: Steps, n: int, r: OutputRecipe, L_y, encoder, x_free) -> Tensor:
    """The state at sample ``burn`` of each segment, by the recipe's start."""
    if r.start == "free":
        return x_free
    if r.start == "encoder":
        y = seg.y[:, : r.burn]
        present = (torch.ones_like(y) if seg.mask is None else seg.mask[:, : r.burn].to(y.dtype))
        parts = [y * present, present] + ([] if seg.u is None else [seg.u[:, : r.burn]])
        return encoder(torch.cat(parts, -1).reshape(y.shape[0], -1))
    burn = seg._replace(y=seg.y[:, : r.burn], mask=None if seg.mask is None else seg.mask[:, : r.burn],
                        u=None if seg.u is None else seg.u[:, : r.burn])
    dt = h[:, : r.burn - 1, 0] if isinstance(h, Tensor) else h
    if isinstance(dt, Tensor) and dt.shape[-1] == 0:
        dt = h[:, :1, 0]
    x0 = start_state(burn, n, None) if (seg.h is None) else torch.zeros(seg.y.shape[0], n, dtype=seg.y.dtype)
    _, _, out, _ = first_layer(model, burn, L_y, dt if isinstance(dt, Tensor) else dt, x0, diagonal=False)
    return out[:, -1]  # the estimate of the state at sample burn, from the outputs before it


@torch.no_grad()
def free_run(model: nn.Module, y: Tensor, C, *, burn: int, Ts: float | None = None, t: Tensor | None = None,
             u: Tensor | None = None, observer: MeasuredFeedback | None = None, encoder: nn.Module | None = None,
             x0: Tensor | None = None) -> Tensor:
    r"""The simulated (free-run) output of a record (B, T, p) or (T, p): the start state at sample ``burn`` from the
    first ``burn`` samples (the ``observer``, the ``encoder``, or ``x0`` given), then the model alone to the end.

    The benchmark protocol of system identification ("simulation" error); returns the outputs from sample
    ``burn`` on, (B, T - burn, p).
    """
    one = isinstance(y, Tensor) and y.ndim == 2
    y = y[None] if one else y
    u = u[None].expand(y.shape[0], *u.shape) if isinstance(u, Tensor) and u.ndim == 2 else u
    n = observer.n if observer is not None else _state_dim(model, C, OutputRecipe(start="free"))
    meas = check_measurements(y, n, C=C, u=u, f=model)
    dt = check_times(t, Ts, meas.y)
    B, T = meas.y.shape[:2]
    steps = row_steps(dt, 0, T)
    steps = steps.expand(B, T, 1) if isinstance(steps, Tensor) else steps
    r = OutputRecipe(start="free", burn=int(burn), horizon=max(1, T - int(burn)))
    if x0 is not None:
        start = torch.as_tensor(x0, dtype=meas.y.dtype).expand(B, n)
    elif observer is not None:
        start = _start(model, meas, steps, n, r.replace(start="feedback", L=tuple(map(tuple, observer.L.tolist()))),
                       observer.L.to(meas.y.dtype), None, None)
    elif encoder is not None:
        start = _start(model, meas, steps, n, r.replace(start="encoder"), None, encoder, None)
    else:
        raise ValueError("give the observer, the encoder or x0 the free run starts from")
    x = _rollout(model, start, meas.u, steps, int(burn), T - int(burn))
    measure = measure_fn(meas, meas.y.dtype)
    out = measure(x) if measure is not None else x
    return out[0] if one else out
