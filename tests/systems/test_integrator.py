"""The RK4 integrator of the Sec. 5 code, on a problem with an exact solution, and its step checks."""

from __future__ import annotations

import math

import pytest
import torch

from fnnlib.systems.integrator import check_step, rk4

F64 = torch.float64


def test_rk4_is_fourth_order_on_a_rotation():
    """y' = A y with A a rotation generator: y(t) = exp(t A) y0 exactly; the error falls as h^4."""
    A = torch.tensor([[0.0, -2.0], [2.0, 0.0]], dtype=F64)
    y0 = torch.tensor([[1.0, 0.5]], dtype=F64)
    exact = y0 @ torch.linalg.matrix_exp(1.0 * A).T
    errs = [float((rk4(lambda y: y @ A.T, y0, 1.0, n) - exact).abs().max()) for n in (8, 16, 32)]
    for coarse, fine in zip(errs, errs[1:]):
        assert 14.0 < coarse / fine < 18.0  # 2^4 = 16


def test_a_given_first_stage_is_used_once():
    f = lambda y: -y  # noqa: E731
    y = torch.ones(3, dtype=F64)
    torch.testing.assert_close(rk4(f, y, 0.1, 2, k1=f(y)), rk4(f, y, 0.1, 2), rtol=0, atol=0)
    assert not torch.equal(rk4(f, y, 0.1, 1, k1=torch.zeros(3, dtype=F64)), rk4(f, y, 0.1, 1))
    torch.testing.assert_close(rk4(f, y, 0.1, 1), y * (1 - 0.1 + 0.1**2 / 2 - 0.1**3 / 6 + 0.1**4 / 24), rtol=1e-15,
                               atol=0)  # one RK4 step of y' = -y is the Taylor polynomial of e^{-h} to order 4


def test_check_step_refuses_bad_steps():
    assert check_step(0.02, 3) == (0.02, 3)
    bad = ((0.0, 1, ValueError, "Ts"), (math.inf, 1, ValueError, "Ts"), ("0.02", 1, TypeError, "Ts"),
           (True, 1, TypeError, "Ts"), (0.02, 0, ValueError, "substeps"), (0.02, 1.5, TypeError, "substeps"))
    for Ts, substeps, err, match in bad:
        with pytest.raises(err, match=match):
            check_step(Ts, substeps)  # type: ignore[arg-type]
