r"""Rotations of the quadrotor of Eq. (27): ``R = Rz(psi) Ry(theta) Rx(phi)`` (Euler ZYX), the Euler-rate map ``W``.

Conventions as in :mod:`fnnlib.quadrotor.system`: ``Theta = (phi, theta, psi)``, ``R`` maps body to world,
``Theta' = W(Theta) omega`` with ``omega`` the body rates. Also the batched matrix-vector products the
quadrotor code uses, and the trilinear maps that turn Eq. (27)'s trigonometry into one matmul each.
"""

from __future__ import annotations

import torch
from torch import Tensor

from fnnlib._validation import check_finite

__all__ = [
    "T_R",
    "T_W",
    "check_last",
    "euler_from_rotation",
    "euler_rate_matrix",
    "inverse_euler_rate_matrix",
    "matvec",
    "outer3",
    "rmatvec",
    "rotation_from_basis",
    "rotation_matrix",
    "trig_basis",
]


def check_last(x: Tensor, n: int, name: str) -> Tensor:
    """Refuse ``x`` unless it is a finite floating-point tensor of shape (..., n); return it."""
    if not isinstance(x, Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(x).__name__}")
    if not x.is_floating_point():
        raise TypeError(f"{name} must be a floating-point tensor, got dtype {x.dtype}")
    if x.ndim < 1 or x.shape[-1] != n:
        raise ValueError(f"{name} must have shape (..., {n}), got shape {tuple(x.shape)}")
    check_finite(x, name=name)
    return x


def _mat3(entries: list[Tensor]) -> Tensor:
    """Stack 9 tensors of shape (...,) row-major into shape (..., 3, 3)."""
    M = torch.stack(entries, dim=-1)
    return M.reshape(*M.shape[:-1], 3, 3)


def _elementary_rotations() -> tuple[Tensor, Tensor, Tensor]:
    """``Rx``, ``Ry``, ``Rz`` as (3, 3, 3) tensors ``T[i, j, c]``, linear in ``b = (1, cos, sin)`` of their angle.

    ``Rx(phi)[i, j] = sum_c T_x[i, j, c] b_phi[c]`` and likewise for ``Ry(theta)``, ``Rz(psi)``.
    """
    T_x, T_y, T_z = (torch.zeros(3, 3, 3, dtype=torch.float64) for _ in range(3))
    one, cos, sin = 0, 1, 2
    # Rx = [[1, 0, 0], [0, c, -s], [0, s, c]]
    T_x[0, 0, one], T_x[1, 1, cos], T_x[1, 2, sin], T_x[2, 1, sin], T_x[2, 2, cos] = 1, 1, -1, 1, 1
    # Ry = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    T_y[0, 0, cos], T_y[0, 2, sin], T_y[1, 1, one], T_y[2, 0, sin], T_y[2, 2, cos] = 1, 1, 1, -1, 1
    # Rz = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T_z[0, 0, cos], T_z[0, 1, sin], T_z[1, 0, sin], T_z[1, 1, cos], T_z[2, 2, one] = 1, -1, 1, 1, 1
    return T_x, T_y, T_z


def _trilinear_maps() -> tuple[Tensor, Tensor]:
    r"""Constant maps that turn Eq. (27)'s trigonometry into one matmul each (float64).

    With ``b_a = (1, cos a, sin a)`` for each Euler angle:

    * ``R = Rz(psi) Ry(theta) Rx(phi)`` is trilinear in ``(b_psi, b_theta, b_phi)``, so
      ``vec(R) = (b_psi (x) b_theta (x) b_phi) @ T_R`` with ``T_R`` (27, 9);
    * ``cos(theta) W(Theta) omega`` is trilinear in ``(b_phi, b_theta, omega)``:
      ``[[ct, sf st, cf st], [0, cf ct, -sf ct], [0, sf, cf]] omega``, so
      ``Theta' = ((b_phi (x) b_theta (x) omega) @ T_W) / cos(theta)`` with ``T_W`` (27, 3).

    A handful of batched ops instead of dozens of scalar products: the
    quadrotor right-hand side is bound by per-op overhead at MPC batch sizes.
    """
    T_x, T_y, T_z = _elementary_rotations()
    T_R = torch.einsum("ija,jkb,klc->abcil", T_z, T_y, T_x).reshape(27, 9)
    T_W = torch.zeros(3, 3, 3, 3, dtype=torch.float64)  # [b_phi, b_theta, omega, row]
    one, cos, sin = 0, 1, 2
    T_W[one, cos, 0, 0] = 1.0  # ct w1
    T_W[sin, sin, 1, 0] = 1.0  # sf st w2
    T_W[cos, sin, 2, 0] = 1.0  # cf st w3
    T_W[cos, cos, 1, 1] = 1.0  # cf ct w2
    T_W[sin, cos, 2, 1] = -1.0  # -sf ct w3
    T_W[sin, one, 1, 2] = 1.0  # sf w2
    T_W[cos, one, 2, 2] = 1.0  # cf w3
    return T_R, T_W.reshape(27, 3)


T_R, T_W = _trilinear_maps()


def trig_basis(Theta: Tensor) -> Tensor:
    """``(..., 3 angles, 3)``: row ``a`` is ``(1, cos a, sin a)`` for ``a = phi, theta, psi``."""
    c = torch.cos(Theta)
    return torch.stack([torch.ones_like(c), c, torch.sin(Theta)], dim=-1)


def outer3(a: Tensor, b: Tensor, c: Tensor) -> Tensor:
    """``a (x) b (x) c`` flattened: (..., 3) x3 -> (..., 27), index ``9 i + 3 j + k``."""
    return ((a.unsqueeze(-1) * b.unsqueeze(-2)).unsqueeze(-1) * c.unsqueeze(-2).unsqueeze(-2)).flatten(-3)


def rotation_from_basis(b_psi: Tensor, b_theta: Tensor, b_phi: Tensor, T_R: Tensor) -> Tensor:
    """``R`` (..., 3, 3) from the (1, cos, sin) bases of psi, theta, phi (see :func:`_trilinear_maps`)."""
    return (outer3(b_psi, b_theta, b_phi) @ T_R).unflatten(-1, (3, 3))


def rotation_matrix(Theta: Tensor, *, check: bool = True) -> Tensor:
    """Body-to-world rotation ``R = Rz(psi) Ry(theta) Rx(phi)`` (Euler ZYX), i.e. ::

        [[cp ct, cp st sf - sp cf, cp st cf + sp sf],
         [sp ct, sp st sf + cp cf, sp st cf - cp sf],
         [-st,   ct sf,            ct cf           ]]

    (``c``/``s`` cos/sin, ``f`` phi, ``t`` theta, ``p`` psi), by the trilinear map of :func:`_trilinear_maps`.

    Parameters
    ----------
    Theta : Tensor, shape (..., 3)
        Euler angles ``(phi roll, theta pitch, psi yaw)`` in rad.
    check : bool, keyword-only
        Validate ``Theta`` (float, finite, last dim 3); ``False`` inside code that checked already.

    Returns
    -------
    Tensor, shape (..., 3, 3)
    """
    if check:
        check_last(Theta, 3, "Theta")
    basis = trig_basis(Theta)
    return rotation_from_basis(basis[..., 2, :], basis[..., 1, :], basis[..., 0, :],
                               T_R.to(dtype=Theta.dtype, device=Theta.device))


def _roll_pitch_terms(Theta: Tensor, check: bool) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor]:
    """``cos(phi), sin(phi), cos(theta), theta`` and zeros/ones like ``phi``, the entries ``W`` and ``W^{-1}`` share."""
    if check:
        check_last(Theta, 3, "Theta")
    phi, theta = Theta[..., 0], Theta[..., 1]
    return torch.cos(phi), torch.sin(phi), torch.cos(theta), theta, torch.zeros_like(phi), torch.ones_like(phi)


def euler_rate_matrix(Theta: Tensor, *, check: bool = True) -> Tensor:
    """``W(Theta)`` of Eq. (27): ``Theta' = W(Theta) omega`` for ZYX Euler angles and body rates.

    Parameters
    ----------
    Theta : Tensor, shape (..., 3)
    check : bool, keyword-only
        Validate ``Theta`` first.

    Returns
    -------
    Tensor, shape (..., 3, 3)
        ``[[1, sin(phi) tan(theta), cos(phi) tan(theta)], [0, cos(phi), -sin(phi)],
        [0, sin(phi)/cos(theta), cos(phi)/cos(theta)]]``; singular at
        ``|theta| = pi/2`` (gimbal lock).
    """
    cf, sf, ct, theta, zero, one = _roll_pitch_terms(Theta, check)
    tt = torch.tan(theta)
    return _mat3([one, sf * tt, cf * tt, zero, cf, -sf, zero, sf / ct, cf / ct])


def matvec(M: Tensor, v: Tensor) -> Tensor:
    """Batched ``M v`` for ``M`` (..., k, n) and ``v`` (..., n), leading dims broadcast; returns (..., k)."""
    return (M @ v.unsqueeze(-1)).squeeze(-1)


def rmatvec(M: Tensor, v: Tensor) -> Tensor:
    """Batched ``M^T v`` for ``M`` (..., n, k) and ``v`` (..., n); returns (..., k)."""
    return (v.unsqueeze(-2) @ M).squeeze(-2)


def inverse_euler_rate_matrix(Theta: Tensor, *, check: bool = True) -> Tensor:
    """``W(Theta)^{-1}`` (..., 3, 3): body rates from Euler-angle rates, ``omega = W^{-1} Theta'``.

    ``[[1, 0, -sin(theta)], [0, cos(phi), sin(phi) cos(theta)], [0, -sin(phi), cos(phi) cos(theta)]]``,
    defined everywhere, unlike ``W``; ``Theta`` (..., 3) and ``check`` as in :func:`euler_rate_matrix`.
    """
    cf, sf, ct, theta, zero, one = _roll_pitch_terms(Theta, check)
    st = torch.sin(theta)
    return _mat3([one, zero, -st, zero, cf, sf * ct, zero, -sf, cf * ct])


def euler_from_rotation(R: Tensor) -> Tensor:
    """ZYX Euler angles of a rotation matrix, the inverse of :func:`rotation_matrix` for ``|theta| < pi/2``.

    Parameters
    ----------
    R : Tensor, shape (..., 3, 3)

    Returns
    -------
    Tensor, shape (..., 3)
        ``(phi, theta, psi)`` with ``phi, psi`` in ``(-pi, pi]``, ``theta`` in ``[-pi/2, pi/2]``.
    """
    if not isinstance(R, Tensor) or R.ndim < 2 or R.shape[-2:] != (3, 3):
        raise ValueError(f"R must be a tensor of shape (..., 3, 3), got {getattr(R, 'shape', type(R).__name__)}")
    check_finite(R, name="R")
    phi = torch.atan2(R[..., 2, 1], R[..., 2, 2])
    theta = torch.asin(torch.clamp(-R[..., 2, 0], -1.0, 1.0))
    psi = torch.atan2(R[..., 1, 0], R[..., 0, 0])
    return torch.stack([phi, theta, psi], dim=-1)

