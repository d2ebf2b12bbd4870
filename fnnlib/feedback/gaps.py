r"""Eqs. (7)-(8) through missing samples, and with partial measurements ``y = C x``: a loop over time.

Where a sample is missing the feedback term is zero and the estimate moves open loop,
:math:`\hat x_{k+1} = \hat x_k + T_s f_{neural}(\hat x_k, u_k)`; it is corrected again when data return.

* Every state measured (``C`` = I): :math:`\hat f_k = f_{neural}(\tilde z_k) + L(\tilde z_k - \hat x_k)` with
  :math:`\tilde z_k` the input where present and :math:`\hat x_k` where missing (per component); the layer
  outputs :math:`\tilde z_k + T_s \hat f_k`. With no gap this is the paper's layer exactly.
* Partial measurements: the field is evaluated at the estimate,
  :math:`\hat f_k = f_{neural}(\hat x_k) + L(y_k - C\hat x_k)` (gaps: that error set to 0), and the layer
  outputs :math:`\hat x_{k+1}`; layer ``i >= 1`` of the cascade measures the previous layer's output
  through the same ``C`` and starts at it.

The gap flags travel with the rows through the cascade (row k of every layer descends from :math:`y_k`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
from torch import Tensor

from fnnlib.feedback.layer import eval_field, shift_inputs
from fnnlib.feedback.measurement import Measurements
from fnnlib.feedback.types import Estimate, VectorField


def apply_gain(L: Tensor, e: Tensor, diagonal: bool | None = None) -> Tensor:
    """``L e`` in row-vector form: ``e * L`` for diagonals ((n,) or a batch (..., n)), ``e @ L.T`` for a matrix (n, q).

    By default a 1-D ``L`` is a diagonal.
    """
    return e * L if (L.ndim == 1 if diagonal is None else diagonal) else e @ L.T


def measure_fn(meas: Measurements, dtype: torch.dtype) -> Callable[[Tensor], Tensor] | None:
    """``x (..., n) -> y (..., p)`` of the measurement model, or ``None`` when every state is measured."""
    if meas.h is not None:
        return lambda x: meas.h(x.reshape(-1, x.shape[-1])).reshape(*x.shape[:-1], meas.p)
    if meas.C is None:
        return None
    C = meas.C.to(dtype)
    return lambda x: x @ C.T


def start_state(meas: Measurements, n: int, x0: Tensor | None) -> Tensor:
    r""":math:`\hat x_0`: ``x0``, else the least-squares state of the first sample's present outputs, :math:`(M_0C)^+ y_0`."""
    y0 = meas.y[..., 0, :]
    if x0 is not None:
        return torch.as_tensor(x0, dtype=y0.dtype).expand(*y0.shape[:-1], n)
    if meas.C is None and meas.h is None:
        return y0  # gaps hold 0
    if meas.h is not None:
        raise ValueError("with a measurement function h give the first estimate x0 (n,): h cannot be inverted")
    C = meas.C.to(y0.dtype)
    if meas.mask is not None:
        C = meas.mask[..., 0, :, None].to(y0.dtype) * C
    return (torch.linalg.pinv(C) @ y0[..., None])[..., 0]


def step_layer(f: VectorField, z: Tensor, L: Tensor, Ts: float, x0: Tensor, *, mask: Tensor | None = None,
               u: Tensor | None = None, measure: Callable[[Tensor], Tensor] | None = None,
               diagonal: bool | None = None) -> tuple[Estimate, Tensor]:
    """One feedback layer along ``z`` (..., T, q) from :math:`\\hat x_0` = ``x0``: (``x_hat``, ``f_hat``) and its output (..., T, n).

    ``mask`` (..., T, q) marks present samples; ``u`` (..., T, m) the inputs; ``measure`` the map
    ``x -> y`` for partial measurements (``None``: every state measured). See the module docstring.
    """
    x_hat = x0
    x_hats, f_hats, outs = [], [], []
    for k in range(z.shape[-2]):
        zk = z[..., k, :]
        mk = None if mask is None else mask[..., k, :]
        if measure is None:
            at = zk if mk is None else torch.where(mk, zk, x_hat)
            e = at - x_hat
        else:
            at = x_hat
            e = zk - measure(x_hat)
            if mk is not None:
                e = torch.where(mk, e, torch.zeros((), dtype=e.dtype))  # no sample: no correction
        uk = None if u is None else u[..., k:k + 1, :]
        f_hat = eval_field(f, at[..., None, :], uk)[..., 0, :] + apply_gain(L, e, diagonal)  # Eq. (7)
        x_hats.append(x_hat)
        f_hats.append(f_hat)
        outs.append(at + Ts * f_hat)
        x_hat = x_hat + Ts * f_hat  # Eq. (8)
    return Estimate(torch.stack(x_hats, -2), torch.stack(f_hats, -2)), torch.stack(outs, -2)


def gap_cascade(f: VectorField, meas: Measurements, L_stack: Sequence[Tensor], Ts: float, n: int, *,
                x0: Tensor | None = None, return_all: bool = False, diagonal: bool | None = None) -> Tensor:
    """The cascade of Sec. 3.3 through gaps and/or with partial measurements: (..., T, n), or (N+1, ..., T, n).

    Layer ``i`` uses ``L_stack[i]`` and the inputs ``u_{k+i}``; depth 0 of ``return_all`` is layer 0's start
    (the measurements for a full-state model, with gaps filled by the estimate, else the first estimates).
    """
    dtype = meas.y.dtype
    measure = measure_fn(meas, dtype)
    z, start = meas.y, start_state(meas, n, x0)
    depths = []
    for i, L_i in enumerate(L_stack):
        inp = z if (i == 0 or measure is None) else measure(z)
        est, out = step_layer(f, inp, L_i, Ts, start, mask=meas.mask, u=shift_inputs(meas.u, i), measure=measure,
                              diagonal=diagonal)
        if return_all and i == 0:
            depths.append(est.x_hat if measure is not None else
                          (z if meas.mask is None else torch.where(meas.mask, z, est.x_hat)))
        z = out
        start = z[..., 0, :]
        depths.append(z)
    return torch.stack(depths) if return_all else z
