"""Rules of O1-O2 (and B3 in tests/pipeline/test_scoreboard.py): numbers that must pass and must fail."""

from __future__ import annotations

import numpy as np
import pytest

from fnnbook.rules import bottle
from fnnbook.results import ClaimResult

RNG = np.random.default_rng(0)
DRAG = np.full(9, 0.10)


def verdict(claim_id: str, rule: ClaimResult) -> str:
    assert rule.id == claim_id
    return rule.verdict


def test_o1_single_seed_per_throw() -> None:
    r = bottle.o1(feedback=np.full(9, 0.03) + 0.001 * np.arange(9), neural_ode=np.full(9, 0.05), drag=DRAG)
    assert verdict("O1", r) == "reproduced" and set(r.checks) == {"feedback<neural_ode per throw",
                                                                     "neural_ode<drag per throw"}
    # the case: a 2 mm mean gap, feedback ahead on 5 of 9 throws -- not a win
    nn = np.array([0.040, 0.050, 0.045, 0.060, 0.030, 0.055, 0.042, 0.048, 0.057])
    fb = nn + np.array([-0.010, -0.008, -0.006, -0.007, -0.005, 0.004, 0.003, 0.005, 0.006])
    r = bottle.o1(feedback=fb, neural_ode=nn, drag=DRAG)
    assert fb.mean() < nn.mean() and r.checks["feedback<neural_ode per throw"] is False
    assert verdict("O1", r) == "partly"
    assert verdict("O1", bottle.o1(feedback=DRAG * 2, neural_ode=DRAG * 1.5, drag=DRAG)) == "not reproduced"


def test_o1_over_seeds() -> None:
    nn = 0.05 + 0.005 * RNG.standard_normal((9, 5))
    r = bottle.o1(feedback=nn - 0.01, neural_ode=nn, drag=DRAG)
    assert verdict("O1", r) == "reproduced" and len(r.checks) == 4 and "5 seeds" in r.rule
    # feedback ahead on every throw on average, but only thanks to one seed
    fb = nn.copy()
    fb[:, 0] -= 0.05
    fb[:, 1:] += 0.001
    r = bottle.o1(feedback=fb, neural_ode=nn, drag=DRAG)
    assert r.checks["feedback<neural_ode per throw"] is True
    assert r.checks["feedback<neural_ode over seeds"] is False and verdict("O1", r) == "partly"
    with pytest.raises(ValueError, match="pair throw by throw"):
        bottle.o1(feedback=nn, neural_ode=nn[:8], drag=DRAG)


def test_o2() -> None:
    throws = [0.03] * 9
    ok = dict(acc_rmse_feedback=0.5, acc_rmse_neural_ode=1.0, error_feedback=0.03, travel=1.0,
              error_per_throw=throws)
    assert verdict("O2", bottle.o2(**ok)) == "reproduced"
    # one throw of 9 off (0.15 of the travel) fails the overlap, though the mean over throws (0.043) passes it:
    # the check reads every throw of Fig. S2, so a plausible run with one hard throw fails it
    one_off = bottle.o2(**ok | {"error_per_throw": [0.03] * 8 + [0.15], "acc_rmse_feedback": [0.5] * 5,
                                "acc_rmse_neural_ode": [1.0] * 5, "error_feedback": [0.043] * 5})
    assert verdict("O2", one_off) == "partly" and one_off.numbers["worst_throw_error_over_travel"] == 0.15
    assert verdict("O2", bottle.o2(acc_rmse_feedback=1.5, acc_rmse_neural_ode=1.0, error_feedback=0.3,
                                   travel=1.0, error_per_throw=[0.3] * 9)) == "not reproduced"
    with pytest.raises(ValueError, match="error_per_throw"):
        bottle.o2(**ok | {"error_per_throw": None})


def test_o1_means_is_o1_on_the_marginals() -> None:
    """O1 from the stored marginals (per-throw means over seeds, per-seed means over throws) is O1 itself."""
    nn = 0.05 + 0.01 * RNG.random((9, 5))
    for fb in (nn - 0.004 + 0.002 * RNG.random((9, 5)), nn + 0.001 * RNG.standard_normal((9, 5))):
        full = bottle.o1(feedback=fb, neural_ode=nn, drag=DRAG)
        means = bottle.o1_means(per_throw={"feedback": fb.mean(1), "neural_ode": nn.mean(1), "drag": DRAG},
                                per_seed={"feedback": fb.mean(0), "neural_ode": nn.mean(0)})
        assert means.checks == full.checks and means.rule == full.rule


def test_o1_means_refuses_bad_marginals() -> None:
    with pytest.raises(ValueError, match="per_seed"):
        bottle.o1_means(per_throw={"feedback": DRAG, "neural_ode": DRAG, "drag": DRAG},
                        per_seed={"feedback": [0.1, 0.2], "neural_ode": [0.1]})
    with pytest.raises(ValueError, match="drag"):
        bottle.o1_means(per_throw={"feedback": DRAG, "neural_ode": DRAG}, per_seed={"feedback": [0.1],
                                                                                   "neural_ode": [0.1]})


def test_o1_per_seed_is_o1_on_the_seed_rows() -> None:
    rng = np.random.default_rng(0)
    fb, nn = 0.1 + 0.01 * rng.random((3, 9)), 0.2 + 0.01 * rng.random((3, 9))  # (seeds, throws)
    drag = 0.3 + 0.01 * rng.random(9)
    a = bottle.o1_per_seed(feedback=fb, neural_ode=nn, drag=drag)
    b = bottle.o1(feedback=fb.T, neural_ode=nn.T, drag=drag)
    assert a.checks == b.checks and a.verdict == b.verdict == "reproduced"
    assert not bottle.o1_per_seed(feedback=nn, neural_ode=fb, drag=drag).checks["feedback<neural_ode per throw"]
