"""Rules of the Sec. 5.1 claims O1-O2 (the thrown bottle, Fig. 6, S2, S3).

Errors are 0.5 s position errors, one row per test throw (one column per seed).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from fnnbook.rules._compare import Value, beats, per_seed
from fnnbook.results import ClaimResult



def _throws(value: Any, name: str) -> np.ndarray:
    """A (throws, seeds) array."""
    arr = np.asarray(value, dtype=float)
    arr = arr[:, None] if arr.ndim == 1 else arr
    if arr.ndim != 2 or arr.shape[0] < 2 or not np.isfinite(arr).all():
        raise ValueError(f"O1: {name} needs finite errors of shape (throws >= 2,) or (throws, seeds)")
    return arr


def o1(*, feedback: Any, neural_ode: Any, drag: Any) -> ClaimResult:
    """O1 (Fig. 6): feedback < neural ODE < drag model in 0.5 s position error.

    ``feedback``, ``neural_ode``: (throws, seeds); ``drag`` (throws,) or (throws, 1): the fitted drag model
    has no seed.  Each "a < b" is judged twice with the one paired rule
    (:func:`fnnlib.stats.paired_win`): per throw (errors averaged over seeds, one pair per throw, so a win
    needs all throws but one), and over seeds (errors averaged over throws; skipped with one seed).
    """
    fb, nn, dr = _throws(feedback, "feedback"), _throws(neural_ode, "neural_ode"), _throws(drag, "drag")
    if fb.shape != nn.shape or dr.shape[0] != fb.shape[0]:
        raise ValueError(f"O1: shapes {fb.shape}, {nn.shape}, {dr.shape} do not pair throw by throw")
    return o1_means(per_throw={"feedback": fb.mean(1), "neural_ode": nn.mean(1), "drag": dr.mean(1)},
                    per_seed={"feedback": fb.mean(0), "neural_ode": nn.mean(0)})


def o1_per_seed(*, feedback: Any, neural_ode: Any, drag: Any) -> ClaimResult:
    """O1 (Fig. 6) on errors laid out one row per seed: ``feedback``, ``neural_ode`` (seeds, throws) (tensors or
    arrays: their means are taken in their own type), ``drag`` (throws,): :func:`o1_means` of their marginals."""
    return o1_means(per_throw={"feedback": feedback.mean(0), "neural_ode": neural_ode.mean(0), "drag": drag},
                    per_seed={"feedback": feedback.mean(1), "neural_ode": neural_ode.mean(1)})


def o1_means(*, per_throw: Mapping[str, Any], per_seed: Mapping[str, Any]) -> ClaimResult:
    """O1 (Fig. 6) from the marginals its checks read: :func:`o1` on the (throws, seeds) errors is this on
    their means, so a stored result (``per_throw_m``, ``per_seed_m`` of the bottle task) can be judged again.

    ``per_throw``: ``feedback``, ``neural_ode``, ``drag`` -> one error per test throw (averaged over seeds);
    ``per_seed``: ``feedback``, ``neural_ode`` -> one error per seed (averaged over throws; the drag model
    has no seed: its mean over throws pairs with every seed).
    """
    for name in ("feedback", "neural_ode", "drag"):
        if name not in per_throw:
            raise ValueError(f"O1: per_throw needs {name!r} errors, got {sorted(per_throw)}")
    fb, nn, dr = (_throws(per_throw[k], k)[:, 0] for k in ("feedback", "neural_ode", "drag"))
    if not fb.shape == nn.shape == dr.shape:
        raise ValueError(f"O1: per-throw shapes {fb.shape}, {nn.shape}, {dr.shape} do not pair throw by throw")
    fb_s, nn_s = (np.asarray(per_seed.get(k, ()), dtype=float).reshape(-1) for k in ("feedback", "neural_ode"))
    if fb_s.size < 1 or fb_s.shape != nn_s.shape or not np.isfinite(np.r_[fb_s, nn_s]).all():
        raise ValueError(f"O1: per_seed needs finite 'feedback' and 'neural_ode' errors, one per seed, as many "
                         f"of each; got {fb_s.shape} and {nn_s.shape}")
    checks = {"feedback<neural_ode per throw": beats(fb, nn), "neural_ode<drag per throw": beats(nn, dr)}
    S = fb_s.size
    if S > 1:
        checks |= {"feedback<neural_ode over seeds": beats(fb_s, nn_s),
                   "neural_ode<drag over seeds": beats(nn_s, np.full(S, dr.mean()))}
    n = fb.shape[0]
    return ClaimResult(
        "O1",
        checks=checks,
        guarantees={},
        rule=f"a < b when lower on >= {n - 1} of the {n} throws and the 90 % interval of the mean paired "
             "difference excludes 0" + (f"; and the same over {S} seeds on the mean over throws" if S > 1
                                        else "; one seed (single trained network)"))


def o2(*, acc_rmse_feedback: Value, acc_rmse_neural_ode: Value, error_feedback: Value, travel: float,
       overlap_fraction: float = 0.1, error_per_throw: Any = None) -> ClaimResult:
    """O2 (Figs. S2, S3): the feedback's learned accelerations are closer to the measured ones than the neural
    ODE's, and its predicted positions almost overlap the truth on *every* test throw ("all 9 test
    trajectories", Fig. S2): the 0.5 s error of each throw (mean over seeds, ``error_per_throw``) below
    ``overlap_fraction`` of the mean distance flown in 0.5 s. A mean over the throws hides the throw a reader
    of Fig. S2 would see apart; one throw alone fails the check. ``error_feedback`` (per seed) is shown.
    """
    if error_per_throw is None:
        raise ValueError("O2: error_per_throw (the feedback's 0.5 s error per test throw) is needed")
    per_throw = np.asarray(error_per_throw, dtype=float)
    per_throw = per_throw.mean(-1) if per_throw.ndim == 2 else per_throw
    if per_throw.ndim != 1 or per_throw.size == 0 or not np.isfinite(per_throw).all():
        raise ValueError(f"O2: one finite error per throw (or per throw and seed), got shape {per_throw.shape}")
    return ClaimResult(
        "O2",
        checks={"feedback_acc_closer": beats(acc_rmse_feedback, acc_rmse_neural_ode),
                f"positions_overlap_on_every_one_of_{per_throw.size}_throws":
                    bool((per_throw < overlap_fraction * travel).all())},
        guarantees={},
        numbers={"worst_throw_error_over_travel": float(per_throw.max() / travel),
                 "mean_error_over_travel": float(per_seed(error_feedback).mean() / travel)},
        reading="'the predicted trajectories almost overlap with the truth ones' (Fig. S2, all 9 test throws) read "
                f"as every throw's 0.5 s error below {overlap_fraction:.0%} of the distance flown in 0.5 s",
        rule="feedback acceleration RMSE beats the neural ODE's; on every test throw the feedback's 0.5 s error "
             f"(mean over seeds) < {overlap_fraction:.0%} of the mean distance flown in 0.5 s")
