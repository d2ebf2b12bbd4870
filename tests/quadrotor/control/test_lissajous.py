"""The Lissajous test reference of Sec. 5.2 / App. A.5.5: the paper's formula and its analytic derivatives."""

from __future__ import annotations

import numpy as np
import pytest

from fnnlib.quadrotor.control.lissajous import lissajous, lissajous_flat_outputs
from fnnlib.quadrotor.presets import PAPER_LISSAJOUS


def curve(**changes: float) -> dict[str, float]:
    """The paper's curve with some parameters changed."""
    return {**PAPER_LISSAJOUS, **changes}


def test_lissajous_matches_the_paper_formula() -> None:
    t = np.linspace(0.0, 6.0, 31)
    d = lissajous(t, **PAPER_LISSAJOUS)
    expected = np.stack([3.0 * np.sin(2 * np.pi * t / 6), 3.0 * np.sin(2 * np.pi * t / 3), 0.5 + 0.5 * np.cos(2 * np.pi * t / 3)], 1)
    np.testing.assert_allclose(d.p, expected, atol=1e-14)
    np.testing.assert_allclose(lissajous([0.0], **curve(h=-0.5)).p, [[0.0, 0.0, 0.0]], atol=1e-15)
    for x in d:
        assert x.shape == (31, 3) and x.dtype == np.float64
    np.testing.assert_allclose(lissajous([6.0], **PAPER_LISSAJOUS).p, lissajous([0.0], **PAPER_LISSAJOUS).p, atol=1e-12)  # period 6 s


@pytest.mark.parametrize("params", [{}, {"r_x": 1.0, "r_y": -2.0, "r_z": 0.7, "T_x": 4.0, "T_y": 2.5, "T_z": 5.0, "h": -0.5}])
def test_lissajous_derivatives_match_central_differences(params: dict[str, float]) -> None:
    t = np.linspace(0.0, 7.0, 71)
    eps = 1e-4
    d, dp, dm = lissajous(t, **curve(**params)), lissajous(t + eps, **curve(**params)), lissajous(t - eps, **curve(**params))
    for r in range(4):
        fd = (dp[r] - dm[r]) / (2 * eps)  # truncation ~ eps^2 w^3 / 6, round-off ~ 1e-16 / eps
        exact = d[r + 1]
        np.testing.assert_allclose(fd, exact, rtol=0, atol=1e-5 * np.abs(exact).max())


def test_lissajous_flat_outputs_stack_p_v_a_j() -> None:
    psi = lissajous_flat_outputs(1.0, 300, 0.02, **curve(T_x=5.0))
    d = lissajous(1.0 + 0.02 * np.arange(300), **curve(T_x=5.0))
    assert psi.shape == (300, 12)
    np.testing.assert_array_equal(psi, np.concatenate([d.p, d.v, d.a, d.j], axis=1))


def test_lissajous_refuses_bad_input() -> None:
    with pytest.raises(ValueError, match="T_y must be a finite positive"):
        lissajous([0.0], **curve(T_y=0.0))
    with pytest.raises(ValueError, match="NaN"):
        lissajous([0.0, np.nan], **PAPER_LISSAJOUS)
    with pytest.raises(ValueError, match="Ts must be a finite positive"):
        lissajous_flat_outputs(0.0, 10, -0.02, **PAPER_LISSAJOUS)
    with pytest.raises(TypeError, match="r_x"):
        lissajous([0.0])  # type: ignore[call-arg]  # the curve is never a silent default
