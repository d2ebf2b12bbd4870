r"""One measurement model for every estimator: :math:`y_k = C x_k` (or :math:`h(x_k)`), inputs :math:`u_k`, gaps.

Shapes follow :meth:`~fnnlib.systems.DynamicalSystem.simulate`: measurements ``y`` (..., T, p), inputs ``u``
(..., T, m) with one row per sample (held over the step from that sample), broadcast against ``y``'s leading
axes. The measurement is a matrix ``C`` (p, n) or a callable ``h(x)``, ``x`` (batch, n) -> (batch, p), whose
Jacobian is taken by autograd (:func:`output_jacobian`).

A missing sample is a NaN in ``y`` or a ``False`` in a boolean ``mask`` of shape (..., T) (the whole row) or
(..., T, p) (one output: multi-rate sensors). :func:`check_measurements` is the one check every estimator runs
before any work: dtypes, shapes, lengths, NaN and ``C`` against the state dimension ``n``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import torch
from torch import Tensor

from fnnlib._validation import as_series
from fnnlib.feedback.layer import check_model_dtype

#: A measurement function ``h(x)``, ``x`` (batch, n) -> (batch, p).
OutputMap = Callable[[Tensor], Tensor]


class Measurements(NamedTuple):
    """Checked measurements: ``y`` (..., T, p) with gaps set to 0, ``mask`` (..., T, p) bool or ``None``
    (every sample present), ``u`` (..., T, m) or ``None``, ``C`` (p, n) float64 or ``None`` (``h`` or every
    state measured), ``h`` the callable measurement or ``None``, ``p`` outputs."""

    y: Tensor
    mask: Tensor | None
    u: Tensor | None
    C: Tensor | None
    h: OutputMap | None
    p: int


def check_output_matrix(C: Tensor, n: int, p: int | None = None) -> Tensor:
    """``C`` as a finite (p, n) float64 matrix; a transposed ``C`` (n, p) is named as such."""
    C = torch.as_tensor(C)
    if C.is_complex() or not (C.is_floating_point() or C.dtype in (torch.int32, torch.int64)):
        raise TypeError(f"C must be a real (p, n) matrix, got dtype {C.dtype}")
    C = C.to(torch.float64)
    if C.ndim != 2:
        raise ValueError(f"C must be a (p, n) matrix (p outputs of n = {n} states), got shape {tuple(C.shape)}")
    if C.shape[1] != n:
        hint = (f"; it looks transposed: pass C.T, of shape ({C.shape[1]}, {n})" if C.shape[0] == n else "")
        raise ValueError(f"C has shape {tuple(C.shape)} but must be (p, n) with n = {n} columns, one per state{hint}")
    if p is not None and C.shape[0] != p:
        raise ValueError(f"C has {C.shape[0]} rows (outputs) but the measurements have p = {p} columns")
    if not bool(torch.isfinite(C).all()):
        raise ValueError("C holds NaN or infinite entries")
    return C


def _check_u(u: Tensor, y: Tensor, name: str) -> Tensor:
    """Inputs ``u`` (..., T, m) against measurements ``y`` (..., T, p): type, dtype, length, leading axes, finite."""
    if not isinstance(u, Tensor) or not u.is_floating_point() or u.ndim < 2:
        raise TypeError(f"inputs u must be a floating-point tensor of shape (..., T, m), got "
                        f"{type(u).__name__} {tuple(getattr(u, 'shape', ()))}")
    if u.shape[-2] != y.shape[-2]:
        raise ValueError(f"inputs u have {u.shape[-2]} rows but {name} has {y.shape[-2]} samples: give one input "
                         "row per sample, shape (..., T, m), the convention of simulate")
    if u.dtype != y.dtype:
        raise TypeError(f"inputs u are {u.dtype} but {name} is {y.dtype}; convert one of them")
    try:
        torch.broadcast_shapes(u.shape[:-2], y.shape[:-2])
    except RuntimeError:
        raise ValueError(f"the leading axes of u {tuple(u.shape)} and {name} {tuple(y.shape)} do not broadcast") from None
    if not bool(torch.isfinite(u).all()):
        idx = tuple(int(i) for i in (~torch.isfinite(u)).nonzero()[0])
        raise ValueError(f"inputs u hold a NaN or infinite value (first at index {idx}); inputs cannot be missing")
    return u


def _check_mask(mask: Tensor, y: Tensor, name: str) -> Tensor:
    """A boolean mask (..., T) or (..., T, p) expanded to ``y``'s shape."""
    if not isinstance(mask, Tensor) or mask.dtype != torch.bool:
        raise TypeError(f"mask must be a boolean tensor of shape (..., T) or (..., T, p), got "
                        f"{type(mask).__name__} {getattr(mask, 'dtype', '')}")
    m = mask if mask.ndim >= 1 and mask.shape[-1] == y.shape[-1] and mask.ndim == y.ndim else mask[..., None]
    try:
        return m.expand(y.shape)
    except RuntimeError:
        raise ValueError(f"mask of shape {tuple(mask.shape)} fits neither (..., T) nor (..., T, p) of {name} "
                         f"{tuple(y.shape)}") from None


def check_measurements(y: Tensor, n: int, *, C: Tensor | OutputMap | None = None, u: Tensor | None = None,
                       mask: Tensor | None = None, f=None, missing: bool = True, name: str = "y") -> Measurements:
    """The one check of measurements ``y`` (..., T, p) before any work; see the module docstring.

    What the feedback of Eq. (7) compares its estimate with: ``y = C x`` or ``h(x)``, with inputs and gaps.

    ``n`` is the state dimension; ``C`` (p, n), a callable ``h`` or ``None`` (every state measured, p = n);
    ``f`` the model, whose parameters must share ``y``'s dtype. With ``missing`` a NaN means "no
    measurement"; without it, NaN is refused. Raises ``TypeError`` / ``ValueError`` naming what is wrong.
    """
    as_series(y, name=name, last="p")
    if y.shape[-2] < 1:
        raise ValueError(f"{name} needs at least one sample, got shape {tuple(y.shape)}")
    h, Cm = (C, None) if callable(C) and not isinstance(C, Tensor) else (None, C)
    if h is not None:
        with torch.no_grad():
            out = h(torch.zeros(1, n, dtype=y.dtype))
        if not isinstance(out, Tensor) or out.shape != (1, y.shape[-1]):
            raise ValueError(f"h(x) must map (batch, n = {n}) to (batch, p = {y.shape[-1]}) (the columns of {name}), "
                             f"got shape {tuple(getattr(out, 'shape', ()))}")
    elif Cm is not None:
        Cm = check_output_matrix(Cm, n, y.shape[-1])
    elif y.shape[-1] != n:
        raise ValueError(f"{name} has {y.shape[-1]} columns but the state has n = {n}; for partial measurements "
                         "pass C (p, n)")
    if f is not None:
        check_model_dtype(f, y)
    if bool(torch.isinf(y).any()):
        idx = tuple(int(i) for i in torch.isinf(y).nonzero()[0])
        raise ValueError(f"{name} holds an infinite value (first at index {idx})")
    nan = torch.isnan(y)
    if bool(nan.any()) and not missing:
        idx = tuple(int(i) for i in nan.nonzero()[0])
        raise ValueError(f"{name} holds a NaN value (first at index {idx}); refusing to continue")
    m = None if mask is None else _check_mask(mask, y, name)
    if bool(nan.any()):
        m = ~nan if m is None else m & ~nan
    if m is not None:
        present = m.flatten(-2).any(-1)  # (...,): a record with at least one present sample
        if not bool(present.all()):
            idx = tuple(int(i) for i in (~present).nonzero()[0]) if present.ndim else ()
            where = f" (record {idx})" if idx else ""
            raise ValueError(f"{name} has no present sample at all{where}: every value is NaN or masked out, so there "
                             "is nothing to estimate from; drop that record")
    if m is not None and bool(m.all()):
        m = None  # every sample present: the gap-free path
    if m is not None:
        y = torch.where(m, y, torch.zeros((), dtype=y.dtype))
    if u is not None:
        u = _check_u(u, y, name)
    return Measurements(y, m, u, Cm, h, y.shape[-1])


def _batched_jacobian(fn: Callable[[Tensor], Tensor], x: Tensor, q: int) -> Tensor:
    """Jacobians of ``fn`` (batch, n) -> (batch, q) at every row of ``x`` (..., n): (..., q, n).

    One forward and one backward pass: each row is repeated q times, copy i's output i is summed, and the
    gradient of that sum is row i of the Jacobian (the rows of a (batch, n) field are independent).
    """
    lead, n = x.shape[:-1], x.shape[-1]
    flat = x.detach().reshape(-1, n)
    with torch.enable_grad():
        X = flat[:, None, :].expand(flat.shape[0], q, n).reshape(-1, n).clone().requires_grad_(True)
        out = fn(X)
        if out.shape != (X.shape[0], q):
            raise ValueError(f"the function returned shape {tuple(out.shape)} for input {tuple(X.shape)}; "
                             f"expected ({X.shape[0]}, {q})")
        (J,) = torch.autograd.grad(out.reshape(-1, q, q).diagonal(dim1=1, dim2=2).sum(), X)
    return J.reshape(*lead, q, n)


def model_jacobian(f, x: Tensor, u: Tensor | None = None, *, t: float = 0.0) -> Tensor:
    r"""The model's Jacobian :math:`A = \partial f/\partial x` at the states ``x`` (..., n): shape (..., n, n).

    The linearisation of :math:`f_{neural}` (Eq. (3)) that a gain of Eq. (7) is checked or placed against.

    ``f(t, x)`` or, with inputs ``u`` (..., m), ``f(t, x, u)``; one batched autograd call
    (:func:`_batched_jacobian`). E.g. ``A = model_jacobian(f, x_op)`` at an operating point, for
    the detectability and stability checks of :class:`~fnnlib.feedback.measured.MeasuredFeedback`.
    """
    if not isinstance(x, Tensor) or not x.is_floating_point() or x.ndim < 1:
        raise TypeError(f"x must be a floating-point tensor of shape (..., n), got {type(x).__name__}")
    check_model_dtype(f, x[None])
    n = x.shape[-1]
    if u is None:
        return _batched_jacobian(lambda xs: f(t, xs), x, n)
    u = torch.as_tensor(u, dtype=x.dtype).expand(*x.shape[:-1], -1)
    m = u.shape[-1]
    U = u.reshape(-1, 1, m).expand(-1, n, m).reshape(-1, m)
    return _batched_jacobian(lambda xs: f(t, xs, U), x, n)


def output_jacobian(h: OutputMap, x: Tensor) -> Tensor:
    """The Jacobian of a measurement function ``h`` at the states ``x`` (..., n): shape (..., p, n)."""
    with torch.no_grad():
        p = h(x.reshape(-1, x.shape[-1])[:1]).shape[-1]
    return _batched_jacobian(h, x, p)


def output_matrix_at(meas: Measurements, x: Tensor) -> Tensor:
    """The measurement matrix (p, n) float64: ``C`` itself, or the Jacobian of ``h`` at one state ``x`` (n,)."""
    if meas.h is None:
        return meas.C if meas.C is not None else torch.eye(x.shape[-1], dtype=torch.float64)
    return output_jacobian(meas.h, x.reshape(1, -1))[0].double()


class DetectabilityError(ValueError):
    """A measurement layout that leaves a mode with :math:`|\\lambda| \\ge 1` unseen: no gain makes its error decay."""


def check_detectable(Ad: Tensor, C: Tensor, *, labels: list[str] | None = None, what: str = "(Ad, C)",
                     tol: float = 1e-9) -> None:
    r"""PBH test of a discrete pair: every eigenvalue :math:`\lambda` of ``Ad`` (m, m) with :math:`|\lambda| \ge 1`
    must have :math:`[\lambda I - A_d;\; C]` of full column rank. Raises :class:`DetectabilityError` naming
    the eigenvalue and the unseen mode (its eigenvector, by the ``labels`` of the state components)."""
    Ad = torch.as_tensor(Ad, dtype=torch.float64)
    C = torch.as_tensor(C, dtype=torch.float64)
    m = Ad.shape[0]
    eye = torch.eye(m, dtype=torch.complex128)
    labels = labels or [f"z{i}" for i in range(m)]
    for lam in torch.linalg.eigvals(Ad):
        if abs(complex(lam)) < 1 - tol:
            continue
        pbh = torch.cat([lam * eye - Ad.to(torch.complex128), C.to(torch.complex128)])
        _, S, Vh = torch.linalg.svd(pbh)
        if float(S[-1]) > 1e-9 * max(1.0, float(S[0])):
            continue
        v = Vh[-1].conj()
        v = v / v[int(v.abs().argmax())]
        mode = " + ".join(f"{complex(c).real:.3g}*{labels[i]}" for i, c in enumerate(v.tolist()) if abs(c) > 1e-6)
        raise DetectabilityError(
            f"{what} is not detectable: the mode with eigenvalue {complex(lam):.4g} (|z| >= 1), direction "
            f"{mode}, is not seen by the measurements (PBH: [lambda I - A; C] v = 0), so no gain can make its "
            "error decay; measure more outputs or model fewer disturbances")
