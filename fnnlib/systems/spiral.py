"""The spiral of App. A.3, Eq. (26)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import torch
from torch import Tensor

from fnnlib.systems.base import DynamicalSystem


@dataclass(frozen=True)
class Spiral(DynamicalSystem):
    r"""Spiral dynamics, Eq. (26):

    .. math:: \dot x = \begin{bmatrix}-\eta & \omega\\ -\omega & -\eta\end{bmatrix} x
              + \begin{bmatrix}\varepsilon\\ \varepsilon\end{bmatrix}

    Parameters
    ----------
    omega : float
        Angular rate (the paper's "period") :math:`\omega`.
    eta : float
        Decay rate :math:`\eta`.
    eps : float
        Bias :math:`\varepsilon`.
    """

    omega: float
    eta: float
    eps: float
    n: ClassVar[int] = 2

    @property
    def A(self) -> Tensor:
        """System matrix, shape (2, 2), float64."""
        return torch.tensor([[-self.eta, self.omega], [-self.omega, -self.eta]], dtype=torch.float64)

    @property
    def b(self) -> Tensor:
        """Bias vector, shape (2,), float64."""
        return torch.tensor([self.eps, self.eps], dtype=torch.float64)

    def __call__(self, t: Tensor | float, x: Tensor) -> Tensor:
        """dx/dt for ``x`` of shape ``(batch, 2)``; Eq. (26)."""
        A = self.A.to(x.dtype)
        b = self.b.to(x.dtype)
        return x @ A.T + b  # x_dot = A x + b, row-vector form

    def exact_solution(self, x0: Tensor, t: Tensor) -> Tensor:
        r"""Closed form :math:`x(t) = x^* + e^{A t}(x_0 - x^*)`, :math:`x^* = -A^{-1} b`.

        Shapes as :meth:`simulate`: ``x0`` (..., 2), ``t`` (T,) -> (..., T, 2).
        Requires a non-singular A (:math:`\eta^2 + \omega^2 > 0`).
        """
        x0 = torch.as_tensor(x0, dtype=torch.float64)
        t = torch.as_tensor(t, dtype=torch.float64)
        A, b = self.A, self.b
        x_star = -torch.linalg.solve(A, b)
        expAt = torch.linalg.matrix_exp(A * (t - t[0])[:, None, None])  # (T, 2, 2)
        dev = (x0 - x_star)[..., None, :, None]  # (..., 1, 2, 1)
        return x_star + (expAt @ dev).squeeze(-1)

    def with_params(self, **changes: float) -> "Spiral":
        """A copy with some of (omega, eta, eps) changed."""
        params = {"omega": self.omega, "eta": self.eta, "eps": self.eps}
        unknown = set(changes) - set(params)
        if unknown:
            raise TypeError(f"unknown spiral parameter(s) {sorted(unknown)}; known: omega, eta, eps")
        params.update(changes)
        return Spiral(**params)
