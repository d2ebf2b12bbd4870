r"""The Sec. 4 claims judged on the evaluation of :mod:`fnnlib.paper.feedback_eval`, for any networks.

D2 and D4 (and D1 with a domain-randomized neural ODE, D3 with the feedback's training loss) by the claims' own
rules (:mod:`fnnbook.rules.sec4`): :func:`judge`; D4 alone on the evaluation's numbers (:func:`d4_result`); the
relative RMSEs after the feedback's estimate has settled (:func:`settled_errors`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from fnnbook.results import ClaimResult
from fnnbook.rules import sec4
from fnnlib.paper.feedback_eval import EvaluationSetup, field_errors, nominal_errors, rate_error_curves

__all__ = ["d4_result", "judge", "settled_errors"]


def settled_errors(curves: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The relative RMSEs after the feedback's estimate has settled (:func:`fnnbook.rules.sec4.settling_index` on
    its curve, per seed), over the same window for the neural ODE alone; and the settling index (E,)."""
    start = sec4.settling_index(curves["neural_feedback"])
    out = {f"rel_rmse_settled_{k}": np.array([float(np.sqrt(np.mean(c[e, s:] ** 2))) for e, s in enumerate(start)])
           for k, c in curves.items()}
    return out | {"settle_index": start}


def d4_result(s8: Mapping[str, np.ndarray], held: Mapping[str, np.ndarray], setup: EvaluationSetup,
              metric: str = "both") -> ClaimResult:
    """D4's rule (:func:`fnnbook.rules.sec4.d4`, read in ``metric``) on :func:`field_errors`' numbers for the S8
    levels (``s8``) and the held-out levels (``held``)."""
    return sec4.d4(**{f"{k}_{m}": s8[f"{k}_{m}"].T for k in ("rate", "err_N") for m in ("neural_feedback", "neural_ode")},
                   **{f"heldout_{k}_{m}": held[f"{k}_{m}"].T for k in ("rate", "err_N")
                      for m in ("neural_feedback", "neural_ode")},
                   N=setup.N, offsets=setup.offsets.tolist(), metric=metric)


def judge(f: torch.nn.Module, h: torch.nn.Module, setup: EvaluationSetup, E: int, *,
          loss: Sequence[float] | np.ndarray | None, factor: float, ratio_max: float, flat: float,
          f_dr: torch.nn.Module | None = None, d1_factor: float = 1.5) -> tuple[dict[str, ClaimResult], dict]:
    """D2 and D4 (and D1 with the domain-randomized ``f_dr``, D3 with the feedback's training ``loss``
    (iterations,) or (iterations, E)) by the claims' own rules, for E seeds side by side; and the numbers."""
    rel_nominal, rel_fb = nominal_errors(f, None, setup, E), nominal_errors(f, h, setup, E)
    s8 = field_errors(f, h, setup.x_s8, setup.f_s8, setup, E)
    held = field_errors(f, h, setup.x_held, setup.f_held, setup, E)
    settled = settled_errors(rate_error_curves(f, h, setup, E))
    numbers: dict[str, Any] = {"rel_rmse_nominal_neural_ode": rel_nominal, "rel_rmse_neural_feedback": rel_fb,
                               "s8": s8, "held_out": held,
                               "rel_rmse_settled_nominal_neural_ode": settled["rel_rmse_settled_neural_ode"],
                               "rel_rmse_settled_neural_feedback": settled["rel_rmse_settled_neural_feedback"],
                               "settle_seconds": settled["settle_index"] * setup.Ts}
    out = {"D2": sec4.d2(rel_feedback=rel_fb, rel_nominal=rel_nominal, frozen_unchanged=True, factor=factor),
           "D4": d4_result(s8, held, setup)}
    if f_dr is not None:
        numbers["rel_rmse_dr_neural_ode"] = rel_dr = nominal_errors(f_dr, None, setup, E)
        out["D1"] = sec4.d1(rel_dr=rel_dr, rel_nominal=rel_nominal, factor=d1_factor)
    if loss is not None:
        ratio, trend = sec4.loss_convergence(loss)
        numbers |= {"ratio": ratio, "last_window_trend_relative": trend}
        out["D3"] = sec4.d3(ratio=ratio, trend=trend, ratio_max=ratio_max, flat=flat)
    return dict(sorted(out.items())), numbers
