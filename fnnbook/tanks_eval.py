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

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

__all__ = ["DIVERGED", "capped", "episode_errors", "free_run", "kalman_n_step", "n_step_output_rmse", "overflow_episodes",
           "run_seed"]


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


def overflow_episodes(saturated: Any, *, gap: int = 0) -> list[tuple[int, int]]:
    """The runs of ``True`` in ``saturated`` (T,), as ``[start, end)`` sample ranges, in time order; runs
    separated by at most ``gap`` samples are one episode (noise flickering at the limit)."""
    s = np.asarray(saturated, dtype=bool).reshape(-1)
    edges = np.diff(np.r_[0, s.astype(int), 0])
    runs = [(int(a), int(b)) for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))]
    merged: list[tuple[int, int]] = []
    for a, b in runs:
        if merged and a - merged[-1][1] <= gap:
            merged[-1] = (merged[-1][0], b)
        else:
            merged.append((a, b))
    return merged


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


DIVERGED = 1e3
"""The error (volts) a prediction or simulation that diverged (non-finite, or beyond it) is counted as."""


def capped(fn: Any, *args: Any, **kw: Any) -> float:
    """``fn(*args, **kw)``, an RMSE, or :data:`DIVERGED` when the prediction behind it diverged."""
    try:
        v = float(fn(*args, **kw))
    except (ValueError, FloatingPointError):
        return DIVERGED
    return v if np.isfinite(v) and v < DIVERGED else DIVERGED


def kalman_n_step(kf: Any, y: Tensor, u: Tensor, Ts: float, horizons: Sequence[int], C: Tensor, *, skip: int,
                  x0: Tensor | None = None) -> dict[int, float]:
    """The N-step output RMSE of a Kalman filter with a disturbance state (:class:`fnnlib.ExtendedKalmanObserver`,
    :class:`fnnlib.UnscentedKalmanObserver`) for every N: the filter runs once, then the corrected model is
    rolled out from its filtered state and disturbance, as its ``predict`` does, N steps from every sample."""
    from fnnlib.observers.augmented import rollout_corrected  # noqa: PLC0415

    with torch.no_grad():
        est = kf.estimate(y, u, x0=x0)
        return {N: capped(n_step_output_rmse, rollout_corrected(kf.f, est.x_hat, est.d_hat, Ts, N, u), y, N, C,
                          skip=skip) for N in horizons}


def _aligned(x_pred: Tensor, N: int, C: Tensor) -> np.ndarray:
    """Row k of an N-step prediction moved to its target sample k + N (NaN before the first target)."""
    y_hat = (x_pred.detach().to(C.dtype) @ C.T)[:, 0].numpy()
    out = np.full(y_hat.shape, np.nan)
    out[N:] = y_hat[:-N]
    return out


def run_seed(rec: Any, seed: int, s: Mapping[str, Any]) -> dict[str, Any]:
    """Everything the chapter measures for one seed: the two trainings on the estimation record, then, on the
    validation record, the free runs, the N-step table, the gains and the overflow episodes.

    ``s`` holds the notebook's settings (its parameters cell): ``hidden``, ``activation``, ``rate``,
    ``x_center``, ``x_scale``, ``u_center``, ``u_scale``, ``observer_gain``, ``train_N``, ``train_iterations``,
    ``train_lr``, ``L_start``, ``beta_start``, ``horizons``, ``hand_L_grid``, ``hand_beta_grid``, ``kf_q``,
    ``kf_qd_grid``, ``kf_r``, ``n_init``, ``overflow_after``, ``overflow_gap``, ``series_N``.
    """
    import time  # noqa: PLC0415

    import fnnlib as F  # noqa: PLC0415
    from fnnlib.models.scaled import ScaledField  # noqa: PLC0415
    from fnnlib.training.outputs import OutputRecipe, train_from_outputs  # noqa: PLC0415

    f64 = torch.float64
    C = torch.tensor([[0.0, 1.0]], dtype=f64)
    Ts, skip, Ns = rec.Ts, int(s["n_init"]), [int(N) for N in s["horizons"]]
    L_obs = torch.tensor(s["observer_gain"], dtype=f64)[:, None]  # (2, 1): Eq. (7)'s gain on the level

    def field() -> ScaledField:
        return ScaledField(2, 1, s["hidden"], s["activation"], [seed], x_center=s["x_center"], x_scale=s["x_scale"],
                           u_center=s["u_center"], u_scale=s["u_scale"], rate=s["rate"])

    def observer(model: Any, y: Tensor) -> Any:  # the first estimate: both tanks at the first measured level
        return F.MeasuredFeedback(model, L_obs, C, Ts, x0=y[0, 0].repeat(2), allow_unstable=True)

    clock, out = {}, {}
    t0 = time.perf_counter()
    model = field()  # trained through its observer: Eqs. (7)-(8) first, the N-step output error descended
    tuned = F.tune_gains(model, rec.y_est, Ts, int(s["train_N"]), u=rec.u_est, observer=observer(model, rec.y_est),
                         L0=s["L_start"], beta0=s["beta_start"], iterations=int(s["train_iterations"]),
                         lr=s["train_lr"], train_model=True)
    clock["train_observer"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    plain = field()  # the same architecture and seed, trained with a free initial state per segment
    fit = train_from_outputs(plain, rec.y_est, C, OutputRecipe(
        start="free", iterations=int(s["train_iterations"]), lr=s["train_lr"], burn=1, horizon=int(s["train_N"])),
        Ts=Ts, u=rec.u_est, seed=seed, progress=False)
    clock["train_no_feedback"] = time.perf_counter() - t0
    out["loss"] = {"observer": [tuned.loss[0], tuned.loss[-1]], "no_feedback": [fit.loss[0], fit.loss[-1]]}
    t0 = time.perf_counter()
    with torch.no_grad():
        out |= _validate(F, rec, model, plain, observer, tuned, C, Ts, skip, Ns, s)
    clock["validate"] = time.perf_counter() - t0
    out["seconds"] = clock
    return out


def _validate(F: Any, rec: Any, model: Any, plain: Any, observer: Any, tuned: Any, C: Tensor, Ts: float, skip: int,
              Ns: list[int], s: Mapping[str, Any]) -> dict[str, Any]:
    """:func:`run_seed`'s measurements with the trained models (no gradients)."""
    yv, uv, ye, ue = rec.y_val, rec.u_val, rec.y_est, rec.u_est
    obs_v, obs_e, plain_v = observer(model, yv), observer(model, ye), observer(plain, yv)
    free = {"observer_trained": free_run(obs_v, yv, uv, skip, C), "no_feedback": free_run(plain_v, yv, uv, skip, C)}
    free_rmse = {k: capped(F.simulation_rmse, v, yv, skip=skip) for k, v in free.items()}
    # hand gains: the best (L, beta) of the sweep by the train_N-step error on the estimation record
    N_h = int(s["train_N"])
    sweep = {(L, b): capped(n_step_output_rmse, F.cascade_predict(model, ye, Ts, N_h, L, b, u=ue, observer=obs_e),
                            ye, N_h, C, skip=skip) for L in s["hand_L_grid"] for b in s["hand_beta_grid"]}
    L_hand, b_hand = min(sweep, key=sweep.get)
    A = F.model_jacobian(model, torch.full((2,), float(s["x_center"]), dtype=C.dtype),
                         torch.full((1,), float(s["u_center"]), dtype=C.dtype))  # the filters' linearisation point
    kf = _kalman(F, model, A, ye, ue, Ts, C, skip, s)
    preds = {}
    table = {}
    for N in Ns:
        p = {"open_loop": obs_v.predict(yv, N, uv),
             "hand": F.cascade_predict(model, yv, Ts, N, L_hand, b_hand, u=uv, observer=obs_v),
             "tuned": F.cascade_predict(model, yv, Ts, N, tuned.L_tensor, tuned.beta, u=uv, observer=obs_v),
             "no_feedback_observer": plain_v.predict(yv, N, uv)}
        table[N] = {k: capped(n_step_output_rmse, v, yv, N, C, skip=skip) for k, v in p.items()}
        table[N]["no_feedback_free_run"] = capped(F.simulation_rmse, free["no_feedback"][N:], yv[N:], skip=skip)
        preds[N] = p
    for name, cls in (("ekf", F.ExtendedKalmanObserver), ("ukf", F.UnscentedKalmanObserver)):
        f = cls(model, Ts, 2, [*s["kf_q"], kf["qd"]], s["kf_r"], C=C, disturbance=[1], A=A)
        for N, v in kalman_n_step(f, yv, uv, Ts, Ns, C, skip=skip, x0=yv[0, 0].repeat(2)).items():
            table[N][name] = v
    return {"free_run": free_rmse, "n_step": table, "overflow": _overflow(rec, free, preds, C, s),
            "gains": {"tuned": {"L": tuned.L, "beta": tuned.beta}, "hand": {"L": L_hand, "beta": b_hand},
                      "sweep": {f"L={L:g}, beta={b:g}": v for (L, b), v in sweep.items()}, "kf_qd": kf["qd"]},
            "series": {"free_run": free["observer_trained"].tolist(),
                       **{k: _aligned(v, int(s["series_N"]), C).tolist()
                          for k, v in preds.get(int(s["series_N"]), {}).items() if k in ("open_loop", "tuned")}}}


def _kalman(F: Any, model: Any, A: Tensor, y: Tensor, u: Tensor, Ts: float, C: Tensor, skip: int, s: Mapping[str, Any]) -> dict:
    """The disturbance's process noise of the Kalman filters: the best of ``kf_qd_grid`` by the EKF's mean N-step
    error over the horizons on the estimation record."""
    score = {}
    for qd in s["kf_qd_grid"]:
        ekf = F.ExtendedKalmanObserver(model, Ts, 2, [*s["kf_q"], qd], s["kf_r"], C=C, disturbance=[1], A=A)
        score[qd] = float(np.mean(list(kalman_n_step(ekf, y, u, Ts, s["horizons"], C, skip=skip,
                                                     x0=y[0, 0].repeat(2)).values())))
    return {"qd": min(score, key=score.get), "score": score}


def _overflow(rec: Any, free: Mapping[str, np.ndarray], preds: Mapping[int, Mapping[str, Tensor]], C: Tensor,
              s: Mapping[str, Any]) -> dict[str, Any]:
    """The error during and after each overflow episode of the validation record: the free run and, at
    ``series_N``, the open-loop and tuned-feedback predictions (each moved to its target sample)."""
    eps = overflow_episodes(rec.saturated("val").numpy(), gap=int(s["overflow_gap"]))
    N = int(s["series_N"])
    series = {"free_run": free["observer_trained"]}
    series |= {k: _aligned(v, N, C) for k, v in preds.get(N, {}).items() if k in ("open_loop", "tuned")}
    return {"episodes": eps, "after": int(s["overflow_after"]),
            "errors": {k: episode_errors(v, rec.y_val, eps, after=int(s["overflow_after"])) for k, v in series.items()}}
