"""NeuralODEEnsemble: E networks side by side on the stacked state, each exactly as it would run alone."""

from __future__ import annotations

import pytest
import torch

import fnnlib as F
from fnnlib.models import split_members, stack_members
from fnnlib.seeding import seed_everything
from fnnlib.stability import observe_continuous
from fnnlib.systems import Spiral, StackedSystem


@pytest.mark.parametrize("batch", [5, F.NeuralODEEnsemble.BMM_MAX_BATCH + 1])  # both evaluation paths
def test_members_start_from_their_seeds_weights_and_evaluate_alone(batch: int) -> None:
    ens = F.NeuralODEEnsemble(2, [8, 8], "tanh", [3, 7])
    x = torch.randn(batch, 2)
    out = split_members(ens(0.0, stack_members(x, 2)), 2)
    for e, s in enumerate([3, 7]):
        seed_everything(s)
        alone = F.NeuralODE(2, [8, 8], "tanh")
        torch.testing.assert_close(out[e], alone(0.0, x))
        torch.testing.assert_close(ens.member(e)(0.0, x), alone(0.0, x))


def test_cascade_on_the_stacked_state_equals_each_member_alone() -> None:
    ens = F.NeuralODEEnsemble(2, [8], "relu", [0, 1, 2])
    x = torch.randn(40, 2)
    z = split_members(F.cascade_predict(ens, stack_members(x, 3), 0.01, 5, F.Gains(20.0, 0.02)), 3)
    for e in range(3):
        torch.testing.assert_close(z[e], F.cascade_predict(ens.member(e), x, 0.01, 5, F.Gains(20.0, 0.02)), atol=1e-5, rtol=0)


def test_member_gradients_do_not_mix() -> None:
    ens = F.NeuralODEEnsemble(2, [4], "relu", [0, 1])
    x = stack_members(torch.randn(6, 2), 2)
    out = split_members(ens(0.0, x), 2)
    out[1].sum().backward()  # a loss on member 1 only
    assert all(float(p.grad[0].abs().max()) == 0.0 for p in [*ens.weights, *ens.biases])
    assert any(float(p.grad[1].abs().max()) > 0.0 for p in ens.weights)


@pytest.mark.parametrize("seeds", [[], [1, 1]])
def test_bad_seeds_are_refused(seeds: list[int]) -> None:
    with pytest.raises(ValueError, match="seed"):
        F.NeuralODEEnsemble(2, [4], "relu", seeds)


def test_wrong_state_width_is_refused() -> None:
    with pytest.raises(ValueError, match=r"\(batch, 4\)"):
        F.NeuralODEEnsemble(2, [4], "relu", [0, 1])(0.0, torch.randn(3, 2))


def test_from_members_rebuilds_the_trained_networks_side_by_side() -> None:
    torch.manual_seed(0)
    members = [F.NeuralODE(2, [8, 8], "relu").double() for _ in range(3)]
    ens = F.NeuralODEEnsemble.from_members(members, [4, 1, 9])
    assert ens.seeds == [4, 1, 9] and ens.size == 3 and next(ens.parameters()).dtype == torch.float64
    x = torch.randn(30, 2, dtype=torch.float64)
    out = split_members(ens(0.0, stack_members(x, 3)), 3)
    for e, m in enumerate(members):
        torch.testing.assert_close(out[e], m(0.0, x))
        torch.testing.assert_close(ens.member(e)(0.0, x), m(0.0, x))
    with pytest.raises(ValueError, match="one member per seed"):
        F.NeuralODEEnsemble.from_members(members, [0, 1])
    with pytest.raises(ValueError, match="share one architecture"):
        F.NeuralODEEnsemble.from_members([members[0], F.NeuralODE(2, [4], "relu").double()], [0, 1])
    with pytest.raises(ValueError, match="share one architecture and dtype"):
        F.NeuralODEEnsemble.from_members([members[0], F.NeuralODE(2, [8, 8], "relu")], [0, 1])


def test_continuous_observer_of_every_member_in_one_integration() -> None:
    torch.manual_seed(1)
    members = [F.NeuralODE(2, [8], "tanh").double() for _ in range(2)]
    ens = F.NeuralODEEnsemble.from_members(members, [0, 1])
    spiral, x0, t = Spiral(3.0, 0.05, 10.0), torch.tensor([9.0, 0.0], dtype=torch.float64), torch.arange(60) * 0.01
    stacked = StackedSystem(spiral, 2)
    assert stacked.n == 4
    x, est = observe_continuous(stacked, ens, 20.0, stack_members(x0, 2), t)
    for e, m in enumerate(members):
        x_e, est_e = observe_continuous(spiral, m, 20.0, x0, t)
        torch.testing.assert_close(split_members(x, 2)[e], x_e, rtol=1e-7, atol=1e-7)
        torch.testing.assert_close(split_members(est.x_hat, 2)[e], est_e.x_hat, rtol=1e-7, atol=1e-7)
        torch.testing.assert_close(split_members(est.f_hat, 2)[e], est_e.f_hat, rtol=1e-6, atol=1e-6)
    with pytest.raises(ValueError, match="E >= 1"):
        StackedSystem(spiral, 0)


def test_split_puts_each_members_own_states_first() -> None:
    """``ens.split`` undoes ``stack_members`` per member: member e's slice of a stacked (..., E n) tensor."""
    ens = F.NeuralODEEnsemble(2, [4], "tanh", [0, 1, 2])
    z = torch.arange(2 * 5 * 6, dtype=torch.float64).reshape(2, 5, 6)  # (..., E n), E = 3, n = 2
    out = ens.split(z)
    assert out.shape == (3, 2, 5, 2)
    for e in range(3):
        torch.testing.assert_close(out[e], z[..., 2 * e:2 * e + 2])
    torch.testing.assert_close(ens.split(stack_members(z[..., :2], 3)), z[..., :2].expand(3, 2, 5, 2))
