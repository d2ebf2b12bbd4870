"""The spiral of App. A.3, Eq. (26)."""

from __future__ import annotations

from collections.abc import Sequence
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


class BatchedSpirals(DynamicalSystem):
    """Several spirals of Eq. (26) in one integration: batch row ``p`` of the state runs ``systems[p]``, on the
    stacked state (P, E 2) of ``E`` copies (the layout of :class:`fnnlib.NeuralODEEnsemble`), so one dopri5 run
    of Theorem 1's continuous observer (:func:`fnnlib.stability.observe_continuous`) covers every spiral and every member.
    """

    def __init__(self, systems: Sequence[Spiral], E: int) -> None:
        if not systems or int(E) != E or int(E) < 1:
            raise ValueError(f"need at least one spiral and a number of copies E >= 1, got {len(systems)}, {E!r}")
        self.A = torch.stack([s.A for s in systems])  # (P, 2, 2)
        self.b = torch.stack([s.b for s in systems])  # (P, 2)
        self.E, self.n = int(E), 2 * int(E)

    def __call__(self, t: Tensor | float, x: Tensor) -> Tensor:
        """dx/dt of row p under spiral p: ``x`` (P, E 2) -> (P, E 2)."""
        if x.shape[0] != self.A.shape[0]:
            raise ValueError(f"need one batch row per spiral ({self.A.shape[0]}), got x of shape {tuple(x.shape)}")
        z = x.reshape(x.shape[0], self.E, 2)
        return (torch.einsum("pij,psj->psi", self.A, z) + self.b[:, None]).reshape(x.shape)
