"""A flight records its MPC fallbacks (reasons, reference steps) and is marked diverged past the share."""

from __future__ import annotations

import numpy as np
import pytest

from fnnlib.quadrotor.mpc import OSQPMPC
from fnnlib.quadrotor.mpc.backends import Backend
from fnnlib.quadrotor.mpc.flight import FlightTest, fly, lissajous_reference
from fnnlib.quadrotor.mpc.linearized import DIVERGED_FALLBACK_SHARE
from fnnlib.quadrotor.mpc.models import PredictionModel
from fnnlib.quadrotor.presets import PAPER_LISSAJOUS, PAPER_MPC_WEIGHTS, PAPER_TS
from fnnlib.quadrotor.system import NOMINAL, Quadrotor

N, STEPS = 10, 20


def _mpc() -> OSQPMPC:
    Q, R = np.array(PAPER_MPC_WEIGHTS["Q"]), np.array(PAPER_MPC_WEIGHTS["R"])
    return OSQPMPC(N, Q, R, cost="as_flown", u_lb=np.zeros(4), u_ub=np.full(4, 6.0))


@pytest.mark.parametrize("n_bad", [0, 2, 14])
def test_flight_counts_fallbacks_by_reason_and_marks_divergence(n_bad: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The QP refuses the data (as with a runaway model) at the last ``n_bad`` steps."""
    x_r, u_r = lissajous_reference(STEPS, N, Ts=PAPER_TS, params=NOMINAL, curve=PAPER_LISSAJOUS)
    mpc = _mpc()
    real = mpc.solve
    calls = []

    def solve(x0, A, B, c, xr, ur):
        calls.append(1)
        if len(calls) > STEPS - n_bad:
            c = np.array(c)
            c[0, 0] = 1e31  # beyond OSQP's infinity: the guard's fallback
        return real(x0, A, B, c, xr, ur)

    monkeypatch.setattr(mpc, "solve", solve)
    test = FlightTest(Quadrotor(NOMINAL), x_r, u_r, steps=STEPS, Ts=PAPER_TS, substeps=1,
                      backend=Backend("torch", "central"))
    res = fly(PredictionModel("Nomi", Quadrotor(NOMINAL), Ts=PAPER_TS), mpc, test)
    assert res.n_fallbacks == n_bad
    assert res.fallback_reasons == ({"data_too_large": n_bad} if n_bad else {})
    assert res.n_reference_fallbacks == max(0, n_bad - (N - 1))  # the plan covers N - 1 fallback steps
    assert res.fallback_share == pytest.approx(n_bad / STEPS)
    assert res.diverged == (n_bad / STEPS > DIVERGED_FALLBACK_SHARE)
    assert np.isfinite(res.x).all()
    assert (res.u >= 0).all() and (res.u <= 6.0).all()
