"""Input checks shared by fnnlib: clear errors before any work starts."""

from __future__ import annotations

import torch
from torch import Tensor


def as_trajectory(x: Tensor, n: int | None = None, *, name: str = "x") -> Tensor:
    """Check a trajectory tensor of shape ``(..., T, n)``.

    Raises
    ------
    TypeError
        If ``x`` is not a floating-point tensor.
    ValueError
        If it has fewer than two axes, the wrong state dimension, or holds a
        NaN or infinite value.
    """
    as_series(x, name=name)
    if n is not None and x.shape[-1] != n:
        raise ValueError(f"{name} has state dimension {x.shape[-1]} (shape {tuple(x.shape)}), expected n = {n}")
    check_finite(x, name=name)
    return x


def as_series(x: Tensor, *, name: str = "x", last: str = "n") -> Tensor:
    """Check that ``x`` is a floating-point tensor of shape ``(..., T, <last>)`` (at least two axes).

    Raises
    ------
    TypeError
        If ``x`` is not a floating-point tensor.
    ValueError
        If it has fewer than two axes.
    """
    if not isinstance(x, Tensor):
        raise TypeError(f"{name} must be a torch.Tensor of shape (..., T, {last}), got {type(x).__name__}")
    if not x.is_floating_point():
        raise TypeError(f"{name} must be a floating-point tensor, got dtype {x.dtype}")
    if x.ndim < 2:
        raise ValueError(f"{name} must have shape (..., T, {last}) with at least 2 axes, got shape {tuple(x.shape)}")
    return x


def check_finite(x: Tensor, *, name: str = "x") -> Tensor:
    """Raise ``ValueError`` naming the first bad index if ``x`` holds NaN or inf."""
    bad = ~torch.isfinite(x)
    if bool(bad.any()):
        idx = tuple(int(i) for i in bad.nonzero()[0])
        kind = "NaN" if bool(torch.isnan(x).any()) else "infinite"
        raise ValueError(f"{name} holds a {kind} value (first at index {idx}); refusing to continue")
    return x


def check_uniform_grid(t: Tensor, *, name: str = "t", rtol: float = 1e-6) -> float:
    """Return the step of a strictly increasing, uniform time grid ``t`` of shape ``(T,)``."""
    if t.ndim != 1 or t.numel() < 2:
        raise ValueError(f"{name} must be a 1-D time grid with at least 2 points, got shape {tuple(t.shape)}")
    check_finite(t, name=name)
    dt = torch.diff(t.double())
    if bool((dt <= 0).any()):
        raise ValueError(f"{name} must be strictly increasing")
    Ts = float(dt.mean())
    if float((dt - Ts).abs().max()) > rtol * max(1.0, abs(Ts)) + 1e-12:
        raise ValueError(f"{name} must be a uniform grid (steps range {float(dt.min()):.3g}..{float(dt.max()):.3g})")
    return Ts


def check_positive(value: float, *, name: str) -> float:
    """Return ``float(value)`` if it is finite and > 0, else raise ``ValueError``."""
    v = float(value)
    if not (v > 0 and v < float("inf")):
        raise ValueError(f"{name} must be a finite positive number, got {value!r}")
    return v
