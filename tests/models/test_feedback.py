"""The neural feedback part h_neural (Sec. 4): shape, config, checkpoint round trip; several seeds side by side."""

import pytest
import torch

from fnnlib.models import (MODELS, NeuralFeedback, NeuralFeedbackEnsemble, NeuralODE, NeuralODEEnsemble, split_members,
                           stack_members)
from fnnlib.seeding import seed_everything
from fnnlib.training import load_checkpoint, save_checkpoint


def test_architecture_is_the_papers():
    h = NeuralFeedback(2, (50, 50), "relu")
    linears = [m for m in h.net if isinstance(m, torch.nn.Linear)]
    assert [(m.in_features, m.out_features) for m in linears] == [(2, 50), (50, 50), (50, 2)]
    assert sum(isinstance(m, torch.nn.ReLU) for m in h.net) == 2
    assert h(torch.zeros(7, 2)).shape == (7, 2)


def test_checkpoint_round_trip(tmp_path):
    assert MODELS["NeuralFeedback"] is NeuralFeedback
    h = NeuralFeedback(3, hidden=(8,), activation="tanh").double()
    save_checkpoint(tmp_path / "h.pt", h, {"seed": 1})
    h2, meta = load_checkpoint(tmp_path / "h.pt", expected_kind="NeuralFeedback")
    e = torch.randn(5, 3, dtype=torch.float64)
    assert torch.equal(h(e), h2(e)) and meta == {"seed": 1} and h2.config == h.config


def test_bad_input_dimension():
    with pytest.raises(ValueError, match="feedback expects 2"):
        NeuralFeedback(2, (50, 50), "relu")(torch.zeros(4, 3))


# --------------------------------------------------------------------------- NeuralFeedbackEnsemble
def _alone(seed, hidden=(8, 8), activation="tanh"):
    seed_everything(seed)
    return NeuralFeedback(2, hidden, activation)


def test_ensemble_members_start_from_their_seeds_feedback_and_evaluate_as_alone():
    seeds = [3, 7, 11]
    ens = NeuralFeedbackEnsemble(2, (8, 8), "tanh", seeds)
    e = torch.randn(30, 2)
    out = split_members(ens(stack_members(e, 3)), 3)
    for m, s in enumerate(seeds):
        alone = _alone(s)
        assert all(torch.equal(a, b) for a, b in zip(ens.member(m).parameters(), alone.parameters()))
        assert torch.equal(out[m], NeuralFeedbackEnsemble(2, (8, 8), "tanh", [s])(e))  # bitwise: a one-member ensemble
        torch.testing.assert_close(out[m], alone(e))  # a plain NeuralFeedback: up to float32 rounding
        with pytest.raises(AssertionError):  # and the members differ
            torch.testing.assert_close(out[m], out[(m + 1) % 3])


def test_ensemble_gradients_do_not_depend_on_the_other_members():
    e = torch.randn(40, 2)
    ens, one = NeuralFeedbackEnsemble(2, (8,), "relu", [0, 1, 2]), NeuralFeedbackEnsemble(2, (8,), "relu", [1])
    split_members(ens(stack_members(e, 3)), 3)[1].pow(2).sum().backward()
    one(e).pow(2).sum().backward()
    stacked = [*ens.stacked.weights, *ens.stacked.biases]
    assert all(torch.equal(p.grad[1], q.grad[0]) for p, q in zip(stacked, [*one.stacked.weights, *one.stacked.biases]))
    assert all(float(p.grad[0].abs().max()) == 0.0 for p in stacked)


def test_ensemble_of_trained_neural_odes_copies_them():
    models = []
    for s in [4, 5]:
        seed_everything(s + 10)
        models.append(NeuralODE(2, (6,), "relu"))
    ens = NeuralODEEnsemble.from_members(models, [4, 5])
    x = torch.randn(9, 2)
    for m, model in enumerate(models):
        assert all(torch.equal(a, b) for a, b in zip(ens.member(m).parameters(), model.parameters()))
        torch.testing.assert_close(split_members(ens(0.0, stack_members(x, 2)), 2)[m], model(0.0, x))
    with pytest.raises(ValueError, match="one member per seed"):
        NeuralODEEnsemble.from_members(models, [4])
    with pytest.raises(ValueError, match="one architecture"):
        NeuralODEEnsemble.from_members([models[0], NeuralODE(2, (7,), "relu")], [4, 5])


def test_ensemble_refuses_a_wrong_width():
    with pytest.raises(ValueError, match=r"\(batch, 4\)"):
        NeuralFeedbackEnsemble(2, (4,), "relu", [0, 1])(torch.zeros(3, 2))
    with pytest.raises(ValueError, match="seed"):
        NeuralFeedbackEnsemble(2, (4,), "relu", [1, 1])
