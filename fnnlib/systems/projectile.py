"""A thrown object with quadratic drag: the model-based baseline of Sec. 5.1 (App. A.4)."""

from __future__ import annotations

from typing import ClassVar

import torch
from torch import Tensor

from fnnlib._validation import as_trajectory
from fnnlib.systems.base import DynamicalSystem

G = 9.81


class ThrownObject(DynamicalSystem):
    r"""Point mass with per-axis quadratic drag, state :math:`x = [p, v]` (6):

    .. math:: \dot p = v, \qquad \dot v = k \odot \lVert v \rVert v - g e_z

    (``k`` < 0 for drag). The drag baseline of Sec. 5.1 fits ``k`` by least
    squares (:func:`fit_drag`).

    Parameters
    ----------
    k : sequence of 3 floats
        Per-axis drag coefficients, 1/m.
    g : float
        Gravity, m/s^2.
    """

    n: ClassVar[int] = 6

    def __init__(self, k: tuple[float, float, float] | Tensor, g: float = G) -> None:
        self.k = torch.as_tensor(k, dtype=torch.float64).reshape(3)
        self.g = float(g)

    def __call__(self, t: Tensor | float, x: Tensor) -> Tensor:
        """dx/dt for ``x`` of shape (batch, 6)."""
        v = x[..., 3:]
        gvec = torch.tensor([0.0, 0.0, -self.g], dtype=x.dtype)
        a = self.k.to(x.dtype) * torch.linalg.vector_norm(v, dim=-1, keepdim=True) * v + gvec
        return torch.cat([v, a], dim=-1)


def fit_drag(v: Tensor, a: Tensor, *, g: float = G) -> ThrownObject:
    r"""Least-squares drag coefficients from velocities and accelerations.

    Per axis i, :math:`a_i + g\delta_{iz} = k_i \lVert v\rVert v_i`, so
    :math:`k_i = \sum \lVert v\rVert v_i (a_i + g\delta_{iz}) / \sum (\lVert v\rVert v_i)^2`.

    Parameters
    ----------
    v, a : Tensor, shape (..., 3)
        Velocities and accelerations, any leading shape (all samples pooled).
    """
    v = as_trajectory(v.reshape(-1, 3), 3, name="v")
    a = as_trajectory(a.reshape(-1, 3), 3, name="a")
    if v.shape != a.shape:
        raise ValueError(f"v and a must have the same shape, got {tuple(v.shape)} and {tuple(a.shape)}")
    phi = torch.linalg.vector_norm(v, dim=-1, keepdim=True) * v  # regressor |v| v_i
    target = a + torch.tensor([0.0, 0.0, float(g)], dtype=a.dtype)
    k = (phi * target).sum(0) / (phi * phi).sum(0)
    return ThrownObject(k=k, g=g)
