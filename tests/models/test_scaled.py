"""ScaledField: each member alone equals its stacked self; the scales are applied as written; bad settings refused."""

from __future__ import annotations

import pytest
import torch

from fnnlib.models.neural_ode import mlp
from fnnlib.models.scaled import ScaledField
from fnnlib.seeding import seed_everything

KW = dict(x_center=5.0, x_scale=3.0, u_center=[3.0], u_scale=2.0, rate=0.05)


def test_members_stacked_equal_members_alone() -> None:
    ens = ScaledField(2, 1, [8, 8], "tanh", [0, 1, 2], **KW)
    x = 10 * torch.rand(7, 6, dtype=torch.float64)
    u = 6 * torch.rand(7, 1, dtype=torch.float64)
    out = ens(0.0, x, u)
    for e in range(3):
        torch.testing.assert_close(ens.member(e)(0.0, x[:, 2 * e:2 * e + 2], u), out[:, 2 * e:2 * e + 2])


def test_one_member_is_the_scaled_mlp_of_its_seed() -> None:
    f = ScaledField(2, 1, [8], "tanh", [4], **KW)
    seed_everything(4)
    net = mlp(3, 2, [8], "tanh").double()
    x = torch.tensor([[2.0, 8.0]], dtype=torch.float64)
    u = torch.tensor([[1.0]], dtype=torch.float64)
    want = 0.05 * net(torch.cat([(x - 5.0) / 3.0, (u - 3.0) / 2.0], -1))
    torch.testing.assert_close(f(0.0, x, u), want)


def test_gradients_stay_in_their_member() -> None:
    ens = ScaledField(2, 1, [8], "tanh", [0, 1], **KW)
    x = torch.rand(5, 4, dtype=torch.float64)
    ens(0.0, x, torch.rand(5, 1, dtype=torch.float64))[:, :2].sum().backward()
    assert all(p.grad[1].abs().sum() == 0 and p.grad[0].abs().sum() > 0 for p in ens.weights)


@pytest.mark.parametrize(("kwargs", "match"), [({"seeds": []}, "seed"), ({"seeds": [1, 1]}, "seed"),
                                               ({"activation": "sigmoid"}, "activation"), ({"rate": 0.0}, "rate"),
                                               ({"x_scale": 0.0}, "x_scale"), ({"u_center": float("nan")}, "u_center")])
def test_bad_settings_are_refused(kwargs, match) -> None:
    args = {"n_state": 2, "n_input": 1, "hidden": [4], "activation": "tanh", "seeds": [0], **KW, **kwargs}
    with pytest.raises(ValueError, match=match):
        ScaledField(**args)
    with pytest.raises(ValueError, match="x must be"):
        ScaledField(2, 1, [4], "tanh", [0])(0.0, torch.zeros(3, 3), torch.zeros(3, 1))
