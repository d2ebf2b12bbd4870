r"""Sample times: one step ``Ts``, or the record's own times ``t`` (..., T), checked before any work.

Every estimator, the cascade, :func:`~fnnlib.rollout_predict`, the tuner and the trainer take either ``Ts``
(uniform sampling, the paper's setting) or ``t`` (uneven sampling: jitter, irregular logs), never both.
With ``t``, Eqs. (7)-(8) step by each interval :math:`\Delta_k = t_{k+1} - t_k`,

.. math:: \hat x_{k+1} = \hat x_k + \Delta_k \hat f_k,

and a missing sample is simply a missing time. Row ``k`` of layer ``i`` of the cascade steps from
:math:`t_{k+i}` to :math:`t_{k+i+1}` (:func:`row_steps`), so depth ``N`` predicts the state at the record's
own :math:`t_{k+N}`; past the record's end the last interval is repeated.

Eq. (11)'s decay :math:`L_i = L e^{-\beta i}` is read **per layer** also with uneven times: ``i`` counts the
samples ahead (the depth of the cascade), whose errors Sec. 3.3 compounds layer by layer; it does not
depend on how long each interval is.
"""

from __future__ import annotations

import torch
from torch import Tensor

from fnnlib._validation import check_positive

#: One step (float) or the per-step intervals (..., T-1).
Steps = float | Tensor


def check_times(t: Tensor | None, Ts: float | None, y: Tensor, *, name: str = "y") -> Steps:
    r"""``Ts`` (checked > 0) or the intervals :math:`\Delta_k` (..., T-1) of the times ``t`` (..., T) of ``y`` (..., T, p).

    ``t`` must be a finite, strictly increasing floating-point tensor with one time per sample of ``y``
    (leading axes broadcasting against ``y``'s: one grid for every record, or one per record). Exactly one of
    ``t`` and ``Ts`` is given. Raises ``TypeError`` / ``ValueError`` naming what is wrong.
    """
    if t is None:
        if Ts is None:
            raise TypeError("give the sample step Ts or the sample times t (..., T)")
        return check_positive(Ts, name="Ts")
    if Ts is not None:
        raise TypeError("give either the sample step Ts or the sample times t, not both (t defines every step)")
    if not isinstance(t, Tensor) or not t.is_floating_point():
        raise TypeError(f"the sample times t must be a floating-point tensor of shape (..., T), got "
                        f"{type(t).__name__} {getattr(t, 'dtype', '')}")
    if t.ndim < 1 or t.shape[-1] != y.shape[-2]:
        raise ValueError(f"the sample times t have shape {tuple(t.shape)} but {name} has {y.shape[-2]} samples "
                         f"(shape {tuple(y.shape)}): give one time per sample, shape (..., T)")
    if t.shape[-1] < 2:
        raise ValueError("the sample times t need at least 2 samples to define a step")
    if bool(torch.isnan(t).any()):
        idx = tuple(int(i) for i in torch.isnan(t).nonzero()[0])
        raise ValueError(f"the sample times t hold a NaN (first at index {idx}); drop that sample instead")
    if not bool(torch.isfinite(t).all()):
        raise ValueError("the sample times t hold an infinite value")
    try:
        torch.broadcast_shapes(t.shape[:-1], y.shape[:-2])
    except RuntimeError:
        raise ValueError(f"the leading axes of t {tuple(t.shape)} and {name} {tuple(y.shape)} do not broadcast") from None
    dt = torch.diff(t.to(y.dtype), dim=-1)
    if bool((dt <= 0).any()):
        idx = tuple(int(i) for i in (dt <= 0).nonzero()[0])
        raise ValueError(f"the sample times t must be strictly increasing; t[{idx[-1] + 1}] <= t[{idx[-1]}] "
                         f"(at index {idx[:-1] + (idx[-1] + 1,)}); sort the record or drop repeated times")
    return dt


def row_steps(dt: Steps, i: int, T: int) -> Steps:
    r"""The step of row ``k`` at depth ``i``: :math:`\Delta_{\min(k+i,\,T-2)}`, shape (..., T, 1) (a float stays a float).

    Layer ``i`` of the cascade moves row ``k`` from :math:`t_{k+i}` to :math:`t_{k+i+1}`; past the record's end
    the last interval is repeated.
    """
    if not isinstance(dt, Tensor):
        return dt
    idx = torch.clamp(torch.arange(T) + i, max=T - 2)
    return dt.index_select(-1, idx)[..., None]


def is_uniform(dt: Steps) -> bool:
    """Whether the steps are one float ``Ts``."""
    return not isinstance(dt, Tensor)


def longest(dt: Steps) -> float:
    """The longest step: the one Eq. (25)'s stability check :math:`\\rho(I - \\Delta L) < 1` is strictest for."""
    return float(dt.max()) if isinstance(dt, Tensor) else float(dt)
