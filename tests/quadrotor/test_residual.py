"""The quadrotor's aerodynamic residual (App. A.5.2), its adaptive last layer (Eqs. (29)-(30)) and the ensemble."""

from __future__ import annotations

import math

import pytest
import torch

from fnnlib.models import MODELS
from fnnlib.quadrotor.residual import AdaptiveResidual, AeroResidual, EnsembleResidual
from fnnlib.quadrotor.presets import PAPER_GAMMA
from fnnlib.training import load_checkpoint, save_checkpoint

F64 = torch.float64


def _net(seed: int = 0, **kw) -> AeroResidual:
    torch.manual_seed(seed)
    return AeroResidual(**{"hidden": (36, 36), "activation": "tanh", **kw}).double()


def _states(n: int, seed: int = 1) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.randn(n, 12, generator=g, dtype=F64)


# --------------------------------------------------------------------------- AeroResidual


def test_architecture_and_shapes():
    net = _net()
    linears = [m for m in net.net if isinstance(m, torch.nn.Linear)]
    assert [(m.in_features, m.out_features) for m in linears] == [(6, 36), (36, 36), (36, 3)]
    assert sum(isinstance(m, torch.nn.Tanh) for m in net.net) == 2
    assert net.last is linears[-1]
    assert net(_states(5)).shape == (5, 3)
    assert net(torch.zeros(2, 4, 12, dtype=F64)).shape == (2, 4, 3)
    assert net(torch.zeros(12, dtype=F64)).shape == (3,)


def test_uses_only_velocity_and_attitude():
    net = _net()
    x = _states(8)
    y = net(x)
    other = x.clone()
    other[:, 0:3] += 5.0  # position
    other[:, 9:12] -= 3.0  # body rates
    assert torch.equal(net(other), y)
    for cols in (slice(3, 6), slice(6, 9)):  # v and Theta each matter
        moved = x.clone()
        moved[:, cols] += 0.5
        assert (net(moved) - y).abs().min() > 0
    # the front layers see exactly x[..., 3:9]
    assert torch.allclose(net(x), net.net(x[:, 3:9]))


def test_last_layer_is_chi():
    net = _net()
    x = _states(6)
    phi = net.features(x)
    assert phi.shape == (6, 36)
    torch.testing.assert_close(net(x), phi @ net.last.weight.T + net.last.bias, rtol=0, atol=1e-14)


def test_rejects_a_state_that_is_not_12_dimensional():
    net = _net()
    with pytest.raises(ValueError, match="12-dimensional"):
        net(torch.zeros(4, 6, dtype=F64))
    with pytest.raises(ValueError, match="12-dimensional"):
        net.features(torch.zeros(4, 13, dtype=F64))
    with pytest.raises(ValueError, match="hidden layer"):
        AeroResidual(hidden=(), activation="tanh")


def test_config_and_checkpoint_round_trip(tmp_path):
    assert MODELS["AeroResidual"] is AeroResidual
    net = _net(hidden=(8, 5), activation="relu")
    assert net.config == {"hidden": [8, 5], "activation": "relu"}
    save_checkpoint(tmp_path / "r.pt", net, {"seed": 3})
    back, meta = load_checkpoint(tmp_path / "r.pt", expected_kind="AeroResidual")
    x = _states(7)
    assert torch.equal(back(x), net(x)) and meta == {"seed": 3} and back.config == net.config


# --------------------------------------------------------------------------- AdaptiveResidual


def test_adaptive_starts_as_the_base_network():
    base = _net()
    ad = AdaptiveResidual(base, Gamma=8.0)
    x = _states(10)
    torch.testing.assert_close(ad(x), base(x), rtol=0, atol=1e-14)
    torch.testing.assert_close(ad.features(x), base.features(x), rtol=0, atol=0)
    assert torch.equal(ad.chi_hat, base.last.weight) and torch.equal(ad.b, base.last.bias)
    # Eq. (29): f_neural = Xi(x) chi_hat (+ the fixed bias)
    torch.testing.assert_close(ad(x), ad.features(x) @ ad.chi_hat.T + ad.b, rtol=0, atol=0)


def test_adapt_is_one_euler_step_of_eq_30():
    base = _net()
    ad = AdaptiveResidual(base, Gamma=2.5)
    x, x_tilde_v, Ts = _states(1, seed=4)[0], torch.tensor([0.3, -1.2, 0.7], dtype=F64), 0.02
    chi_before, b_before = ad.chi_hat.clone(), ad.b.clone()
    front_before = [p.clone() for p in ad.front.parameters()]
    phi = base.features(x)
    ad.adapt(x, x_tilde_v, Ts)
    # chi_hat += Ts Gamma x_tilde_v phi(x)^T
    torch.testing.assert_close(ad.chi_hat - chi_before, Ts * 2.5 * torch.outer(x_tilde_v, phi), rtol=1e-12, atol=1e-15)
    assert torch.equal(ad.b, b_before)
    assert all(torch.equal(p, q) for p, q in zip(ad.front.parameters(), front_before))
    # the sign of Eq. (30): at the adaptation point the output moves along x_tilde_v, by Ts Gamma |phi|^2 x_tilde_v
    moved = ad(x) - base(x)
    torch.testing.assert_close(moved, Ts * 2.5 * phi.dot(phi) * x_tilde_v, rtol=1e-10, atol=1e-14)
    # elsewhere the network is the new chi_hat on the same features
    y = _states(5, seed=9)
    torch.testing.assert_close(ad(y), base.features(y) @ ad.chi_hat.T + base.last.bias, rtol=0, atol=1e-13)


def test_zero_error_does_not_adapt_and_reset_restores():
    base = _net()
    ad = AdaptiveResidual(base, Gamma=PAPER_GAMMA)
    x = _states(1)[0]
    ad.adapt(x, torch.zeros(3, dtype=F64), 0.02)
    assert torch.equal(ad.chi_hat, base.last.weight)
    for _ in range(3):
        ad.adapt(x, torch.ones(3, dtype=F64), 0.02)
    assert not torch.equal(ad.chi_hat, base.last.weight)
    ad.reset()
    assert torch.equal(ad.chi_hat, base.last.weight)
    y = _states(4)
    assert torch.equal(ad(y), ad.features(y) @ base.last.weight.T + base.last.bias)


def test_adaptive_copies_the_base_and_never_modifies_it():
    base = _net()
    flags = [p.requires_grad for p in base.parameters()]
    params = [p.clone() for p in base.parameters()]
    ad = AdaptiveResidual(base, Gamma=PAPER_GAMMA)
    x = _states(6)
    y0 = ad(x)
    ad.adapt(x[0], torch.ones(3, dtype=F64), 0.1)
    # the base keeps its weights and stays trainable
    assert [p.requires_grad for p in base.parameters()] == flags == [True] * len(flags)
    assert all(torch.equal(p, q) for p, q in zip(base.parameters(), params))
    assert not any(p.requires_grad for p in ad.front.parameters())
    # changing the base afterwards does not reach the adaptive copy, nor does converting the copy reach the base
    ad.reset()
    with torch.no_grad():
        base.net[0].weight.add_(1.0)
    torch.testing.assert_close(ad(x), y0, rtol=0, atol=0)
    ad.float()
    assert base(x).dtype == F64


@pytest.mark.parametrize("Gamma", [0.0, -1.0, math.nan, math.inf])
def test_refuses_a_gain_that_is_not_positive(Gamma):
    with pytest.raises(ValueError, match="Gamma"):
        AdaptiveResidual(_net(), Gamma=Gamma)


def test_adapt_refuses_nan_and_wrong_shapes():
    ad = AdaptiveResidual(_net(), Gamma=PAPER_GAMMA)
    x = _states(1)[0]
    chi = ad.chi_hat.clone()
    with pytest.raises(ValueError, match="NaN"):
        ad.adapt(x, torch.tensor([0.0, math.nan, 1.0], dtype=F64), 0.02)
    with pytest.raises(ValueError, match="NaN"):
        ad.adapt(x, torch.tensor([0.0, math.inf, 1.0], dtype=F64), 0.02)
    z3 = torch.zeros(3, dtype=F64)
    for xx, e in ((x, torch.zeros(12, dtype=F64)), (x, torch.zeros(1, 3, dtype=F64)), (x[:9], z3), (_states(2), z3)):
        with pytest.raises(ValueError, match="adapt takes"):
            ad.adapt(xx, e, 0.02)
    assert torch.equal(ad.chi_hat, chi)  # a refused update changes nothing
    with pytest.raises(ValueError, match="12-dimensional"):
        ad(torch.zeros(3, 6, dtype=F64))


# --------------------------------------------------------------------------- EnsembleResidual


def _members(E: int = 3, **kw) -> list[AeroResidual]:
    return [_net(seed=10 + e, **kw) for e in range(E)]


def test_ensemble_equals_each_member_alone():
    members = _members(3)
    ens = EnsembleResidual(members)
    assert ens.E == 3
    x = torch.randn(4, 5, 3, 12, dtype=F64, generator=torch.Generator().manual_seed(0))
    y = ens(x)
    assert y.shape == (4, 5, 3, 3)
    for e, m in enumerate(members):
        torch.testing.assert_close(y[..., e, :], m(x[..., e, :]), rtol=1e-12, atol=1e-14)
    # a single batch axis works too
    torch.testing.assert_close(ens(x[0, 0]), torch.stack([m(x[0, 0, e]) for e, m in enumerate(members)]),
                               rtol=1e-12, atol=1e-14)


def test_member_round_trip():
    members = _members(3, hidden=(7, 4), activation="elu")
    ens = EnsembleResidual(members)
    x = _states(9)
    for e, m in enumerate(members):
        back = ens.member(e)
        assert isinstance(back, AeroResidual) and back.config == m.config
        assert all(torch.equal(p, q) for p, q in zip(back.parameters(), m.parameters()))
        assert torch.equal(back(x), m(x))
    # member() is a copy: changing it leaves the ensemble alone
    with torch.no_grad():
        ens.member(0).last.weight.add_(1.0)
    assert torch.equal(ens.member(0).last.weight, members[0].last.weight)


def test_a_training_step_on_the_ensemble_is_each_members_own_step():
    E = 3
    members = _members(E)
    alone = [_net(seed=10 + e) for e in range(E)]  # identical copies, trained one by one
    ens = EnsembleResidual(members)
    g = torch.Generator().manual_seed(5)
    x = torch.randn(16, E, 12, generator=g, dtype=F64)
    target = torch.randn(16, E, 3, generator=g, dtype=F64)

    def member_loss(y: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        return ((y - t) ** 2).mean()

    # gradients: a summed loss gives each member exactly its own gradient
    loss = sum(member_loss(ens(x)[:, e], target[:, e]) for e in range(E))
    loss.backward()
    for e, m in enumerate(alone):
        member_loss(m(x[:, e]), target[:, e]).backward()
        linears = [layer for layer in m.net if isinstance(layer, torch.nn.Linear)]
        for i, layer in enumerate(linears):
            torch.testing.assert_close(ens.weights[i].grad[e], layer.weight.grad, rtol=1e-12, atol=1e-15)
            torch.testing.assert_close(ens.biases[i].grad[e], layer.bias.grad, rtol=1e-12, atol=1e-15)

    # and Adam, being element-wise, then moves each member as it would move alone (a few steps)
    opt = torch.optim.Adam(ens.parameters(), lr=1e-2)
    opts = [torch.optim.Adam(m.parameters(), lr=1e-2) for m in alone]
    for _ in range(3):
        opt.zero_grad()
        sum(member_loss(ens(x)[:, e], target[:, e]) for e in range(E)).backward()
        opt.step()
        for e, (m, o) in enumerate(zip(alone, opts)):
            o.zero_grad()
            member_loss(m(x[:, e]), target[:, e]).backward()
            o.step()
    for e, m in enumerate(alone):
        for p, q in zip(ens.member(e).parameters(), m.parameters()):
            torch.testing.assert_close(p, q, rtol=1e-10, atol=1e-12)
    assert not torch.equal(ens.member(0).last.weight, members[0].last.weight)  # it did train


def test_ensemble_checks():
    with pytest.raises(ValueError, match="at least one member"):
        EnsembleResidual([])
    with pytest.raises(ValueError, match="share hidden sizes"):
        EnsembleResidual([_net(hidden=(4,)), _net(hidden=(5,))])
    with pytest.raises(ValueError, match="share hidden sizes"):
        EnsembleResidual([_net(activation="tanh"), _net(activation="relu")])
    ens = EnsembleResidual(_members(2))
    with pytest.raises(ValueError, match=r"\(\.\.\., 2, 12\)"):
        ens(torch.zeros(4, 3, 12, dtype=F64))
    with pytest.raises(ValueError, match=r"\(\.\.\., 2, 12\)"):
        ens(torch.zeros(4, 2, 6, dtype=F64))
