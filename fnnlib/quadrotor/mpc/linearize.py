r"""Affine models of a discrete torch step along a nominal plan, for the QP of Eq. (28).

The MPC of Eq. (28) (App. A.5.3, ``Standard_MPC``) predicts with a discrete
model :math:`x_{k+1} = f_d(x_k, u_k)`. :func:`linearize` replaces it along a
nominal plan :math:`(\bar x_k, \bar u_k)`, :math:`k = 0..N-1`, by

.. math:: x_{k+1} \approx A_k x_k + B_k u_k + c_k, \qquad
          A_k = \partial f_d / \partial x, \;
          B_k = \partial f_d / \partial u, \;
          c_k = f_d(\bar x_k, \bar u_k) - A_k \bar x_k - B_k \bar u_k,

all N Jacobians in one batched call of the model.

Method (measured, see ``benchmarks/bench_mpc.py``): reverse mode over a
replicated batch. The N nominal points are stacked n times, the a-th copy
gets the cotangent :math:`e_a`, and a single ``torch.autograd.grad`` call
returns every row of every :math:`[A_k\;B_k]`. With torch 2.13 on CPU this
beat ``vmap(jacrev)`` (about 2x), ``autograd.functional.jacobian(...,
vectorize=True)`` and every forward-mode variant (``jvp``/``jacfwd``, about
4x slower) for n = 12, m = 4, N = 10 and an RK4 rigid body with an MLP inside.
"""

from __future__ import annotations

import math

from collections.abc import Callable
from typing import Literal, NamedTuple

import numpy as np
import torch
from torch import Tensor

StepFn = Callable[[Tensor, Tensor, Tensor], Tensor]
"""A discrete model ``step(x (B, n), u (B, m), k (B,) int64) -> x_next (B, n)``."""

METHODS = ("reverse", "vmap", "central", "forward")


class Linearization(NamedTuple):
    r"""Affine model :math:`x_{k+1} \approx A_k x_k + B_k u_k + c_k`, k = 0..N-1 (numpy float64).

    Attributes
    ----------
    A : ndarray, shape (N, n, n)
        :math:`A_k = \partial f_d/\partial x` at :math:`(\bar x_k, \bar u_k)`.
    B : ndarray, shape (N, n, m)
        :math:`B_k = \partial f_d/\partial u`.
    c : ndarray, shape (N, n)
        :math:`c_k = f_d(\bar x_k, \bar u_k) - A_k \bar x_k - B_k \bar u_k`.
    x_next : ndarray, shape (N, n)
        :math:`f_d(\bar x_k, \bar u_k)`, the model's own prediction at the nominal points.
    """

    A: np.ndarray
    B: np.ndarray
    c: np.ndarray
    x_next: np.ndarray


def _as_tensor(value: Tensor | np.ndarray, dtype: torch.dtype, name: str, ndim: int) -> Tensor:
    t = value.detach().to(dtype) if isinstance(value, Tensor) else torch.as_tensor(np.asarray(value, dtype=np.float64), dtype=dtype)
    if t.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} axes, got shape {tuple(t.shape)}")
    if not bool(torch.isfinite(t).all()):
        raise ValueError(f"{name} holds a NaN or infinite value; cannot linearise there")
    return t


def _infer_dtype(step: StepFn, x_bar: Tensor | np.ndarray) -> torch.dtype:
    if isinstance(x_bar, Tensor) and x_bar.is_floating_point():
        return x_bar.dtype
    if isinstance(step, torch.nn.Module):
        for p in list(step.parameters()) + list(step.buffers()):
            if p.is_floating_point():
                return p.dtype
    return torch.float64


def linearize(
    step: StepFn,
    x_bar: Tensor | np.ndarray,
    u_bar: Tensor | np.ndarray,
    k: Tensor | np.ndarray | None = None,
    *,
    method: Literal["reverse", "vmap", "central", "forward"] = "reverse",
    dtype: torch.dtype | None = None,
    h: float | None = None,
) -> Linearization:
    r"""Jacobians :math:`A_k, B_k` and offsets :math:`c_k` of a torch model along a nominal plan.

    Parameters
    ----------
    step : callable
        Discrete model ``step(x, u, k) -> x_next`` with ``x`` (B, n), ``u`` (B, m),
        ``k`` an int64 tensor (B,) of horizon indices (so a model can add a
        per-step correction) and ``x_next`` (B, n). It must treat the B rows
        independently (no batch statistics): the ``"reverse"`` method calls it once
        on n stacked copies of the plan, i.e. B = n N. The ``"vmap"`` method calls
        it on single rows (B = 1) under ``torch.func.vmap`` instead.
    x_bar : Tensor or ndarray, shape (N, n)
        Nominal states :math:`\bar x_0..\bar x_{N-1}`.
    u_bar : Tensor or ndarray, shape (N, m)
        Nominal inputs :math:`\bar u_0..\bar u_{N-1}`.
    k : Tensor or ndarray of int, shape (N,), optional
        Horizon index of each point; default ``arange(N)``.
    method : {"reverse", "vmap", "central"}
        ``"reverse"`` (default, exact): one reverse pass over the plan
        replicated n times. ``"vmap"``: ``torch.func.vmap(torch.func.jacrev(...))``.
        ``"central"``: central differences with step ``h``, all ``2(n+m)+1`` points of
        all N plan points in one forward call without a graph (about 2x faster for
        the quadrotor models; error ~1e-9 in float64, use it in float64 only).
        ``"forward"``: one-sided differences, ``n+m+1`` points per plan point (half the
        rows of ``"central"``; error ~1e-7 in float64).
    h : float, optional
        Difference step; default 1e-6 for ``"central"``, 1.5e-8 (about the square root of
        float64's epsilon) for ``"forward"``.
    dtype : torch.dtype, optional
        Dtype the model is evaluated in. Default: ``x_bar``'s dtype if it is a
        floating tensor, else the dtype of the module's first floating parameter
        if ``step`` is an ``nn.Module``, else float64.

    Returns
    -------
    Linearization
        ``A`` (N, n, n), ``B`` (N, n, m), ``c`` (N, n), ``x_next`` (N, n), numpy float64.

    Raises
    ------
    ValueError
        Bad shapes, a NaN/inf in the plan, an unknown method, or a model output of the
        wrong shape or holding NaN/inf.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    float_dtype = dtype if dtype is not None else _infer_dtype(step, x_bar)
    if not float_dtype.is_floating_point:
        raise ValueError(f"dtype must be a floating-point torch dtype, got {float_dtype}")
    x = _as_tensor(x_bar, float_dtype, "x_bar (N, n)", 2)
    u = _as_tensor(u_bar, float_dtype, "u_bar (N, m)", 2)
    N, n = x.shape
    m = u.shape[1]
    if N < 1 or n < 1:
        raise ValueError(f"x_bar must have shape (N, n) with N, n >= 1, got {tuple(x.shape)}")
    if u.shape[0] != N:
        raise ValueError(f"u_bar has {u.shape[0]} rows but x_bar has N = {N}; both must be (N, .)")
    if k is None:
        kk = torch.arange(N)
    else:
        kk = torch.as_tensor(k)
        if kk.shape != (N,) or kk.is_floating_point() or kk.is_complex() or kk.dtype == torch.bool:
            raise ValueError(f"k must be an integer tensor of shape ({N},), got dtype {kk.dtype} shape {tuple(kk.shape)}")
        kk = kk.to(torch.long)

    if method == "reverse":
        A, B, x_next = _jacobians_reverse(step, x, u, kk)
    elif method in ("central", "forward"):
        h = (1e-6 if method == "central" else 1.5e-8) if h is None else h
        if not (math.isfinite(h) and h > 0):
            raise ValueError(f"difference step h must be finite and > 0, got {h!r}")
        jac = _jacobians_central if method == "central" else _jacobians_forward
        A, B, x_next = jac(step, x, u, kk, float(h))
    else:
        A, B, x_next = _jacobians_vmap(step, x, u, kk)

    as_np = lambda t: t.double().cpu().numpy()  # noqa: E731
    return affine_model(as_np(A), as_np(B), as_np(x_next), as_np(x), as_np(u))


def affine_model(A: np.ndarray, B: np.ndarray, x_next: np.ndarray, x_bar: np.ndarray,
                 u_bar: np.ndarray) -> Linearization:
    r"""The :class:`Linearization` from Jacobians and the model's value at the plan:
    :math:`c_k = f_d(\bar x_k, \bar u_k) - A_k \bar x_k - B_k \bar u_k`.

    Raises
    ------
    ValueError
        If any of ``A``, ``B``, ``x_next`` or the resulting ``c`` holds NaN or inf.
    """
    with np.errstate(all="ignore"):
        finite = np.isfinite(A).all() and np.isfinite(B).all() and np.isfinite(x_next).all()
        c = x_next - np.einsum("kij,kj->ki", A, x_bar) - np.einsum("kij,kj->ki", B, u_bar)
    if not (finite and np.isfinite(c).all()):
        raise ValueError("the model returned a NaN or infinite value (or derivative) at the nominal plan")
    return Linearization(A, B, c, x_next)


def _check_output(out: Tensor, rows: int, n: int) -> None:
    if not isinstance(out, Tensor) or out.shape != (rows, n):
        shape = tuple(out.shape) if isinstance(out, Tensor) else type(out).__name__
        raise ValueError(f"step(x, u, k) must return x_next of shape ({rows}, {n}) for x of shape ({rows}, {n}), got {shape}")


def _jacobians_reverse(step: StepFn, x: Tensor, u: Tensor, k: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """One reverse pass over the plan replicated n times: copy a carries the cotangent e_a."""
    N, n = x.shape
    X = x.repeat(n, 1).requires_grad_(True)  # row a*N + i = x_bar_i (copy a)
    U = u.repeat(n, 1).requires_grad_(True)
    with torch.enable_grad():
        out = step(X, U, k.repeat(n))
        _check_output(out, n * N, n)
        if not out.requires_grad:  # the model ignores x and u
            zeros = torch.zeros(N, n, n + u.shape[1], dtype=x.dtype)
            return zeros[..., :n], zeros[..., n:], out[:N].detach()
        cot = torch.eye(n, dtype=out.dtype).repeat_interleave(N, dim=0)  # row a*N + i = e_a
        gx, gu = torch.autograd.grad(out, (X, U), cot, allow_unused=True)
    gx = torch.zeros_like(X) if gx is None else gx
    gu = torch.zeros_like(U) if gu is None else gu
    # gx[a*N + i, :] = d x_next_{i,a} / d x_i  ->  A[i, a, :]
    A = gx.reshape(n, N, n).transpose(0, 1)
    B = gu.reshape(n, N, -1).transpose(0, 1)
    return A, B, out[:N].detach()


def _jacobians_central(step: StepFn, x: Tensor, u: Tensor, k: Tensor, h: float) -> tuple[Tensor, Tensor, Tensor]:
    """Central differences: every perturbed point of every plan point in one batched call."""
    N, n = x.shape
    d = n + u.shape[1]
    z = torch.cat([x, u], dim=-1)  # (N, d)
    E = h * torch.eye(d, dtype=z.dtype)
    Z = torch.cat([z[:, None] + E, z[:, None] - E, z[:, None]], dim=1).reshape(-1, d)  # (N (2d+1), d)
    with torch.no_grad():
        out = step(Z[:, :n], Z[:, n:], k.repeat_interleave(2 * d + 1))
    _check_output(out, N * (2 * d + 1), n)
    out = out.reshape(N, 2 * d + 1, n)
    # J[:, :, j] = (f(z + h e_j) - f(z - h e_j)) / 2h
    J = ((out[:, :d] - out[:, d:2 * d]) / (2 * h)).transpose(1, 2)  # (N, n, d)
    return J[..., :n], J[..., n:], out[:, -1]


def _jacobians_forward(step: StepFn, x: Tensor, u: Tensor, k: Tensor, h: float) -> tuple[Tensor, Tensor, Tensor]:
    """One-sided differences: ``n+m`` perturbed points and the nominal one per plan point, one batched call."""
    N, n = x.shape
    d = n + u.shape[1]
    z = torch.cat([x, u], dim=-1)  # (N, d)
    Z = torch.cat([z[:, None] + h * torch.eye(d, dtype=z.dtype), z[:, None]], dim=1).reshape(-1, d)  # (N (d+1), d)
    with torch.no_grad():
        out = step(Z[:, :n], Z[:, n:], k.repeat_interleave(d + 1))
    _check_output(out, N * (d + 1), n)
    out = out.reshape(N, d + 1, n)
    # J[:, :, j] = (f(z + h e_j) - f(z)) / h
    J = ((out[:, :d] - out[:, -1:]) / h).transpose(1, 2)  # (N, n, d)
    return J[..., :n], J[..., n:], out[:, -1]


def _jacobians_vmap(step: StepFn, x: Tensor, u: Tensor, k: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """``vmap(jacrev)`` over single rows: for models that are functorch-compatible."""
    n = x.shape[1]

    def one(xi: Tensor, ui: Tensor, ki: Tensor) -> tuple[Tensor, Tensor]:
        y = step(xi[None], ui[None], ki[None])
        _check_output(y, 1, n)
        return y[0], y[0]

    jac = torch.func.jacrev(one, argnums=(0, 1), has_aux=True)
    (A, B), x_next = torch.func.vmap(jac)(x, u, k)
    return A.detach(), B.detach(), x_next.detach()
