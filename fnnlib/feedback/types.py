"""The types the Sec. 3 core passes around: vector fields, feedbacks and estimates."""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from torch import Tensor

#: A learned or true vector field ``f(t, x)``, ``x`` of shape (batch, n) -> (batch, n) (torchdiffeq's convention).
VectorField = Callable[[Tensor | float, Tensor], Tensor]

#: A feedback ``h(e)`` on the observation error ``e = x - x_hat`` of shape (batch, n) -> (batch, n) (Sec. 4).
Feedback = Callable[[Tensor], Tensor]


class Estimate(NamedTuple):
    """An observer's output along a trajectory, both of shape (..., T, n).

    ``x_hat`` is the state estimate of Eq. (8), ``f_hat`` the corrected change rate of Eq. (7).
    """

    x_hat: Tensor
    f_hat: Tensor
