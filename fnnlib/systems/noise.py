"""Measurement noise."""

from __future__ import annotations

import torch
from torch import Tensor


def add_measurement_noise(x: Tensor, std: float, generator: torch.Generator | None = None) -> Tensor:
    """Return ``x + std * w`` with ``w`` standard normal, same shape and dtype as ``x``.

    Parameters
    ----------
    x : Tensor, shape (..., T, n)
        Clean states.
    std : float
        Noise standard deviation per component (>= 0).
    generator : torch.Generator, optional
        Source of randomness; pass one for reproducible noise.
    """
    std = float(std)
    if not std >= 0.0 or std == float("inf"):
        raise ValueError(f"noise std must be finite and >= 0, got {std!r}")
    if std == 0.0:
        return x.clone()
    w = torch.randn(x.shape, generator=generator, dtype=x.dtype)
    return x + std * w
