"""Learning the quadrotor residual (App. A.5.2): the stacked closed loop, ensemble training, prediction, MLP."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fnnlib.quadrotor.control.dfbc import DFBC
from fnnlib.data.quadrotor import Flights, make_flights
from fnnlib.quadrotor.residual import AeroResidual, EnsembleResidual
from fnnlib.quadrotor.presets import PAPER_DFBC_GAINS, PAPER_FLIGHT_DATA, PAPER_RESIDUAL_RECIPE, PAPER_TS
from fnnlib.quadrotor.training import PAPER_RESIDUAL, ResidualRecipe
from fnnlib.quadrotor.system import NOMINAL, TRAINING_TRUTH, Quadrotor
from fnnlib.training.external import make_segments, rollout
from fnnlib.quadrotor.training import (closed_loop_step, convergence_checks, predict_flights, state_group_errors,
                                      train_residual_ensemble, train_single_step)

F64 = torch.float64
CTRL, PLANT = DFBC(NOMINAL, **PAPER_DFBC_GAINS), Quadrotor(NOMINAL)
#: the paper's recipe with a short run's settings
RECIPE = PAPER_RESIDUAL


def _flights(n_flights: int, n_nodes: int, **changes: object) -> Flights:
    """Training flights as the release draws and flies them (0.02 s, DFBC on the nominal model), some settings
    changed (the nominal vehicle unless ``truth`` is given)."""
    kw = {"Ts": PAPER_TS, "seed": 0, "truth": NOMINAL, "controller": DFBC(NOMINAL, **PAPER_DFBC_GAINS),
          **PAPER_FLIGHT_DATA, **changes}
    return make_flights(n_flights, n_nodes, **kw)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def flights() -> Flights:
    """4 flights x 40 nodes of 0.05 s on the drag truth (2 s each: short flights at 0.02 s are not flyable)."""
    return _flights(4, 40, Ts=0.05, seed=0, truth=TRAINING_TRUTH, n_waypoints=2)


def _subset(f: Flights, k: slice) -> Flights:
    return Flights(x=f.x[k], Psi=f.Psi[k], u=f.u[k], Ts=f.Ts)


def _true_drag(x: torch.Tensor) -> torch.Tensor:
    return Quadrotor(TRAINING_TRUTH).drag_acceleration(x)


# --------------------------------------------------------------------------- closed_loop_step


def test_stacked_step_equals_separate_steps(flights):
    E, B = 3, 5
    torch.manual_seed(0)
    members = [AeroResidual(hidden=(8, 8), activation="tanh").double() for _ in range(E)]
    ens = EnsembleResidual(members)
    g = torch.Generator().manual_seed(1)
    x = flights.x[:, 10:15].reshape(-1, 18)[:B] + 0.1 * torch.randn(B, 18, generator=g, dtype=F64)
    x = torch.cat([x + 0.05 * e for e in range(E)], dim=-1)  # (B, 18 E): different states per member
    I = flights.Psi[:, 10:15].reshape(-1, 12)[:B]
    for Ts, substeps in ((0.02, 1), (0.05, 2)):
        out = closed_loop_step(ens, CTRL, PLANT, Ts=Ts, substeps=substeps, members=E)(x, I)
        assert out.shape == (B, 18 * E)
        for e, m in enumerate(members):
            alone = closed_loop_step(m, CTRL, PLANT, Ts=Ts, substeps=substeps)(x[:, 18 * e:18 * (e + 1)], I)
            torch.testing.assert_close(out[:, 18 * e:18 * (e + 1)], alone, rtol=1e-12, atol=1e-12)
            direct = CTRL.closed_loop_step(x[:, 18 * e:18 * (e + 1)], I, PLANT, Ts=Ts, substeps=substeps, a_res_fn=m)
            torch.testing.assert_close(alone, direct, rtol=0, atol=0)
    # no residual: the plain closed loop
    plain = closed_loop_step(None, CTRL, PLANT, Ts=0.05)(x[:, :18], I)
    torch.testing.assert_close(plain, CTRL.closed_loop_step(x[:, :18], I, PLANT, Ts=0.05), rtol=0, atol=0)


# --------------------------------------------------------------------------- predict_flights


def test_prediction_with_the_true_drag_reproduces_the_flights(flights):
    """The key consistency check of the learning setup: nominal + the true drag, flown by the same DFBC from
    each flight's first state on the recorded commands with the data's sub-steps, is the recorded flight."""
    pred = predict_flights(_true_drag, flights, controller=CTRL, plant=PLANT, substeps=4)
    assert pred.shape == flights.x.shape and pred.dtype == F64
    assert torch.equal(pred[:, 0], flights.x[:, 0])
    torch.testing.assert_close(pred, flights.x, rtol=0, atol=1e-9)
    # without the drag the same prediction is off: the check can fail
    nominal = predict_flights(None, flights, controller=CTRL, plant=PLANT, substeps=4)
    assert float((nominal - flights.x)[..., :12].abs().max()) > 0.1


def test_prediction_at_the_default_step_too():
    f = _flights(1, 40, seed=1, truth=TRAINING_TRUTH, n_waypoints=2)  # Ts = 0.02
    pred = predict_flights(_true_drag, f, controller=CTRL, plant=PLANT, substeps=4)
    torch.testing.assert_close(pred, f.x, rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- train_residual_ensemble


def test_train_residual_ensemble_tiny(flights):
    val = _subset(flights, slice(0, 1))
    fit = train_residual_ensemble([0, 1], flights, RECIPE.replace(segment_length=10, batch_size=8, epochs=2),
                                  controller=CTRL, plant=PLANT, val=val, progress=False)
    assert len(fit.members) == 2 and all(type(m) is AeroResidual for m in fit.members)
    assert all(m.config == {"hidden": [36, 36], "activation": "tanh"} for m in fit.members)
    assert next(fit.members[0].parameters()).dtype == torch.float32
    loss = fit.member_loss
    assert len(loss) == 3 and all(len(row) == 2 for row in loss)  # before training + 2 epochs, 2 members
    assert all(math.isfinite(v) and v > 0 for row in loss for v in row)
    assert loss[0][0] != loss[0][1]  # different initialisations
    for e in range(2):
        assert loss[2][e] < loss[1][e] < loss[0][e]
    assert fit.history.segments == 16 and fit.history.n_updates == 4
    assert fit.history.epoch_loss[1] < fit.history.epoch_loss[0]
    assert fit.val_epochs == [0, 2] and len(fit.val_loss) == 2
    assert all(math.isfinite(v) for row in fit.val_loss for v in row)
    assert fit.val_loss[1][0] < fit.val_loss[0][0] and fit.val_loss[1][1] < fit.val_loss[0][1]
    assert fit.seconds > 0
    # the members differ after training (their initial weights did)
    assert not torch.equal(fit.members[0].last.weight, fit.members[1].last.weight)
    # the last recorded loss is Eq. (13) of the returned members, each rolled out alone at the data's step
    x_seg, I_seg = make_segments(flights.x.float(), flights.Psi.float(), 10)
    for e, member in enumerate(fit.members):
        x = rollout(closed_loop_step(member, CTRL, PLANT, Ts=flights.Ts), x_seg[:, 0], I_seg)
        own = 0.5 * ((x[:, 1:, :12] - x_seg[:, 1:, :12]) ** 2).sum(dim=(1, 2)).mean()
        assert loss[2][e] == pytest.approx(float(own), rel=1e-4)


def test_each_member_trains_as_it_would_alone(flights):
    """Q1's batching: member e of an ensemble ends where training it alone ends (full batches, float64)."""
    data = _subset(flights, slice(0, 2))
    recipe = RECIPE.replace(hidden=(8, 8), segment_length=10, batch_size=None, epochs=2)
    kw = dict(controller=CTRL, plant=PLANT, progress=False, dtype=F64)
    ens = train_residual_ensemble([0, 1], data, recipe, **kw)
    for e, seed in enumerate((0, 1)):
        alone = train_residual_ensemble([seed], data, recipe, **kw)
        for p, q in zip(ens.members[e].parameters(), alone.members[0].parameters()):
            torch.testing.assert_close(p, q, rtol=1e-9, atol=1e-12)
        for row_ens, row_alone in zip(ens.member_loss, alone.member_loss):
            assert row_ens[e] == pytest.approx(row_alone[0], rel=1e-9)


def test_train_residual_ensemble_checks(flights):
    with pytest.raises(ValueError, match="seed"):
        train_residual_ensemble([], flights, RECIPE, controller=CTRL, plant=PLANT, progress=False)
    other = _flights(1, 12, Ts=0.04, seed=0, n_waypoints=2)
    with pytest.raises(ValueError, match="Ts"):
        train_residual_ensemble([0], flights, RECIPE.replace(epochs=1, segment_length=10, batch_size=None),
                                controller=CTRL, plant=PLANT, val=other, progress=False)
    with pytest.raises(TypeError, match="ResidualRecipe"):
        train_residual_ensemble([0], flights, dict(PAPER_RESIDUAL_RECIPE), controller=CTRL, plant=PLANT)  # type: ignore[arg-type]


def test_the_paper_residual_recipe_is_the_presets_and_checks_its_fields():
    assert PAPER_RESIDUAL.as_dict() == {**PAPER_RESIDUAL_RECIPE}
    assert RECIPE.replace(hidden=[8, 8]).hidden == (8, 8)
    for change, match in (({"hidden": ()}, "hidden"), ({"hidden": (8, 0)}, "hidden"), ({"activation": "sin"}, "activation"),
                          ({"epochs": 0}, "epochs"), ({"lr": 0.0}, "lr"), ({"batch_size": 0}, "batch_size"),
                          ({"segment_length": 0}, "segment_length")):
        with pytest.raises(ValueError, match=match):
            ResidualRecipe(**{**PAPER_RESIDUAL_RECIPE, **change})


# --------------------------------------------------------------------------- train_single_step


def test_train_single_step_fits_a_drag_like_target():
    g = torch.Generator().manual_seed(0)
    x = torch.randn(256, 12, generator=g, dtype=F64)
    D = torch.tensor([[0.7, 0.1, 0.0], [0.0, 0.7, 0.2], [0.1, 0.0, 0.3]], dtype=F64)
    labels = -x[:, 3:6] @ D.T + 0.1 * torch.sin(x[:, 6:9])  # linear in v, a little of Theta
    torch.manual_seed(0)
    net = AeroResidual(hidden=(16,), activation="tanh").double()
    with torch.no_grad():
        before = float(((net(x) - labels) ** 2).mean())
    losses = train_single_step(net, x, labels, epochs=60, batch_size=32, lr=1e-2, seed=0)
    assert len(losses) == 60 and all(math.isfinite(v) for v in losses)
    assert losses[-1] < 0.05 * losses[0]
    with torch.no_grad():
        after = float(((net(x) - labels) ** 2).mean())
    assert after < 0.05 * before
    # the recorded loss is the mean over the epoch's mini-batches, close to the final full-batch MSE
    assert after == pytest.approx(losses[-1], rel=0.5)


def test_train_single_step_same_seed_same_result():
    g = torch.Generator().manual_seed(2)
    x, labels = torch.randn(40, 12, generator=g, dtype=F64), torch.randn(40, 3, generator=g, dtype=F64)
    runs = []
    for _ in range(2):
        torch.manual_seed(3)
        net = AeroResidual(hidden=(4,), activation="tanh").double()
        runs.append(train_single_step(net, x, labels, epochs=3, batch_size=16, lr=1e-3, seed=7))
    assert runs[0] == runs[1]


def test_train_single_step_refuses_bad_pairs():
    net = AeroResidual(hidden=(4,), activation="tanh").double()
    x, labels = torch.zeros(10, 12, dtype=F64), torch.zeros(10, 3, dtype=F64)
    for xx, yy in ((x[:9], labels), (x[:, :11], labels), (x, labels[:, :2]), (x, torch.zeros(10, 4, dtype=F64))):
        with pytest.raises(ValueError, match=r"need x \(M, 12\) and labels \(M, 3\)"):
            train_single_step(net, xx, yy, epochs=1, batch_size=256, lr=1e-3, seed=0)
    bad = labels.clone()
    bad[3, 1] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        train_single_step(net, x, bad, epochs=1, batch_size=256, lr=1e-3, seed=0)


# --------------------------------------------------------------------------- the claims' evaluation


def test_convergence_checks_apply_q1s_rule():
    epochs = 10
    good = np.stack([np.geomspace(10.0, 0.5, epochs + 1), np.geomspace(12.0, 0.6, epochs + 1)], axis=1)
    good[-2:] = good[-3]  # flat at the end
    assert all(convergence_checks(good, epochs).values())
    still_falling = good.copy()
    still_falling[-1] = 0.5 * good[-2]  # the last 10 % of epochs halve the loss
    assert not convergence_checks(still_falling, epochs)["every initialisation: last 10 % of epochs change the loss < 20 %"]
    apart = good.copy()
    apart[:, 1] *= 3.0  # one member ends 3x higher
    assert not convergence_checks(apart, epochs)["initialisations agree: max/min final loss <= 2"]


def test_state_group_errors_are_relative_rmse_per_group():
    g = torch.Generator().manual_seed(0)
    true = torch.randn(2, 30, 12, generator=g, dtype=F64)
    pred = true.clone()
    pred[..., 3:6] *= 1.1  # only v is off, by 10 % of its own size
    errors = state_group_errors(pred, true)
    assert list(errors) == ["p", "v", "Theta", "omega"]
    assert errors["p"] == errors["Theta"] == errors["omega"] == 0.0
    assert errors["v"] == pytest.approx(0.1, rel=1e-12)
