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
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import torch
from torch import Tensor

from fnnlib.data.tanks import simulation_rmse

__all__ = ["DIVERGED", "LEVEL", "TanksSettings", "capped", "judged_again", "load_trained", "one_member", "outside_overflow",
           "save_trained", "depths", "episode_errors", "free_run", "kalman_n_step", "n_step_output_rmse",
           "no_feedback", "overflow_episodes", "overflow_table", "run_seeds"]


@dataclass(frozen=True)
class TanksSettings:
    """The settings of the cascaded tanks chapter's measures (its notebook's names).

    The model: an MLP field (``hidden``, ``activation``) in the log's units (``x_center``, ``x_scale``,
    ``u_center``, ``u_scale``, ``rate``); its training through the observer (output gain ``observer_gain``, horizon
    ``train_N``, ``train_iterations`` Adam steps at ``train_lr``); the gains of Eqs. (7), (11) tuned from
    ``L_start``, ``beta_start`` and picked by hand on ``hand_L_grid`` x ``hand_beta_grid``; the Kalman filters'
    noises (``kf_q``, ``kf_qd_grid``, ``kf_r``); the horizons ``horizons`` and ``series_N``; the free run from
    ``n_init`` samples; the overflow episodes (``overflow_after``, ``overflow_gap``); the no-feedback baseline's
    starts ``baseline_starts`` and horizon ``baseline_horizon``.
    """

    hidden: tuple[int, ...]
    activation: str
    rate: float
    x_center: float
    x_scale: float
    u_center: float
    u_scale: float
    observer_gain: tuple[float, ...]
    train_N: int
    train_iterations: int
    train_lr: float
    L_start: float
    beta_start: float
    horizons: tuple[int, ...]
    hand_L_grid: tuple[float, ...]
    hand_beta_grid: tuple[float, ...]
    kf_q: tuple[float, ...]
    kf_qd_grid: tuple[float, ...]
    kf_r: float
    n_init: int
    overflow_after: int
    overflow_gap: int
    series_N: int
    baseline_starts: tuple[str, ...]
    baseline_horizon: int

    @classmethod
    def of(cls, parameters: Mapping[str, Any]) -> TanksSettings:
        """These settings from a run's parameters (a record holding at least these names; the rest ignored)."""
        return cls(**{f.name: parameters[f.name] for f in fields(cls)})


def _signal(name: str, v: Any) -> np.ndarray:
    a = np.asarray(v.detach() if isinstance(v, Tensor) else v, dtype=float)
    if a.ndim == 2 and a.shape[1] == 1:
        a = a[:, 0]
    if a.ndim != 1:
        raise ValueError(f"{name} must be one signal, shape (T,) or (T, 1), got {a.shape}")
    return a


def n_step_output_rmse(x_pred: Tensor, y: Tensor, N: int, C: Tensor, *, skip: int = 0,
                       keep: np.ndarray | None = None) -> float:
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
    keep : array of bool, shape (T,), optional
        The target samples scored (a window of the record); by default all of them.
    """
    y = _signal("y", y)
    if x_pred.ndim != 2 or x_pred.shape[0] != y.size:
        raise ValueError(f"x_pred must be (T, n) with T = {y.size}, got {tuple(x_pred.shape)}")
    if isinstance(N, bool) or int(N) != N or not 1 <= N < y.size - skip:
        raise ValueError(f"N must be an integer in 1..{y.size - skip - 1}, got {N!r}")
    y_hat = (x_pred.detach().to(C.dtype) @ C.T)[:, 0].numpy()
    err = y_hat[skip:y.size - N] - y[skip + N:]
    if keep is not None:
        err = err[np.asarray(keep, dtype=bool).reshape(-1)[skip + N:]]
    if not np.isfinite(err).all():
        raise ValueError(f"the N={N} predictions hold non-finite values (a diverged prediction)")
    return float(np.sqrt(np.mean(err ** 2)))


def free_run(observer: Any, y: Tensor, u: Tensor, n_init: int, C: Tensor) -> np.ndarray:
    """The simulated output over a record: the observer (a :class:`fnnlib.MeasuredFeedback` with measurement
    ``C``) sees the first ``n_init`` samples of ``y`` (T, 1), none after them, so the model runs open loop from
    its estimate at sample ``n_init - 1``. Returns :math:`C \\hat x_k`, (T,), or (T, p) for several outputs
    (a stacked ensemble's members)."""
    T = y.shape[0]
    if not 1 <= n_init < T:
        raise ValueError(f"n_init must be in 1..{T - 1}, got {n_init}")
    hidden = y.clone()
    hidden[n_init:] = float("nan")  # a gap: Eq. (8) without the correction term
    with torch.no_grad():
        x_hat = observer.observe(hidden, u).x_hat
    out = x_hat.to(C.dtype) @ C.T
    return _signal("simulation", out) if out.shape[-1] == 1 else out.numpy()


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


def overflow_table(errors: Sequence[Mapping[str, Sequence[Mapping[str, float | None]]]],
                   episodes: Sequence[tuple[int, int]]) -> str:
    """The overflow episodes as a markdown table: per episode (its samples) and model, the mean over the seeds of
    the model's error during the episode and in the samples after it (:func:`episode_errors`); ``-`` where a seed
    has no such error. ``errors``: one ``{model: [per episode {"during", "after"}]}`` per seed."""
    names = list(errors[0]) if errors else []

    def mean(name: str, i: int, when: str) -> str:
        v = [e[name][i][when] for e in errors]
        return "-" if None in v else f"{np.mean(v):.3f}"
    rows = ["| episode (samples) | " + " | ".join(f"{n}: during / after" for n in names) + " |",
            "|" + "---|" * (1 + len(names))]
    return "\n".join(rows + [f"| {a}-{b - 1} | " + " | ".join(f"{mean(n, i, 'during')} / {mean(n, i, 'after')}"
                                                              for n in names) + " |" for i, (a, b) in enumerate(episodes)])


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


LEVEL = torch.tensor([[0.0, 1.0]], dtype=torch.float64)
"""The measurement of one member, :math:`y = C x` with :math:`C = [0, 1]` (the lower level)."""


def one_member(s: TanksSettings, seed: int) -> Any:
    """An untrained one-member field of ``seed`` with the chapter's settings ``s``."""
    return _field(s, [seed])


def _field(s: TanksSettings, members: Sequence[int]) -> Any:
    from fnnlib.models.scaled import ScaledField  # noqa: PLC0415

    return ScaledField(2, 1, s.hidden, s.activation, list(members), x_center=s.x_center, x_scale=s.x_scale,
                       u_center=s.u_center, u_scale=s.u_scale, rate=s.rate)


def _blocks(M: Tensor, E: int) -> Tensor:
    """``E`` copies of ``M`` on the diagonal of a block matrix: one member's gain or measurement, stacked."""
    return torch.block_diag(*([M] * E))


def _stacked(members: Sequence[Any], template: Any) -> Any:
    """One-member fields (:class:`fnnlib.models.scaled.ScaledField`) copied into the stacked ``template``."""
    with torch.no_grad():
        for e, one in enumerate(members):
            for dst, src in zip([*template.weights, *template.biases], [*one.weights, *one.biases]):
                dst[e:e + 1].copy_(src)
    return template


def depths(model: Any, observer: Any, y: Tensor, u: Tensor, Ts: float, L: Tensor, beta: Tensor, N: int) -> Tensor:
    r"""Every depth 1..N of the cascade after the observer, for ``G`` diagonal gains at once: (N, G, T, n).

    Entry ``N' - 1`` is the N'-step prediction (row k predicts sample k + N'): the observer's output
    :math:`z^{(1)}` (Eqs. (7)-(8) on ``y``), then layers ``i = 1 .. N'-1`` with :math:`L e^{-\beta i}` (Eq. (11)).
    Layer ``i`` does not depend on ``N'``, so one cascade of depth N gives every shorter horizon. ``L`` and
    ``beta`` are (G, n): a gain and a decay rate per state (a stacked ensemble's members each their own);
    ``L = 0`` is the open-loop rollout from the observer's estimate (:meth:`fnnlib.MeasuredFeedback.predict`).
    """
    from fnnlib.feedback.cascade import run_cascade  # noqa: PLC0415

    with torch.no_grad():
        z1 = observer.predict(y, 1, u)  # (T, n): the first layer, the observer alone
        G = L.shape[0]
        stack = [(L * torch.exp(-beta * i)).to(z1.dtype) for i in range(N)]  # Eq. (11), per state
        return run_cascade(model, z1.expand(G, *z1.shape), stack[1:], Ts, diagonal=True, u=u, first_depth=1,
                           return_all=True)


def run_seeds(rec: Any, seeds: Sequence[int], s: TanksSettings
              ) -> tuple[dict[int, dict[str, Any]], dict[str, float], dict[str, Any]]:
    """Everything the chapter measures, for every seed: the trainings on the estimation record, then, on the
    validation record, the free runs, the N-step table, the gains and the overflow episodes.

    The seeds' models through their observer are one stacked ensemble (:class:`fnnlib.models.scaled.ScaledField`,
    a block-diagonal observer; ``tune_gains(..., members=E)``): each member is trained and tuned as it would be
    alone, in one run. ``s`` holds the notebook's settings (its parameters cell): ``hidden``, ``activation``,
    ``rate``, ``x_center``, ``x_scale``, ``u_center``, ``u_scale``, ``observer_gain``, ``train_N``,
    ``train_iterations``, ``train_lr``, ``L_start``, ``beta_start``, ``horizons``, ``hand_L_grid``,
    ``hand_beta_grid``, ``kf_q``, ``kf_qd_grid``, ``kf_r``, ``n_init``, ``overflow_after``, ``overflow_gap``,
    ``series_N``, ``baseline_starts``, ``baseline_horizon``. Returns the per-seed results, the seconds
    of each stage (over all seeds) and the trained ensembles (what :func:`save_trained` stores).
    """
    import time  # noqa: PLC0415

    import fnnlib as F  # noqa: PLC0415

    f64 = torch.float64
    seeds = [int(v) for v in seeds]
    E = len(seeds)
    C = torch.tensor([[0.0, 1.0]], dtype=f64)
    CE = _blocks(C, E)  # (E, 2E): member e's level
    Ts, skip = rec.Ts, int(s.n_init)
    L_obs = _blocks(torch.tensor(s.observer_gain, dtype=f64)[:, None], E)  # (2E, E): Eq. (7)'s gain per member

    def field(members: Sequence[int]) -> Any:
        return _field(s, members)

    def observer(model: Any, y: Tensor) -> Any:  # the first estimate: both tanks at the first measured level
        return F.MeasuredFeedback(model, Ts, L=L_obs, measurement=F.Measurement(C=CE, x0=y[0, 0].repeat(2 * E)),
                                  allow_unstable=True)

    def tile(y: Tensor) -> Tensor:
        return y.expand(-1, E).contiguous()

    clock = {}
    t0 = time.perf_counter()
    model = field(seeds)  # trained through its observer: Eqs. (7)-(8) first, the N-step output error descended
    ye = tile(rec.y_est)
    tuned = F.tune_gains(model, ye, Ts, int(s.train_N),
                         recipe=F.TuneRecipe(L0=s.L_start, beta0=s.beta_start, iterations=int(s.train_iterations), lr=s.train_lr, train_model=True, members=E),
                         u=rec.u_est, observer=observer(model, ye))
    clock["train_observer"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    free = _free_starts(rec, seeds, s, field(seeds), C) if "free" in s.baseline_starts else None
    base = [no_feedback(rec, seed, s, field([seed]), C, free=None if free is None else free.member(e))
            for e, seed in enumerate(seeds)]
    plain = _stacked([b["model"] for b in base], field(seeds))
    clock["train_no_feedback"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    out = _validate(F, rec, model, plain, observer, tuned, CE, Ts, skip, s, E)
    clock["validate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    for e, seed in enumerate(seeds):
        kf = _kalman_member(F, model.member(e), rec, Ts, C, skip, s)
        for N, row in kf.pop("n_step").items():
            out[e]["n_step"][N] |= row
        out[e]["gains"]["kf_qd"] = kf["qd"]
    clock["kalman"] = time.perf_counter() - t0
    for e, (seed, b) in enumerate(zip(seeds, base)):
        out[e]["free_run"]["no_feedback"] = b["free_run"]
        out[e]["no_feedback"] = {k: v for k, v in b.items() if k not in ("model", "free_run", "series")}
        for N in out[e]["n_step"]:
            out[e]["n_step"][N]["no_feedback_free_run"] = capped(simulation_rmse, b["series"][N:], rec.y_val[N:],
                                                                 skip=skip)
        out[e]["loss"] = {"observer_total": [tuned.loss[0], tuned.loss[-1]]}
    trained = {"seeds": seeds, "observer_trained": model, "no_feedback": plain, "tuned_L": tuned.L.tolist(),
               "tuned_beta": [float(v) for v in torch.as_tensor(tuned.beta).reshape(-1).expand(E)],
               "hand": [out[e]["gains"]["hand"] for e in range(E)]}
    return {seed: out[e] for e, seed in enumerate(seeds)}, clock, trained


def save_trained(path: Any, trained: Mapping[str, Any]) -> None:
    """The chapter's trained ensembles, gains and seeds, for the pages that judge them again (never retrain)."""
    torch.save({k: (v.state_dict() if isinstance(v, torch.nn.Module) else v) for k, v in trained.items()}, path)


def load_trained(path: Any, s: TanksSettings) -> dict[str, Any]:
    """:func:`save_trained`'s file, the ensembles rebuilt with the chapter's settings ``s``."""
    data = torch.load(path, weights_only=True)
    for k in ("observer_trained", "no_feedback"):
        m = _field(s, data["seeds"])
        m.load_state_dict(data[k])
        data[k] = m
    return data


def outside_overflow(rec: Any, s: TanksSettings) -> np.ndarray:
    """The validation samples (T,) neither in an overflow episode nor in the ``overflow_after`` samples after one."""
    keep = np.ones(rec.y_val.shape[0], dtype=bool)
    for a, b in overflow_episodes(rec.saturated("val").numpy(), gap=int(s.overflow_gap)):
        keep[a:b + int(s.overflow_after)] = False
    return keep


def judged_again(rec: Any, trained: Mapping[str, Any], s: TanksSettings, *, first: str, keep: np.ndarray | None,
                 grid: Sequence[tuple[float, float]] = ()) -> dict[str, dict[int, list[float]]]:
    """The N-step errors per seed of the trained ensemble on the validation record, for the open loop, the tuned
    and the hand gains and each fixed ``(L, beta)`` of ``grid`` (named ``"L=.., beta=.."``), with the observer's
    first estimate ``first`` (``"first_level"``: both tanks at the first measured level, the chapter's;
    ``"least_squares"``: :math:`C^+ y_0`, the upper tank empty) and the target samples ``keep``.
    Returns ``{predictor: {N: [one RMSE per seed]}}``."""
    import fnnlib as F  # noqa: PLC0415

    model, seeds = trained["observer_trained"], trained["seeds"]
    E, f64, skip = len(seeds), torch.float64, int(s.n_init)
    C = torch.tensor([[0.0, 1.0]], dtype=f64)
    yv = rec.y_val.expand(-1, E)
    x0 = {"first_level": yv[0, 0].repeat(2 * E), "least_squares": None}[first]
    obs = F.MeasuredFeedback(model, rec.Ts, L=_blocks(torch.tensor(s.observer_gain, dtype=f64)[:, None], E),
                             measurement=F.Measurement(C=_blocks(C, E), x0=x0), allow_unstable=True)
    two = lambda v: torch.as_tensor(v, dtype=f64).reshape(-1).repeat_interleave(2)  # noqa: E731  per member -> per state
    rows = {"open_loop": (torch.zeros(2 * E, dtype=f64), torch.zeros(2 * E, dtype=f64)),
            "tuned": (torch.as_tensor(trained["tuned_L"], dtype=f64), two(trained["tuned_beta"])),
            "hand": (two([h["L"] for h in trained["hand"]]), two([h["beta"] for h in trained["hand"]]))}
    rows |= {f"L={L:g}, beta={b:g}": (torch.full((2 * E,), float(L), dtype=f64), torch.full((2 * E,), float(b), dtype=f64))
             for L, b in grid}
    Ns = [int(N) for N in s.horizons]
    d = depths(model, obs, yv, rec.u_val, rec.Ts, torch.stack([v[0] for v in rows.values()]),
               torch.stack([v[1] for v in rows.values()]), max(Ns))
    return {name: {N: [capped(n_step_output_rmse, d[N - 1, g, :, 2 * e:2 * e + 2], rec.y_val, N, C, skip=skip, keep=keep)
                       for e in range(E)] for N in Ns} for g, name in enumerate(rows)}


def _free_starts(rec: Any, seeds: Sequence[int], s: TanksSettings, stacked: Any, C: Tensor) -> Any:
    """The free-start baseline of every seed in one run: the stacked field on the record tiled once per member,
    with a block-diagonal measurement (each member's start states and weights are its own; Adam is elementwise,
    so each member descends as alone, its loss scaled by 1 / E)."""
    from fnnlib.training.outputs import OutputRecipe, train_from_outputs  # noqa: PLC0415

    E = len(seeds)
    train_from_outputs(stacked, rec.y_est.expand(-1, E).contiguous(), _blocks(C, E), OutputRecipe(
        start="free", iterations=int(s.train_iterations), lr=s.train_lr, burn=1,
        horizon=int(s.baseline_horizon), seed=int(seeds[0])), Ts=rec.Ts, u=rec.u_est, progress=False)
    return stacked


def no_feedback(rec: Any, seed: int, s: TanksSettings, make: Any, C: Tensor, *, free: Any = None) -> dict[str, Any]:
    """The same architecture and seed trained without feedback: for each start of ``baseline_starts`` (a free
    initial state per segment, or an encoder of the first ``n_init`` samples) over segments of
    ``baseline_horizon`` samples, with the same Adam steps and rate as the model trained through its observer;
    the one whose free run of the *estimation* record is best is kept (nothing chosen on the validation
    record). Its free run of the validation record starts as it was trained to start: from the encoder, or
    (free starts) from the observer on the first ``n_init`` samples, as the observer-trained model's does.
    ``make`` is an untrained one-member field of this seed (copied per start); ``free``, where given, is this
    seed's free-start model already trained (:func:`run_seeds` trains them as one ensemble)."""
    import copy  # noqa: PLC0415

    import fnnlib as F  # noqa: PLC0415
    from fnnlib.training.outputs import OutputRecipe, train_from_outputs  # noqa: PLC0415

    skip, H = int(s.n_init), int(s.baseline_horizon)
    tried = {}
    for start in s.baseline_starts:
        if start == "free" and free is not None:
            m, encoder = free, None
        else:
            m = copy.deepcopy(make)
            encoder = train_from_outputs(m, rec.y_est, C, OutputRecipe(
                start=start, iterations=int(s.train_iterations), lr=s.train_lr,
                burn=1 if start == "free" else skip, horizon=H, seed=int(seed)), Ts=rec.Ts, u=rec.u_est,
                progress=False).encoder
        est = _simulate(F, m, encoder, rec.y_est, rec.u_est, rec.Ts, skip, C, s)
        tried[start] = (m, encoder, capped(simulation_rmse, est, rec.y_est, skip=skip))
    best = min(tried, key=lambda k: tried[k][2])
    m, encoder, _ = tried[best]
    val = _simulate(F, m, encoder, rec.y_val, rec.u_val, rec.Ts, skip, C, s)
    return {"model": m, "start": best, "estimation_free_run": {k: v[2] for k, v in tried.items()},
            "free_run": capped(simulation_rmse, val, rec.y_val, skip=skip), "series": val}


def _simulate(F: Any, m: Any, encoder: Any, y: Tensor, u: Tensor, Ts: float, skip: int, C: Tensor,
              s: TanksSettings) -> np.ndarray:
    """The free run (T,) of a one-member model from the first ``skip`` samples: its encoder's start, or the
    observer's (the first ``skip`` entries are the measured ones where the encoder starts)."""
    from fnnlib.training.outputs import free_run as from_start  # noqa: PLC0415

    if encoder is not None:
        sim = from_start(m, y, C, burn=skip, Ts=Ts, u=u, encoder=encoder)[:, 0].numpy()
        return np.r_[y[:skip, 0].numpy(), sim]
    obs = F.MeasuredFeedback(m, Ts, L=torch.tensor(s.observer_gain, dtype=C.dtype)[:, None],
                             measurement=F.Measurement(C=C, x0=y[0, 0].repeat(2)), allow_unstable=True)
    return free_run(obs, y, u, skip, C)


def _validate(F: Any, rec: Any, model: Any, plain: Any, observer: Any, tuned: Any, CE: Tensor, Ts: float, skip: int,
              s: TanksSettings, E: int) -> list[dict[str, Any]]:
    """:func:`run_seeds`' measurements with the trained ensembles (no gradients), one dict per member."""
    f64 = CE.dtype
    yv, uv, ye, ue = rec.y_val.expand(-1, E), rec.u_val, rec.y_est.expand(-1, E), rec.u_est
    Ns, N_h, N_s = [int(N) for N in s.horizons], int(s.train_N), int(s.series_N)
    obs_v, obs_e, plain_v = observer(model, yv), observer(model, ye), observer(plain, yv)
    free_obs = free_run(obs_v, yv, uv, skip, CE)  # (T, E)
    grid = [(float(L), float(b)) for L in s.hand_L_grid for b in s.hand_beta_grid]
    per_state = lambda v: torch.as_tensor(v, dtype=f64).reshape(-1, 1).expand(-1, 2 * E)  # noqa: E731
    L_grid, b_grid = per_state([g[0] for g in grid]), per_state([g[1] for g in grid])
    # hand gains: per member, the best (L, beta) of the sweep by the train_N-step error on the estimation record
    z = depths(model, obs_e, ye, ue, Ts, L_grid, b_grid, N_h)[N_h - 1]  # (G, T, 2E)
    sweep = np.array([[capped(n_step_output_rmse, z[g][:, 2 * e:2 * e + 2], ye[:, e], N_h, CE[:1, :2], skip=skip)
                       for g in range(len(grid))] for e in range(E)])  # (E, G)
    hand = sweep.argmin(1)
    beta_t = torch.as_tensor(tuned.beta, dtype=f64).reshape(-1).expand(E).repeat_interleave(2)
    zero = torch.zeros(1, 2 * E, dtype=f64)
    L_all = torch.cat([zero, tuned.L.reshape(1, -1), L_grid])  # open loop, tuned, the hand grid
    b_all = torch.cat([zero, beta_t[None], b_grid])
    Nmax = max(Ns)
    d = depths(model, obs_v, yv, uv, Ts, L_all, b_all, Nmax)  # (Nmax, 2 + G, T, 2E)
    d_plain = depths(plain, plain_v, yv, uv, Ts, zero, zero, Nmax)[:, 0]  # (Nmax, T, 2E)
    C1 = CE[:1, :2]
    out = []
    for e in range(E):
        sl, y_e = slice(2 * e, 2 * e + 2), rec.y_val
        p = {N: {"open_loop": d[N - 1, 0, :, sl], "tuned": d[N - 1, 1, :, sl], "hand": d[N - 1, 2 + hand[e], :, sl],
                 "no_feedback_observer": d_plain[N - 1, :, sl]} for N in Ns}
        table = {N: {k: capped(n_step_output_rmse, v, y_e, N, C1, skip=skip) for k, v in p[N].items()} for N in Ns}
        free = {"observer_trained": free_obs[:, e]}
        L_h, b_h = grid[int(hand[e])]
        out.append({
            "free_run": {"observer_trained": capped(simulation_rmse, free_obs[:, e], y_e, skip=skip)},
            "n_step": table, "overflow": _overflow(rec, free, p, C1, s),
            "gains": {"tuned": {"L": tuned.L[2 * e:2 * e + 2].tolist(), "beta": float(beta_t[2 * e])},
                      "hand": {"L": L_h, "beta": b_h},
                      "sweep": {f"L={L:g}, beta={b:g}": float(v) for (L, b), v in zip(grid, sweep[e])}},
            "series": {"free_run": free_obs[:, e].tolist(),
                       **{k: _aligned(v, N_s, C1).tolist() for k, v in p.get(N_s, {}).items()
                          if k in ("open_loop", "tuned")}}})
    return out


def _kalman_member(F: Any, model: Any, rec: Any, Ts: float, C: Tensor, skip: int, s: TanksSettings) -> dict:
    """One member's EKF and UKF: the disturbance's process noise the best of ``kf_qd_grid`` by the EKF's mean N-step
    error over the horizons on the estimation record, then both filters' N-step errors on the validation record."""
    A = F.model_jacobian(model, torch.full((2,), float(s.x_center), dtype=C.dtype),
                         torch.full((1,), float(s.u_center), dtype=C.dtype))  # the filters' linearisation point
    Ns = [int(N) for N in s.horizons]

    def make(cls: Any, qd: float) -> Any:
        return cls(model, Ts, n=2, cov=F.Covariances([*s.kf_q, qd], s.kf_r), C=C, disturbance=[1], A=A)

    score = {}
    for qd in s.kf_qd_grid:
        score[qd] = float(np.mean(list(kalman_n_step(make(F.ExtendedKalmanObserver, qd), rec.y_est, rec.u_est, Ts, Ns,
                                                     C, skip=skip, x0=rec.y_est[0, 0].repeat(2)).values())))
    qd = min(score, key=score.get)
    table: dict[int, dict[str, float]] = {N: {} for N in Ns}
    for name, cls in (("ekf", F.ExtendedKalmanObserver), ("ukf", F.UnscentedKalmanObserver)):
        for N, v in kalman_n_step(make(cls, qd), rec.y_val, rec.u_val, Ts, Ns, C, skip=skip,
                                  x0=rec.y_val[0, 0].repeat(2)).items():
            table[N][name] = v
    return {"qd": qd, "score": score, "n_step": table}


def _overflow(rec: Any, free: Mapping[str, Any], preds: Mapping[int, Mapping[str, Tensor]], C: Tensor,
              s: TanksSettings) -> dict[str, Any]:
    """The error during and after each overflow episode of the validation record: the free run and, at
    ``series_N``, the open-loop and tuned-feedback predictions (each moved to its target sample)."""
    eps = overflow_episodes(rec.saturated("val").numpy(), gap=int(s.overflow_gap))
    N = int(s.series_N)
    series = {"free_run": free["observer_trained"]}
    series |= {k: _aligned(v, N, C) for k, v in preds.get(N, {}).items() if k in ("open_loop", "tuned")}
    return {"episodes": eps, "after": int(s.overflow_after),
            "errors": {k: episode_errors(v, rec.y_val, eps, after=int(s.overflow_after)) for k, v in series.items()}}
