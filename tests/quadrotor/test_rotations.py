"""Rotations of Eq. (27): R = Rz Ry Rx (Euler ZYX), the Euler-rate map W and its inverse, the trilinear map."""

from __future__ import annotations

import math

import pytest
import torch

from fnnlib.quadrotor.rotations import (
    euler_from_rotation,
    euler_rate_matrix,
    inverse_euler_rate_matrix,
    matvec,
    rmatvec,
    rotation_matrix,
)

F64 = torch.float64


def _hat(w: torch.Tensor) -> torch.Tensor:
    wx, wy, wz = w.tolist()
    return torch.tensor([[0.0, -wz, wy], [wz, 0.0, -wx], [-wy, wx, 0.0]], dtype=F64)


# --------------------------------------------------------------------------- parameters


def test_rotation_matrix_is_a_proper_rotation() -> None:
    Theta = torch.randn(50, 3, generator=torch.Generator().manual_seed(7), dtype=F64) * 1.2
    R = rotation_matrix(Theta)
    eye = torch.eye(3, dtype=F64).expand(50, 3, 3)
    assert torch.allclose(R.transpose(-1, -2) @ R, eye, atol=1e-13)
    assert torch.allclose(torch.linalg.det(R), torch.ones(50, dtype=F64), atol=1e-13)


def test_rotation_matrix_known_cases() -> None:
    e1 = torch.tensor([1.0, 0.0, 0.0], dtype=F64)
    yaw90 = rotation_matrix(torch.tensor([0.0, 0.0, math.pi / 2], dtype=F64))
    assert torch.allclose(yaw90 @ e1, torch.tensor([0.0, 1.0, 0.0], dtype=F64), atol=1e-15)  # nose east
    pitch = rotation_matrix(torch.tensor([0.0, 0.3, 0.0], dtype=F64))
    assert float((pitch @ e1)[2]) < 0  # positive pitch lifts the nose (z down)
    # ZYX order: R = Rz Ry Rx
    phi, theta, psi = 0.3, -0.5, 1.1
    c, s = math.cos, math.sin
    Rx = torch.tensor([[1, 0, 0], [0, c(phi), -s(phi)], [0, s(phi), c(phi)]], dtype=F64)
    Ry = torch.tensor([[c(theta), 0, s(theta)], [0, 1, 0], [-s(theta), 0, c(theta)]], dtype=F64)
    Rz = torch.tensor([[c(psi), -s(psi), 0], [s(psi), c(psi), 0], [0, 0, 1]], dtype=F64)
    R = rotation_matrix(torch.tensor([phi, theta, psi], dtype=F64))
    assert torch.allclose(R, Rz @ Ry @ Rx, atol=1e-15)
    assert torch.allclose(euler_from_rotation(R), torch.tensor([phi, theta, psi], dtype=F64), atol=1e-14)


def test_euler_rate_matrix_matches_finite_differences_along_a_rotation() -> None:
    Theta0 = torch.tensor([0.4, -0.3, 0.7], dtype=F64)
    omega = torch.tensor([1.2, -0.7, 0.5], dtype=F64)
    R0 = rotation_matrix(Theta0)
    h = 1e-5

    def Theta(t: float) -> torch.Tensor:  # body rates omega held: R(t) = R0 exp(t [omega]x)
        return euler_from_rotation(R0 @ torch.linalg.matrix_exp(t * _hat(omega)))

    fd = (Theta(h) - Theta(-h)) / (2 * h)
    # central difference: error ~ h^2 |Theta'''| / 6 ~ 1e-10
    assert torch.allclose(euler_rate_matrix(Theta0) @ omega, fd, atol=1e-8)
    assert torch.allclose(
        inverse_euler_rate_matrix(Theta0) @ euler_rate_matrix(Theta0), torch.eye(3, dtype=F64), atol=1e-14
    )


def test_trilinear_rotation_equals_the_explicit_zyx_product():
    """R from the (1, cos, sin) basis map equals Rz(psi) Ry(theta) Rx(phi) multiplied out by hand."""
    torch.manual_seed(3)
    Theta = (torch.rand(50, 3, dtype=torch.float64) - 0.5) * 6.0
    phi, theta, psi = Theta.unbind(-1)
    c, s = torch.cos, torch.sin
    zero, one = torch.zeros_like(phi), torch.ones_like(phi)
    Rx = torch.stack([one, zero, zero, zero, c(phi), -s(phi), zero, s(phi), c(phi)], -1).reshape(-1, 3, 3)
    Ry = torch.stack([c(theta), zero, s(theta), zero, one, zero, -s(theta), zero, c(theta)], -1).reshape(-1, 3, 3)
    Rz = torch.stack([c(psi), -s(psi), zero, s(psi), c(psi), zero, zero, zero, one], -1).reshape(-1, 3, 3)
    torch.testing.assert_close(rotation_matrix(Theta), Rz @ Ry @ Rx, rtol=0, atol=1e-14)


def test_unchecked_forms_are_the_same_numbers_and_checked_forms_refuse_bad_angles():
    Theta = torch.randn(20, 3, generator=torch.Generator().manual_seed(1), dtype=F64)
    for fn in (rotation_matrix, euler_rate_matrix, inverse_euler_rate_matrix):
        assert torch.equal(fn(Theta), fn(Theta, check=False))
        with pytest.raises(ValueError, match=r"Theta must have shape \(\.\.\., 3\)"):
            fn(Theta[:, :2])
        with pytest.raises(ValueError, match="NaN"):
            fn(torch.tensor([0.0, math.nan, 0.0], dtype=F64))
    with pytest.raises(TypeError, match="floating-point"):
        rotation_matrix(torch.zeros(3, dtype=torch.long))


def test_matvec_and_rmatvec_are_batched_products():
    g = torch.Generator().manual_seed(2)
    M, v = torch.randn(5, 3, 4, generator=g, dtype=F64), torch.randn(5, 4, generator=g, dtype=F64)
    w = torch.randn(5, 3, generator=g, dtype=F64)
    torch.testing.assert_close(matvec(M, v), torch.einsum("bij,bj->bi", M, v), rtol=1e-15, atol=1e-15)
    torch.testing.assert_close(rmatvec(M, w), torch.einsum("bij,bi->bj", M, w), rtol=1e-15, atol=1e-15)
