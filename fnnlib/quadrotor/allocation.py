"""The motor allocation of Eq. (27): ``[T, tau_x, tau_y, tau_z] = C u`` for the PX4 "quad X" layout.

Motors 1 front-right, 2 rear-left, 3 front-left, 4 rear-right; motors 1 and 2 spin so that their drag
torque is ``+c u`` about ``z_B`` (see :mod:`fnnlib.quadrotor.system`).
"""

from __future__ import annotations

from typing import Protocol

import torch
from torch import Tensor

__all__ = ["Arms", "allocation_inverse", "allocation_matrix"]


class Arms(Protocol):
    """What the allocation reads of a vehicle (:class:`fnnlib.quadrotor.system.QuadrotorParams` has both): the
    moment arm ``d = l / sqrt(2)`` in m and the torque coefficient ``c`` in m."""

    @property
    def moment_arm(self) -> float: ...

    @property
    def torque_coeff(self) -> float: ...


def allocation_matrix(
    params: Arms, *, dtype: torch.dtype = torch.float64, device: torch.device | str | None = None
) -> Tensor:
    """Control allocation ``C`` of Eq. (27): ``[T, tau_x, tau_y, tau_z] = C u``.

    With ``d = l / sqrt(2)`` and ``c`` the torque coefficient::

        T     =    u1 + u2 + u3 + u4
        tau_x = d(-u1 + u2 + u3 - u4)
        tau_y = d( u1 - u2 + u3 - u4)
        tau_z = c( u1 + u2 - u3 - u4)

    (each motor at ``r_i`` in B pushing ``-u_i e3`` gives ``r_i x (-u_i e3)``).

    Returns
    -------
    Tensor, shape (4, 4)
    """
    d, c = params.moment_arm, params.torque_coeff
    rows = [[1.0, 1.0, 1.0, 1.0], [-d, d, d, -d], [d, -d, d, -d], [c, c, -c, -c]]
    return torch.tensor(rows, dtype=dtype, device=device)


def allocation_inverse(
    params: Arms, *, dtype: torch.dtype = torch.float64, device: torch.device | str | None = None
) -> Tensor:
    """``C^{-1}``: motor thrusts from ``[T, tau]``, ``u = C^{-1} [T, tau]``.

    The rows of ``C`` are orthogonal, so ``C^{-1} = C^T diag(1/4, 1/(4d^2), 1/(4d^2), 1/(4c^2))``
    (exact, no numerical inversion).

    Returns
    -------
    Tensor, shape (4, 4)
    """
    d, c = params.moment_arm, params.torque_coeff
    C = allocation_matrix(params, dtype=dtype, device=device)
    scale = torch.tensor([0.25, 0.25 / d**2, 0.25 / d**2, 0.25 / c**2], dtype=dtype, device=device)
    return C.T * scale
