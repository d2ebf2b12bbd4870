"""Missing samples and partial measurements: through a gap the estimate is the model's Euler rollout, no NaN
reaches an estimate, multi-rate masks, and the cascade with C against the truth of a linear plant."""

from __future__ import annotations

import pytest
import torch

import fnnlib as F
from fnnlib.feedback import cascade_sweep, Gains
from fnnlib.systems import LinearSystem
from fnnlib.feedback.measurement import model_jacobian

from tests.feedback.test_inputs import A, B, F64, TS
from tests.feedback.test_inputs import _euler_data as _euler

C = torch.tensor([[1.0, 0.0]], dtype=F64)
T = 120
PLANT = LinearSystem(A, B)


def _data():
    u = torch.sin(0.9 * torch.arange(T, dtype=F64) * TS)[:, None]
    return _euler(torch.tensor([1.0, -2.0], dtype=F64), u), u


def _euler_from(x0, u, steps):
    xs = [x0]
    for k in range(steps):
        xs.append(xs[-1] + TS * (A @ xs[-1] + B @ u[k]))
    return torch.stack(xs)


def _gain():
    return F.place_observer_gain(torch.eye(2, dtype=F64) + TS * A, TS * C, [0.6, 0.7])


def test_model_jacobian_is_A_in_one_batched_call():
    J = model_jacobian(PLANT, torch.randn(4, 3, 2, dtype=F64), torch.zeros(4, 3, 1, dtype=F64))
    assert J.shape == (4, 3, 2, 2)
    torch.testing.assert_close(J, A.expand(4, 3, 2, 2))


@pytest.mark.parametrize("how", ["nan", "mask"])
def test_estimate_through_a_gap_is_the_euler_rollout_and_corrects_after(how):
    x, u = _data()
    y = x @ C.T + 0.3  # a biased sensor: the estimate differs from the truth, so the gap is visible
    gap = slice(40, 60)
    obs = F.MeasuredFeedback(PLANT, TS, L=_gain(), measurement=F.Measurement(C=C), A=A)
    if how == "nan":
        y_gap, mask = y.clone(), None
        y_gap[gap] = float("nan")
    else:
        y_gap, mask = y, torch.ones(T, dtype=torch.bool)
        mask[gap] = False
    full = obs.observe(y, u).x_hat
    est = obs.observe(y_gap, u, mask=mask).x_hat
    assert bool(torch.isfinite(est).all())
    torch.testing.assert_close(est[:41], full[:41], rtol=0, atol=0)  # identical up to the first missing sample
    torch.testing.assert_close(est[40:61], _euler_from(est[40], u[40:], 20), rtol=0, atol=1e-12)  # open loop
    assert float((est[110:] - full[110:]).abs().max()) < 1e-3 * float((est[60] - full[60]).abs().max())


def test_cascade_through_a_gap_full_state_equals_the_paper_cascade_outside_it():
    x, u = _data()
    x_gap = x.clone()
    x_gap[50:55] = float("nan")
    z = F.cascade_predict(PLANT, x_gap, TS, 4, F.Gains(3.0, 0.1), u=u)
    ref = F.cascade_predict(PLANT, x, TS, 4, F.Gains(3.0, 0.1), u=u)
    assert bool(torch.isfinite(z).all())
    torch.testing.assert_close(z[:50], ref[:50], rtol=0, atol=1e-12)  # the gap loop is the scan's recursion
    torch.testing.assert_close(z[90:], ref[90:], rtol=0, atol=1e-9)  # exact data: the model is right, so are both
    sweep = cascade_sweep(PLANT, x_gap, TS, 4, Gains.sweep(torch.tensor([1.0, 3.0]), 0.1), u=u)
    torch.testing.assert_close(sweep[1], z, rtol=0, atol=1e-12)


def test_cascade_with_C_predicts_a_partially_measured_plant():
    x, u = _data()
    y = x @ C.T
    y[30:45] = float("nan")
    obs = F.MeasuredFeedback(PLANT, TS, L=_gain(), measurement=F.Measurement(C=C), A=A)
    z = F.cascade_predict(PLANT, y, TS, 5, F.Gains(3.0, 0.05), u=u, observer=obs)
    assert z.shape == (T, 2) and bool(torch.isfinite(z).all())
    torch.testing.assert_close(z[100:-5], x[105:], rtol=0, atol=1e-6)


def test_multi_rate_mask_per_output():
    x, u = _data()
    C2 = torch.eye(2, dtype=F64)
    mask = torch.ones(T, 2, dtype=torch.bool)
    mask[1::2, 1] = False  # the velocity sensor at half the rate
    L = torch.tensor([[8.0, 0.0], [0.0, 8.0]], dtype=F64)
    obs = F.MeasuredFeedback(PLANT, TS, L=L, measurement=F.Measurement(C=C2, x0=torch.zeros(2, dtype=F64)), A=A)
    est = obs.observe(x + 0.1, u, mask=mask)
    assert bool(torch.isfinite(est.x_hat).all())
    with pytest.raises(ValueError, match=r"mask of shape \(120, 3\) fits neither"):
        obs.observe(x, u, mask=torch.ones(T, 3, dtype=torch.bool))
    with pytest.raises(TypeError, match="mask must be a boolean tensor"):
        obs.observe(x, u, mask=torch.ones(T))


def test_tune_gains_through_gaps_and_with_a_recipe_and_an_objective():
    x, u = _data()
    y = x + 0.01 * torch.randn(T, 2, generator=torch.Generator().manual_seed(0), dtype=F64)
    recipe = F.TuneRecipe(L0=2.0, beta0=0.1, iterations=3, lr=0.1)
    a = F.tune_gains(PLANT, y, TS, 5, u=u, recipe=recipe)
    b = F.tune_gains(PLANT, y, TS, 5, F.TuneRecipe(L0=2, beta0=0.1, iterations=3, lr=0.1), u=u)
    assert a.loss == b.loss and torch.equal(a.L, b.L)  # an integer L0 is the float, bit for bit
    assert isinstance(a.L, torch.Tensor) and a.L.dtype == F64 and torch.equal(a.schedule().L, a.L) and a.schedule().beta == a.beta
    y_gap = y.clone()
    y_gap[20:30] = float("nan")
    g = F.tune_gains(PLANT, y_gap, TS, 5, u=u, recipe=recipe)
    assert all(torch.isfinite(torch.tensor(g.loss)))
    calls = []

    def objective(gains, x_, u_, mask_):
        calls.append(mask_ is None)
        return (gains.L() - 7.0).pow(2).sum() + gains.beta()

    o = F.tune_gains(PLANT, y, TS, 5, u=u,
                     recipe=F.TuneRecipe(L0=2.0, beta0=0.1, iterations=40, lr=0.1, objective=objective))
    assert len(calls) == 40 and o.L[0] > 2.5  # the closed-loop cost is what was descended
    with pytest.raises(TypeError, match="unexpected keyword argument 'lr'"):  # the recipe holds every setting
        F.tune_gains(PLANT, y, TS, 5, u=u, recipe=recipe, lr=0.2)
    with pytest.raises(TypeError, match="recipe must be a TuneRecipe"):
        F.tune_gains(PLANT, y, TS, 5, {"lr": 0.2}, u=u)
    with pytest.raises(TypeError, match="TuneRecipe.objective must be a callable"):
        F.TuneRecipe(objective=3.0)
    with pytest.raises(ValueError, match="TuneRecipe.iterations must be an integer >= 1"):
        F.TuneRecipe(iterations=0)
    with pytest.raises(ValueError, match="TuneRecipe.L0 must be > 0"):
        F.TuneRecipe(L0=-1.0)
    d = F.tune_gains(PLANT, y[:40], TS, 5, u=u[:40])  # no recipe: the default one
    assert len(d.loss) == F.TuneRecipe().iterations


def test_tune_gains_with_an_observer_tunes_the_layers_after_it_and_checks_its_gain():
    x, u = _data()
    y = x @ C.T + 0.01 * torch.randn(T, 1, generator=torch.Generator().manual_seed(2), dtype=F64)
    y[10:20] = float("nan")
    obs = F.MeasuredFeedback(PLANT, TS, L=_gain(), measurement=F.Measurement(C=C), A=A)
    tuned = F.tune_gains(PLANT, y, TS, 4, recipe=F.TuneRecipe(L0=2.0, beta0=0.05, iterations=3, lr=0.1), u=u,
                         observer=obs)
    assert tuned.L.shape == (2,) and tuned.loss[-1] < tuned.loss[0] and tuned.observer is obs
    both = F.tune_gains(PLANT, y, TS, 4,
                        recipe=F.TuneRecipe(L0=2.0, beta0=0.05, iterations=3, lr=0.1, tune_observer=True), u=u,
                        observer=obs)
    assert both.observer is not obs and both.observer.L.shape == (2, 1) and both.loss[-1] < both.loss[0]
    assert not torch.equal(both.observer.L, obs.L)
    with pytest.raises(ValueError, match="tune_observer=True needs an observer"):
        F.tune_gains(PLANT, x, TS, 4,
                     recipe=F.TuneRecipe(L0=2.0, beta0=0.05, iterations=1, lr=0.1, tune_observer=True), u=u)
    with pytest.raises(F.GainError, match="not detectable"):  # a Jacobian whose mode the position does not see
        F.MeasuredFeedback(PLANT, TS, L=_gain(), measurement=F.Measurement(C=C),
                           A=torch.tensor([[0.0, 0.0], [0.0, 1.0]], dtype=F64))


def test_cascade_sweep_with_an_observer_sweeps_the_layers_after_it():
    x, u = _data()
    y = x @ C.T
    y[30:45] = float("nan")
    obs = F.MeasuredFeedback(PLANT, TS, L=_gain(), measurement=F.Measurement(C=C), A=A)
    sweep = cascade_sweep(PLANT, y, TS, 5, Gains.sweep(torch.tensor([1.0, 3.0]), [0.05, 0.2]), u=u, observer=obs)
    assert sweep.shape == (2, T, 2)
    for g, (L, beta) in enumerate([(1.0, 0.05), (3.0, 0.2)]):
        torch.testing.assert_close(sweep[g], F.cascade_predict(PLANT, y, TS, 5, F.Gains(L, beta), u=u, observer=obs),
                                   rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="do not pair up"):
        cascade_sweep(PLANT, y, TS, 5, Gains.sweep(torch.tensor([1.0, 2.0, 3.0]), [0.05, 0.2]), u=u, observer=obs)
    with pytest.raises(TypeError, match="observer must be a fnnlib.MeasuredFeedback"):
        cascade_sweep(PLANT, y, TS, 5, Gains.sweep(1.0, 0.1), u=u, observer="C")
