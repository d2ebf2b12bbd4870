r"""The Sec. 4 evaluation of a frozen neural ODE with a neural feedback (Fig. 5b, Fig. S10), for any networks.

The ``neural_feedback`` notebook evaluates our trained networks; the why notebooks evaluate retrained
feedbacks and the authors' released networks the same way, through :func:`evaluation_setup`: the nominal
task (:func:`nominal_errors`, :func:`rate_error_curves`), the 12 residual levels of S8 and the held-out levels
(:func:`field_errors`), and the feedback's training loss in the release's form (:func:`release_form_loss`).
The book judges these numbers by the claims' rules (``fnnbook.feedback_eval``).

Systems are made by ``make`` (``fnnlib.systems.Spiral`` for Eq. (26); ``fnnlib.release.release_spiral`` for the
release's transposed spiral, in which the authors' networks were trained).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import torch
from torch import Tensor

from fnnlib.feedback import eval_field, rollout_predict
from fnnlib.metrics import n_step_errors, relative_rmse, rmse_over_time
from fnnlib.models import split_members, stack_members
from fnnlib.observers import NeuralFeedbackObserver
from fnnlib.paper.sweeps import colon_range, paired_levels, simulate_levels
from fnnlib.systems import Spiral

__all__ = ["CentredFeedback", "EvaluationSettings", "EvaluationSetup", "evaluation_setup", "field_errors", "nominal_errors",
           "rate_error_curves", "release_form_loss"]


class CentredFeedback(torch.nn.Module):
    """A learned feedback with its value at zero error removed: :math:`h(e) - h(0)`.

    The cascade of Sec. 3.3 starts each layer's estimate at its input (:math:`e = 0`), where a learned
    :math:`h(0)` need not vanish; centred, the first estimate is exact at the input. A usage the paper does not
    state, tried by the why of D4 against the learned :math:`h` as it is."""

    def __init__(self, h: torch.nn.Module):
        super().__init__()
        self.h = h

    def forward(self, e: Tensor) -> Tensor:
        return self.h(e) - self.h(torch.zeros_like(e[:1]))


@dataclass(frozen=True)
class EvaluationSetup:
    """The trajectories of the Sec. 4 evaluation (float32, noise-free, closed form).

    ``x_nom`` (T, 2) / ``f_nom`` (T, 2): the nominal task; ``x_s8``, ``f_s8`` (12, T, 2): the S8 levels;
    ``x_held``, ``f_held`` (H, T, 2): the held-out levels; ``offsets`` (12, 3): the S8 offsets.
    """

    x_nom: Tensor
    f_nom: Tensor
    x_s8: Tensor
    f_s8: Tensor
    x_held: Tensor
    f_held: Tensor
    offsets: Tensor
    Ts: float
    N: int


def _trajectories(make: Callable[..., Any], params: Tensor, x0: Tensor, t: Tensor) -> tuple[Tensor, Tensor]:
    """Closed-form trajectories (levels, T, 2) of ``make(*p)`` per row of ``params`` (rounded to float32, as the
    neural_feedback notebook does) and their true rates (at the unrounded parameters)."""
    rounded = params.float().tolist()
    x = simulate_levels([make(*p) for p in rounded], x0, t, exact=True).float()
    f = torch.stack([make(*p).rate(xi) for p, xi in zip(params.tolist(), x)])
    return x, f


@dataclass(frozen=True)
class EvaluationSettings:
    """The settings of the Sec. 4 evaluation (the ``neural_feedback`` notebook's names): the spiral's start
    ``x0`` and ``nominal`` parameters, ``n_samples`` samples of ``Ts``, the horizon ``N``; the S8 levels around
    ``residual_base`` on the grids ``domega_range``, ``deta_range``, ``deps_range`` (``[start, step, stop]``);
    the training cases' grids ``dr_omega_range``, ``dr_eta_range``, ``dr_eps_range``; the held-out levels: the S8
    offsets times ``heldout_flip``, kept at least ``heldout_min_distance`` training steps from every case."""

    x0: tuple[float, ...]
    nominal: tuple[float, ...]
    n_samples: int
    Ts: float
    N: int
    residual_base: tuple[float, ...]
    domega_range: tuple[float, ...]
    deta_range: tuple[float, ...]
    deps_range: tuple[float, ...]
    dr_omega_range: tuple[float, ...]
    dr_eta_range: tuple[float, ...]
    dr_eps_range: tuple[float, ...]
    heldout_flip: tuple[float, ...]
    heldout_min_distance: float

    @classmethod
    def of(cls, parameters: Mapping[str, Any]) -> EvaluationSettings:
        """These settings from a run's parameters (a record holding at least these names; the rest ignored)."""
        return cls(**{f.name: parameters[f.name] for f in fields(cls)})


def evaluation_setup(s: EvaluationSettings, make: Callable[..., Any] = Spiral) -> EvaluationSetup:
    """The evaluation of :class:`EvaluationSettings` ``s``, with systems made by ``make``."""
    t = torch.arange(s.n_samples, dtype=torch.float64) * s.Ts
    x0 = torch.tensor(s.x0, dtype=torch.float64)
    sys_nom = make(*s.nominal)
    x_nom = sys_nom.exact_solution(x0, t).float()
    offsets = paired_levels(*(colon_range(*g) for g in (s.domega_range, s.deta_range, s.deps_range)))
    base = torch.tensor(s.residual_base, dtype=torch.float64)
    x8, f8 = _trajectories(make, base + offsets, x0, t)
    grids = (s.dr_omega_range, s.dr_eta_range, s.dr_eps_range)
    cases = paired_levels(*(colon_range(*g) for g in grids))
    steps = torch.tensor([g[1] for g in grids], dtype=torch.float64)
    flipped = base + offsets * torch.tensor(s.heldout_flip, dtype=torch.float64)
    far = torch.cdist(flipped / steps, cases / steps).amin(-1) >= s.heldout_min_distance
    if not far.any():
        raise ValueError(f"no held-out level is {s.heldout_min_distance} training steps from the cases")
    xh, fh = _trajectories(make, flipped[far], x0, t)
    return EvaluationSetup(x_nom, sys_nom.rate(x_nom), x8, f8, xh, fh, offsets, float(s.Ts), int(s.N))


def _per_seed(z: Tensor, E: int) -> Tensor:
    return split_members(z, E)


def nominal_errors(f: torch.nn.Module, h: torch.nn.Module | None, setup: EvaluationSetup, E: int) -> np.ndarray:
    """Relative change-rate RMSE on the nominal task, per seed (E,): of ``f`` alone when ``h`` is None, else of
    the frozen ``f`` with the feedback ``h`` (the observer's :math:`\\hat f`)."""
    xs = stack_members(setup.x_nom, E)
    if h is None:
        with torch.no_grad():
            fhat = _per_seed(eval_field(f, xs), E)
    else:
        fhat = _per_seed(NeuralFeedbackObserver(f, setup.Ts, h=h, n=2 * E).observe(xs).f_hat, E)
    return np.array([relative_rmse(fhat[e], setup.f_nom) for e in range(E)])


def rate_error_curves(f: torch.nn.Module, h: torch.nn.Module, setup: EvaluationSetup, E: int) -> dict[str, np.ndarray]:
    """The per-time change-rate error on the nominal task, per seed (E, T): ``||f_hat(t) - f(t)||`` over the RMS
    norm of the true rate over the record (so the windowed RMS of a curve is the relative RMSE of
    :func:`nominal_errors` over that window), for ``f`` alone ("neural_ode") and with ``h`` ("neural_feedback")."""
    xs = stack_members(setup.x_nom, E)
    with torch.no_grad():
        alone = _per_seed(eval_field(f, xs), E)
    fb = _per_seed(NeuralFeedbackObserver(f, setup.Ts, h=h, n=2 * E).observe(xs).f_hat, E)
    scale = float(torch.linalg.vector_norm(setup.f_nom, dim=-1).pow(2).mean().sqrt())
    return {k: (torch.linalg.vector_norm(v - setup.f_nom, dim=-1) / scale).numpy()
            for k, v in (("neural_ode", alone), ("neural_feedback", fb))}


def release_form_loss(f: torch.nn.Module, h: torch.nn.Module, x_cases: Tensor, Ts: float, E: int, *,
                      skip_seconds: float = 0.5) -> np.ndarray:
    r"""The feedback's training loss in the release's form, per seed (E,): the mean absolute difference, over the
    randomized cases ``x_cases`` (C, T, 2), their samples and both components, between the finite-difference rate
    :math:`(x_{k+1} - x_k) / T_s` and the observer's :math:`\hat f_k = f(x_k) + h(x_k - \hat x_k)`. This is the
    loss the release logs and stops on (its ``Total_loss``, read in ``spiral_curve/d_FeedbackNN_converge.py``,
    not copied); the first ``skip_seconds``, which the release fades in, are left out."""
    xs = stack_members(x_cases, E)
    f_hat = _per_seed(NeuralFeedbackObserver(f, Ts, h=h, n=2 * E).observe(xs).f_hat, E)  # (E, C, T, 2)
    fd = (x_cases[:, 1:] - x_cases[:, :-1]) / Ts
    k0 = int(round(skip_seconds / Ts))
    return (f_hat[:, :, k0:-1] - fd[None, :, k0:]).abs().mean(dim=(1, 2, 3)).numpy()


def field_errors(f: torch.nn.Module, h: torch.nn.Module, x: Tensor, f_true: Tensor, setup: EvaluationSetup,
                 E: int, *, beta: float = 0.0) -> dict[str, np.ndarray]:
    """Per seed and level (E, levels): change-rate RMSE and mean ``N``-step error of the neural ODE ``f`` (Euler
    rollout) and of ``f`` with the neural feedback ``h`` (its cascade, decayed by ``beta`` along its layers), on
    the levels ``x`` (levels, T, 2)."""
    xs = stack_members(x, E)
    nf = NeuralFeedbackObserver(f, setup.Ts, h=h, n=2 * E, beta=beta)
    with torch.no_grad():
        f_nn = _per_seed(eval_field(f, xs), E)
    z = {"neural_ode": _per_seed(rollout_predict(f, xs, setup.Ts, setup.N), E),
         "neural_feedback": _per_seed(nf.predict(xs, setup.N), E)}
    rate = {"neural_ode": f_nn, "neural_feedback": _per_seed(nf.observe(xs).f_hat, E)}
    out = {f"rate_{k}": rmse_over_time(v, f_true.expand_as(v)).numpy() for k, v in rate.items()}
    return out | {f"err_N_{k}": n_step_errors(v, x, setup.N).mean(-1).numpy() for k, v in z.items()}
