"""The interface every observer shares, and the metrics the S11 comparison computes for each.

An observer turns measurements into an :class:`~fnnlib.feedback.types.Estimate`
(state and change rate) and predicts N steps ahead from every sample, so a
comparison is a loop over objects: :class:`~fnnlib.observers.LinearFeedback`
(Eqs. (7)-(8), cascade of Sec. 3.3), :class:`~fnnlib.observers.LuenbergerObserver`,
:class:`~fnnlib.observers.KalmanObserver`, :class:`~fnnlib.observers.ExtendedKalmanObserver`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import NamedTuple, Protocol, runtime_checkable

import torch
from torch import Tensor

from fnnlib.metrics import error_norm, rmse
from fnnlib.feedback.options import Measurement, record_sampling
from fnnlib.feedback.sampling import check_times
from fnnlib.feedback.types import Estimate


@runtime_checkable
class Observer(Protocol):
    r"""What the comparison needs from an observer.

    Each one gives an estimate :math:`\hat x` of the state, as Eq. (8) does: the linear feedback of Eqs. (7)-(8),
    the neural feedback of Eq. (12), the Luenberger and Kalman baselines.

    Attributes
    ----------
    n : int
        State dimension.
    Ts : float
        Sampling step.
    """

    n: int
    Ts: float

    def observe(self, x: Tensor) -> Estimate:
        """State and change-rate estimates along measurements ``x`` (..., T, n), each (..., T, n).

        fnnlib's observers also take ``t=`` (..., T), the sample times, instead of the nominal step ``Ts``."""

    def predict(self, x: Tensor, N: int) -> Tensor:
        """Predictions (..., T, n) from every sample of ``x``; row k predicts the state at ``t_{k+N}``."""


class ObserverReport(NamedTuple):
    """One observer's outputs on one trajectory and its metrics (plain floats)."""

    estimate: Estimate
    z_N: Tensor
    metrics: dict[str, float]


def _best_seconds(fn, repeats: int):
    """Run ``fn`` ``repeats`` times; return its last result and the fastest wall time."""
    best, out = float("inf"), None
    for _ in range(max(1, int(repeats))):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return out, best


def evaluate_observer(observer: Observer, y: Tensor, truth: tuple[Tensor, Tensor], N: int, *,
                      settle: int = 0, repeats: int = 3, u: Tensor | None = None,
                      measurement: Measurement | None = None) -> ObserverReport:
    """Run ``observer`` on measurements ``y`` and score it against the truth.

    Parameters
    ----------
    observer : Observer
    y : Tensor, shape (T, p)
        Measurements (noisy states, or p outputs ``y = C x`` of an observer built with that ``C``;
        NaN where a sample is missing, for the observers that take gaps).
    truth : (x_true, f_true), each a Tensor of shape (T, n)
        Clean states and true change rates at the same samples.
    u : Tensor, shape (T, m), optional
        Inputs of a controlled model, passed to ``observe`` and ``predict``.
    measurement : Measurement, optional
        The record's missing samples (``mask`` (T,) or (T, p)) and its sample times ``t`` (T,) (uneven
        sampling), passed to ``observe`` and ``predict`` (``mask=``, ``t=``; the times instead of the observer's
        ``Ts``), checked here before any work (:func:`~fnnlib.feedback.sampling.check_times`). The measurement
        model (``C``) is the observer's own.
    N : int
        Prediction horizon.
    settle : int
        Samples of start-up transient (every observer starts knowing no
        disturbance) left out of the ``*_settled`` metrics.
    repeats : int
        Timings are the fastest of this many runs.

    Returns
    -------
    ObserverReport
        ``metrics`` holds ``state_rmse`` (:math:`\\hat x` vs ``x_true``),
        ``rate_rmse`` (:math:`\\hat f` vs ``f_true``), the same two over
        samples ``k >= settle`` (``state_rmse_settled``, ``rate_rmse_settled``), ``err_N_mean`` (mean
        2-norm error of the N-step predictions from every start with a truth
        N steps later, the metric of Fig. 4f), ``us_per_step`` (observing, per
        sample) and ``us_per_start`` (predicting N steps from every sample,
        filtering included, per start).
    """
    t, mask = record_sampling(measurement)
    if not isinstance(truth, (tuple, list)) or len(truth) != 2:
        raise TypeError("truth must be the pair (x_true, f_true), each of shape (T, n)")
    x_true, f_true = truth
    if not isinstance(observer, Observer):
        raise TypeError(f"{type(observer).__name__} does not implement the Observer interface "
                        "(n, Ts, observe, predict)")
    if not isinstance(y, Tensor) or y.ndim != 2 or not (x_true.shape == f_true.shape == (y.shape[0], observer.n)):
        raise ValueError(f"need y (T, p) and x_true, f_true (T, n) with n = {observer.n}; got "
                         f"{tuple(getattr(y, 'shape', ()))}, {tuple(x_true.shape)}, {tuple(f_true.shape)}")
    for name, v in (("x_true", x_true), ("f_true", f_true)):
        if not bool(torch.isfinite(v).all()):
            raise ValueError(f"{name} holds a NaN or infinite value: the truth must be complete")
    T = y.shape[0]
    if not 1 <= int(N) < T:
        raise ValueError(f"need 1 <= N < T = {T}, got N = {N}")
    settle = int(settle)
    if not 0 <= settle < T:
        raise ValueError(f"need 0 <= settle < T = {T}, got settle = {settle}")
    if t is not None:
        check_times(t, None, y)
    args = () if u is None else (u,)
    kw = ({} if mask is None else {"mask": mask}) | ({} if t is None else {"t": t})
    est, t_obs = _best_seconds(lambda: observer.observe(y, *args, **kw), repeats)
    z_N, t_pred = _best_seconds(lambda: observer.predict(y, int(N), *args, **kw), repeats)
    metrics = {
        "state_rmse": rmse(est.x_hat, x_true),
        "rate_rmse": rmse(est.f_hat, f_true),
        "state_rmse_settled": rmse(est.x_hat[settle:], x_true[settle:]),
        "rate_rmse_settled": rmse(est.f_hat[settle:], f_true[settle:]),
        "err_N_mean": float(error_norm(z_N[: T - N], x_true[N:]).mean()),
        "us_per_step": 1e6 * t_obs / T,
        "us_per_start": 1e6 * t_pred / T,
    }
    return ObserverReport(est, z_N, metrics)


def metrics_table(rows: Mapping[str, Mapping[str, float]], *, digits: int = 4) -> str:
    """A markdown table: one row per observer, one column per metric (the first row's keys)."""
    if not rows:
        raise ValueError("no rows to tabulate")
    cols = list(next(iter(rows.values())))
    lines = ["| observer | " + " | ".join(cols) + " |", "|---|" + "---:|" * len(cols)]
    for name, m in rows.items():
        lines.append(f"| {name} | " + " | ".join(f"{float(m[c]):.{digits}g}" for c in cols) + " |")
    return "\n".join(lines)
