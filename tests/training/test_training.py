"""Training on random segments: loss goes down, runs are deterministic, bad settings are refused."""

from __future__ import annotations

import pytest
import torch

from fnnlib import NeuralODE, ODERecipe, train_neural_ode
from fnnlib.seeding import seed_everything
from fnnlib.systems import Spiral
from fnnlib.training import PAPER_SPIRAL_RECIPE
from fnnlib.training import sample_segments

F64 = torch.float64


@pytest.fixture(scope="module")
def data():
    t = torch.arange(41, dtype=F64) * 0.05
    x = Spiral(2.0, 0.1, 0.0).exact_solution(torch.tensor([[2.0, 0.0], [0.0, -1.5]]), t)  # (2, 41, 2)
    return t, x


def _model(seed=0):
    seed_everything(seed)
    return NeuralODE(2, (16,), "tanh").double()


def _train(model, t, x, u=None, **kw):
    settings = dict(iterations=30, batch_size=8, batch_time=5, lr=1e-2, optimizer="adam", loss="l1", method="rk4",
                    adjoint=False, rtol=1e-7, atol=1e-9, adjoint_seminorm=True)
    settings.update(kw)
    seed = settings.pop("seed", 0)
    return train_neural_ode(model, t, x, ODERecipe(**settings), seed=seed, progress=False, u=u)


def _full_loss(model, t, x):
    from torchdiffeq import odeint
    with torch.no_grad():
        pred = odeint(model, x[:, 0], t, method="rk4", options={"step_size": 0.05}).permute(1, 0, 2)
    return float((pred - x).abs().mean())


def test_short_training_lowers_the_loss(data):
    t, x = data
    model = _model()
    before = _full_loss(model, t[:10], x[:, :10])
    hist = _train(model, t, x, iterations=40)
    assert len(hist.loss) == 40
    assert all(torch.isfinite(torch.tensor(hist.loss)))
    assert sum(hist.loss[-5:]) < 0.5 * sum(hist.loss[:5])
    assert _full_loss(model, t[:10], x[:, :10]) < 0.5 * before
    assert hist.seconds > 0 and hist.ms_per_iteration > 0


def test_same_seed_same_losses(data):
    t, x = data
    a = _train(_model(3), t, x, iterations=10, method="euler")
    b = _train(_model(3), t, x, iterations=10, method="euler")
    c = _train(_model(3), t, x, iterations=10, method="euler", seed=1)  # other mini-batches
    assert a.loss == b.loss
    assert a.loss != c.loss


def test_single_trajectory_and_mse(data):
    t, x = data
    hist = _train(_model(), t, x[0], iterations=3, loss="mse", optimizer="rmsprop")
    assert len(hist.loss) == 3


def test_adjoint_dopri5_runs(data):
    t, x = data
    hist = _train(_model(), t, x, iterations=2, method="dopri5", adjoint=True, rtol=1e-5, atol=1e-6)
    assert len(hist.loss) == 2 and all(v == v for v in hist.loss)


@pytest.mark.parametrize("kw, match", [
    (dict(optimizer="sgd"), r"unknown optimizer 'sgd'; choose one of \['adam', 'rmsprop'\]"),
    (dict(loss="huber"), r"unknown loss 'huber'; choose one of \['l1', 'mse'\]"),
    (dict(method="rk45"), r"unknown solver 'rk45'"),
    (dict(batch_size=1000), r"batch_size=1000 exceeds the 74 available segments"),
    (dict(batch_time=1), r"2 <= batch_time <= T"),
    (dict(batch_time=42), r"2 <= batch_time <= T"),
    (dict(iterations=0), r"need iterations >= 1"),
    (dict(lr=0.0), r"lr must be a finite positive number"),
])
def test_bad_settings(data, kw, match):
    t, x = data
    with pytest.raises(ValueError, match=match):
        _train(_model(), t, x, **kw)


def test_non_uniform_time_grid_is_taken_and_a_decreasing_one_refused(data):
    t, x = data
    t_jitter = t.clone()
    t_jitter[5] += 0.01  # uneven times train along their own intervals (tests/training/test_times_training.py)
    assert len(_train(_model(), t_jitter, x).loss) > 0
    with pytest.raises(ValueError, match="t must be strictly increasing"):
        _train(_model(), t.flip(0), x)


def test_time_grid_length_mismatch(data):
    t, x = data
    with pytest.raises(ValueError, match="t has 40 points but x has 41 samples"):
        _train(_model(), t[:-1], x)


def test_nan_data(data):
    t, x = data
    bad = x.clone()
    bad[1, 7, 0] = float("nan")
    with pytest.raises(ValueError, match=r"x holds a NaN value \(first at index \(1, 7, 0\)\)"):
        _train(_model(), t, bad)


def test_bad_data_rank(data):
    t, x = data
    with pytest.raises(ValueError, match=r"x must have shape \(T, n\) or \(n_traj, T, n\)"):
        _train(_model(), t, x[None])


def test_adjoint_needs_a_module(data):
    t, x = data
    model = _model()
    with pytest.raises(TypeError, match="the adjoint method needs model to be an nn.Module"):
        train_neural_ode(lambda t, y: model(t, y), t, x, PAPER_SPIRAL_RECIPE.replace(iterations=1), seed=0,
                         progress=False)


def test_recipe_is_required_and_typed(data):
    t, x = data
    with pytest.raises(TypeError, match="recipe must be an ODERecipe"):
        train_neural_ode(_model(), t, x, dict(iterations=1), seed=0, progress=False)
    with pytest.raises(TypeError):
        train_neural_ode(_model(), t, x, seed=0)  # no silent paper defaults
    with pytest.raises(TypeError):
        ODERecipe(iterations=1)  # every setting is named


# --- sample_segments ---------------------------------------------------------------------------------------------

def test_sample_segments_shapes_and_contiguity():
    n_traj, T, n = 3, 12, 2
    # x[j, k] = (j, k): each sample names its trajectory and time index
    j = torch.arange(n_traj, dtype=F64)[:, None].expand(n_traj, T)
    k = torch.arange(T, dtype=F64)[None, :].expand(n_traj, T)
    x = torch.stack([j, k], dim=-1)
    seg = sample_segments(x, 10, 4, torch.Generator().manual_seed(0))
    assert seg.shape == (4, 10, n)
    for b in range(10):
        traj, times = seg[:, b, 0], seg[:, b, 1]
        assert bool((traj == traj[0]).all())  # one trajectory per segment
        assert torch.equal(times - times[0], torch.arange(4, dtype=F64))  # consecutive samples
        assert 0 <= times[0] <= T - 4
    starts = {(int(seg[0, b, 0]), int(seg[0, b, 1])) for b in range(10)}
    assert len(starts) == 10  # drawn without replacement


def test_sample_segments_reproducible_and_exhaustive():
    x = torch.randn(2, 6, 2, dtype=F64)
    a = sample_segments(x, 5, 3, torch.Generator().manual_seed(4))
    b = sample_segments(x, 5, 3, torch.Generator().manual_seed(4))
    assert torch.equal(a, b)
    every = sample_segments(x, 8, 3, torch.Generator().manual_seed(0))  # 2 * (6 - 3 + 1) = 8: all of them
    assert every.shape == (3, 8, 2)
    with pytest.raises(ValueError, match="batch_size=9 exceeds the 8 available segments"):
        sample_segments(x, 9, 3, torch.Generator().manual_seed(0))


@pytest.mark.parametrize("kw, match", [
    (dict(optimizer="sgd"), "unknown optimizer"), (dict(loss="huber"), "unknown loss"),
    (dict(method="rk45"), "unknown solver"), (dict(iterations=0), "need iterations >= 1"),
    (dict(batch_time=1), r"2 <= batch_time"), (dict(lr=-1.0), "lr must be a finite positive number"),
])
def test_a_recipe_checks_its_fields_when_made(kw, match):
    """No data needed: a bad recipe is refused where it is written, before any training."""
    with pytest.raises(ValueError, match=match):
        PAPER_SPIRAL_RECIPE.replace(**kw)


def _controlled(seed=0):
    seed_everything(seed)
    return NeuralODE(2, (8,), "tanh", n_input=1).double()


def test_a_shared_input_is_broadcast_like_simulate(data):
    """u (T, m) for x (n_traj, T, n) trains exactly as the same u repeated per trajectory."""
    t, x = data
    u = torch.sin(t)[:, None]
    shared = _train(_controlled(), t, x, u=u, iterations=3).loss
    repeated = _train(_controlled(), t, x, u=u.expand(2, -1, -1).clone(), iterations=3).loss
    assert shared == repeated


@pytest.mark.parametrize("shape", [(40, 1), (3, 41, 1), (2, 40, 1), (1, 2, 41, 1)])
def test_a_wrong_input_shape_names_both_shapes(data, shape):
    t, x = data
    with pytest.raises(ValueError, match=(r"u must have shape \(T, m\) = \(41, m\).*\(n_traj, T, m\) = \(2, 41, m\)"
                                          r".*x of shape \(2, 41, 2\); got u of shape")):
        _train(_controlled(), t, x, u=torch.zeros(shape, dtype=F64))
