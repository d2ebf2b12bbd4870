"""Measurement noise."""

from __future__ import annotations

import torch
from torch import Tensor


def add_measurement_noise(x: Tensor, std: float, generator: torch.Generator | None = None, *,
                          draws: int | None = None) -> Tensor:
    """Return ``x + std * w`` with ``w`` standard normal, same shape and dtype as ``x``.

    The noisy measurements :math:`x(t_k)` that the feedback of Eq. (7) compares its estimate with.

    With ``draws``, that many noisy copies stacked on a new leading axis, shape (draws, ..., T, n).

    Parameters
    ----------
    x : Tensor, shape (..., T, n)
        Clean states.
    std : float
        Noise standard deviation per component (>= 0).
    generator : torch.Generator, optional
        Source of randomness; pass one for reproducible noise.
    draws : int, optional
        Number of independent noisy copies.
    """
    std = float(std)
    if not std >= 0.0 or std == float("inf"):
        raise ValueError(f"noise std must be finite and >= 0, got {std!r}")
    if draws is not None and (int(draws) != draws or int(draws) < 1):
        raise ValueError(f"number of noise draws must be an integer >= 1, got {draws!r}")
    shape = x.shape if draws is None else (int(draws), *x.shape)
    if std == 0.0:
        return x.expand(shape).clone()
    w = torch.randn(shape, generator=generator, dtype=x.dtype)
    return x + std * w


def add_member_noise(x: Tensor, std: float, generators: list[torch.Generator], *,
                     draws: int | None = None) -> Tensor:
    """Noisy measurements of ``x`` for every member of an ensemble (one network per seed), on the stacked state.

    Member ``e`` sees ``add_measurement_noise(x, std, generators[e], draws=draws)`` -- its own noise draw,
    from its own generator (seed it from the member's seed) -- and the members are concatenated along the
    last axis, the layout of :class:`fnnlib.NeuralODEEnsemble`: shape (..., T, E n), or (draws, ..., T, E n).
    """
    if not generators:
        raise ValueError("need one generator per ensemble member, got none")
    return torch.cat([add_measurement_noise(x, std, g, draws=draws) for g in generators], dim=-1)
