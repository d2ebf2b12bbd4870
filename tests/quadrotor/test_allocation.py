"""The motor allocation of Eq. (27): C maps the four thrusts to [T, tau] for the quad-X layout."""

from __future__ import annotations

import math

import torch

from fnnlib.quadrotor.allocation import allocation_inverse, allocation_matrix
from fnnlib.quadrotor.system import NOMINAL

F64 = torch.float64


def test_allocation_inverse_is_exact() -> None:
    for params in (NOMINAL, NOMINAL.replace(arm=0.2, torque_coeff=0.02)):
        C, C_inv = allocation_matrix(params), allocation_inverse(params)
        assert torch.allclose(C @ C_inv, torch.eye(4, dtype=F64), atol=1e-12)
        assert torch.allclose(C_inv @ C, torch.eye(4, dtype=F64), atol=1e-12)


def test_allocation_torques_follow_the_motor_positions() -> None:
    d = 0.15 / math.sqrt(2.0)
    C = allocation_matrix(NOMINAL)
    # raising the two motors with a '+' in tau_x (2 rear-left, 3 front-left) rolls right (+tau_x, FRD)
    du = torch.tensor([0.0, 1.0, 1.0, 0.0], dtype=F64)
    assert float((C @ du)[1]) > 0
    # each motor at r_i (FRD) pushes -u_i e3: its torque is r_i x (-u_i e3)
    r = torch.tensor([[d, d, 0.0], [-d, -d, 0.0], [d, -d, 0.0], [-d, d, 0.0]], dtype=F64)
    e3 = torch.tensor([0.0, 0.0, 1.0], dtype=F64)
    for i in range(4):
        assert torch.allclose(C[1:3, i], torch.linalg.cross(r[i], -e3)[:2], atol=1e-15)
    assert torch.allclose(C[3], torch.tensor([0.01, 0.01, -0.01, -0.01], dtype=F64))
