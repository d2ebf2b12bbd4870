r"""Systems with an input u (not in the paper): a linear plant with a closed form, and a damped pendulum.

Both follow :class:`~fnnlib.systems.base.DynamicalSystem`'s controlled convention ``f(t, x, u)``,
``x`` (batch, n), ``u`` (batch, m).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import torch
from torch import Tensor

from fnnlib.systems.base import DynamicalSystem


class LinearSystem(DynamicalSystem):
    r""":math:`\dot x = A x + B u`, ``A`` (n, n), ``B`` (n, m); float64.

    :meth:`discretize` gives its exact zero-order-hold discretisation (the closed form the tests use).
    """

    def __init__(self, A: Tensor, B: Tensor):
        self.A = torch.as_tensor(A, dtype=torch.float64)
        self.B = torch.as_tensor(B, dtype=torch.float64)
        if self.A.ndim != 2 or self.A.shape[0] != self.A.shape[1]:
            raise ValueError(f"A must be square (n, n), got {tuple(self.A.shape)}")
        if self.B.ndim != 2 or self.B.shape[0] != self.A.shape[0]:
            raise ValueError(f"B must have shape ({self.A.shape[0]}, m), got {tuple(self.B.shape)}")
        self.n, self.m = self.A.shape[0], self.B.shape[1]

    def __call__(self, t: Tensor | float, x: Tensor, u: Tensor) -> Tensor:
        return x @ self.A.T.to(x.dtype) + u @ self.B.T.to(x.dtype)  # x' = A x + B u

    def discretize(self, Ts: float) -> tuple[Tensor, Tensor]:
        r"""``(Ad, Bd)`` with :math:`x_{k+1} = A_d x_k + B_d u_k` exactly under zero-order hold.

        :math:`\exp\left(T_s\begin{bmatrix}A & B\\ 0 & 0\end{bmatrix}\right) = \begin{bmatrix}A_d & B_d\\ 0 & I\end{bmatrix}`.
        """
        n, m = self.n, self.m
        M = torch.zeros(n + m, n + m, dtype=torch.float64)
        M[:n, :n], M[:n, n:] = self.A, self.B
        E = torch.linalg.matrix_exp(float(Ts) * M)
        return E[:n, :n], E[:n, n:]


@dataclass(frozen=True)
class Pendulum(DynamicalSystem):
    r"""A damped pendulum driven by a torque: :math:`\dot\theta = \omega`,
    :math:`\dot\omega = -a\sin\theta - c\,\omega + b\,u + d`.

    Parameters
    ----------
    a : float
        :math:`g/l` (1/s^2).
    c : float
        Damping (1/s).
    b : float
        Input gain :math:`1/(m l^2)`.
    d : float
        A constant disturbance torque (per inertia), 0 for the nominal plant.
    """

    a: float
    c: float
    b: float
    d: float
    n: ClassVar[int] = 2
    m: ClassVar[int] = 1

    def __call__(self, t: Tensor | float, x: Tensor, u: Tensor) -> Tensor:
        theta, omega = x[..., 0], x[..., 1]
        domega = -self.a * torch.sin(theta) - self.c * omega + self.b * u[..., 0] + self.d
        return torch.stack([omega, domega], dim=-1)
