r"""What the cascaded tanks chapter measures on a learned model, beside the benchmark's own metric.

* :func:`n_step_output_rmse`: the N-step prediction RMSE of the measured output, from the rows of a predictor
  (:func:`fnnlib.cascade_predict`, an observer's or a Kalman filter's ``predict``: row ``k`` predicts the
  state at sample ``k + N``), scored from sample ``skip`` on.
* :func:`free_run`: the benchmark's simulation: the observer corrects the model on the first ``n_init``
  measured samples only, then the model runs open loop to the end of the record (the later samples are
  hidden from it, so Eq. (8) runs without its correction term).
* :func:`overflow_episodes`, :func:`episode_errors`: the stretches where the measured level sits at the
  sensor's 10 V limit, and a prediction's error during each and in the samples after it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

__all__ = ["episode_errors", "free_run", "n_step_output_rmse", "overflow_episodes"]


def _signal(name: str, v: Any) -> np.ndarray:
    a = np.asarray(v.detach() if isinstance(v, Tensor) else v, dtype=float)
    if a.ndim == 2 and a.shape[1] == 1:
        a = a[:, 0]
    if a.ndim != 1:
        raise ValueError(f"{name} must be one signal, shape (T,) or (T, 1), got {a.shape}")
    return a


def n_step_output_rmse(x_pred: Tensor, y: Tensor, N: int, C: Tensor, *, skip: int = 0) -> float:
    """RMSE of :math:`C \\hat x_{k+N|k}` against :math:`y_{k+N}` over the start times ``k`` from ``skip`` to
    ``T - N - 1``.

    Parameters
    ----------
    x_pred : Tensor, shape (T, n)
        Row ``k`` predicts the state at sample ``k + N``.
    y : Tensor, shape (T,) or (T, 1)
        The measured output.
    N : int
        The horizon, 1 <= N < T - skip.
    C : Tensor, shape (1, n)
        The measurement.
    skip : int
        Start times left out (those an estimate needs to settle, or the simulation's initial samples).
    """
    y = _signal("y", y)
    if x_pred.ndim != 2 or x_pred.shape[0] != y.size:
        raise ValueError(f"x_pred must be (T, n) with T = {y.size}, got {tuple(x_pred.shape)}")
    if isinstance(N, bool) or int(N) != N or not 1 <= N < y.size - skip:
        raise ValueError(f"N must be an integer in 1..{y.size - skip - 1}, got {N!r}")
    y_hat = (x_pred.detach().to(C.dtype) @ C.T)[:, 0].numpy()
    err = y_hat[skip:y.size - N] - y[skip + N:]
    if not np.isfinite(err).all():
        raise ValueError(f"the N={N} predictions hold non-finite values (a diverged prediction)")
    return float(np.sqrt(np.mean(err ** 2)))


def free_run(observer: Any, y: Tensor, u: Tensor, n_init: int, C: Tensor) -> np.ndarray:
    """The simulated output over a record: the observer (a :class:`fnnlib.MeasuredFeedback` with measurement
    ``C``) sees the first ``n_init`` samples of ``y`` (T, 1), none after them, so the model runs open loop from
    its estimate at sample ``n_init - 1``. Returns :math:`C \\hat x_k`, (T,)."""
    T = y.shape[0]
    if not 1 <= n_init < T:
        raise ValueError(f"n_init must be in 1..{T - 1}, got {n_init}")
    hidden = y.clone()
    hidden[n_init:] = float("nan")  # a gap: Eq. (8) without the correction term
    with torch.no_grad():
        x_hat = observer.observe(hidden, u).x_hat
    return _signal("simulation", x_hat.to(C.dtype) @ C.T)


def overflow_episodes(saturated: Any) -> list[tuple[int, int]]:
    """The runs of ``True`` in ``saturated`` (T,), as ``[start, end)`` sample ranges, in time order."""
    s = np.asarray(saturated, dtype=bool).reshape(-1)
    edges = np.diff(np.r_[0, s.astype(int), 0])
    return [(int(a), int(b)) for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))]


def episode_errors(y_hat: Any, y: Any, episodes: Sequence[tuple[int, int]], *, after: int) -> list[dict]:
    """Per overflow episode: its samples, the RMSE of ``y_hat`` against ``y`` during it, and over the
    ``after`` samples that follow it (fewer at the end of the record; None when none follow).

    ``y_hat`` is aligned with ``y`` (entry k predicts sample k); NaN entries (no prediction) are left out.
    """
    a, b = _signal("y_hat", y_hat), _signal("y", y)
    if a.shape != b.shape:
        raise ValueError(f"y_hat and y must have the same length, got {a.shape} and {b.shape}")
    if int(after) != after or after < 1:
        raise ValueError(f"after must be an integer >= 1, got {after!r}")

    def rmse(lo: int, hi: int) -> float | None:
        e = (a[lo:hi] - b[lo:hi])[np.isfinite(a[lo:hi])]
        return float(np.sqrt(np.mean(e ** 2))) if e.size else None

    return [{"start": s, "samples": e - s, "during": rmse(s, e), "after": rmse(e, min(e + after, b.size))}
            for s, e in episodes]
