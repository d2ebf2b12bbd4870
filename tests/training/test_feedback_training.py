"""Learning the neural feedback (Eq. (12), Alg. 1): one step descends, cases batch, f stays frozen, seeds side by side."""

import copy

import pytest
import torch

from fnnlib.models import NeuralFeedback, NeuralFeedbackEnsemble, NeuralODE, NeuralODEEnsemble, stack_members
from fnnlib.observers import feedback_rollout
from fnnlib.systems import Spiral
from fnnlib.seeding import seed_everything
from fnnlib.training import (PAPER_FEEDBACK_RECIPE, QUICK_RECIPE, FeedbackRecipe, feedback_loss, train_neural_feedback,
                             train_neural_ode)

TS = 0.05


def _cases(n_case=3, T=40):
    t = torch.arange(T, dtype=torch.float64) * TS
    X = torch.stack([Spiral(w, 0.1, e).exact_solution(torch.tensor([2.0, 0.0]), t)
                     for w, e in zip([1.5, 2.0, 2.5][:n_case], [-1.0, 0.0, 1.0][:n_case])])
    return t, X


def _fit(f, h, t, X, progress=False, **settings):
    """train_neural_feedback with the paper's recipe but for ``settings``."""
    return train_neural_feedback(f, h, t, X, PAPER_FEEDBACK_RECIPE.replace(**settings), seed=0, progress=progress)


def _fit_seeds(f, h, t, X, seeds, **settings):
    """train_neural_feedback over ``seeds`` (a list: side by side; an int: one plain seed)."""
    return train_neural_feedback(f, h, t, X, PAPER_FEEDBACK_RECIPE.replace(**settings), seed=seeds, progress=False)


def _nets(seed=0):
    torch.manual_seed(seed)
    return NeuralODE(2, (16,), "tanh").double(), NeuralFeedback(2, (16,), "relu").double()


def test_one_step_lowers_the_full_batch_loss():
    t, X = _cases()
    f, h = _nets()
    with torch.no_grad():
        fx = f(0.0, X.reshape(-1, 2)).reshape(X.shape)
        e = X - feedback_rollout(fx, X, h, TS).x_hat
    args = (X[:, :-1].reshape(-1, 2), fx[:, :-1].reshape(-1, 2), e[:, :-1].reshape(-1, 2), X[:, 1:].reshape(-1, 2), TS)
    with torch.no_grad():
        before = feedback_loss(h, *args).item()
    pool = X.shape[0] * (X.shape[1] - 1)
    hist = _fit(f, h, t, X, iterations=1, batch_size=pool, lr=1e-3, optimizer="adam")
    with torch.no_grad():
        after = feedback_loss(h, *args).item()
    assert hist.loss[0] == pytest.approx(before, rel=1e-12)
    assert after < before


def test_training_leaves_f_bitwise_unchanged():
    t, X = _cases()
    f, h = _nets()
    f_state = copy.deepcopy(f.state_dict())
    flags = [p.requires_grad for p in f.parameters()]
    hist = _fit(f, h, t, X, iterations=60, batch_size=32, lr=0.01, refresh_every=5)
    assert len(hist.loss) == 60 and hist.seconds > 0
    assert all(torch.equal(f_state[k], v) for k, v in f.state_dict().items())
    assert [p.requires_grad for p in f.parameters()] == flags  # restored after training
    assert all(p.grad is None for p in f.parameters())


def test_rollout_batched_over_cases_equals_per_case():
    t, X = _cases()
    f, h = _nets()
    with torch.no_grad():
        fx = f(0.0, X.reshape(-1, 2)).reshape(X.shape)
        batched = feedback_rollout(fx, X, h, TS)
        for i in range(X.shape[0]):
            one = feedback_rollout(fx[i], X[i], h, TS)
            torch.testing.assert_close(batched.x_hat[i], one.x_hat, rtol=0, atol=1e-12)
            torch.testing.assert_close(batched.f_hat[i], one.f_hat, rtol=0, atol=1e-12)


def test_same_seed_same_result():
    t, X = _cases()
    runs = []
    for _ in range(2):
        f, h = _nets()
        runs.append(_fit(f, h, t, X, iterations=5, batch_size=16).loss)
    assert runs[0] == runs[1]


def test_bad_inputs():
    t, X = _cases()
    f, h = _nets()
    with pytest.raises(ValueError, match="n_case, T, n"):
        _fit(f, h, t, X[0])
    with pytest.raises(ValueError, match="points but X has"):
        _fit(f, h, t[:-1], X)
    with pytest.raises(ValueError, match="exceeds"):
        _fit(f, h, t, X, batch_size=10_000)
    with pytest.raises(ValueError, match="unknown optimizer"):
        _fit(f, h, t, X, optimizer="sgd")
    with pytest.raises(ValueError, match="refresh_every"):
        _fit(f, h, t, X, refresh_every=0)
    with pytest.raises(ValueError, match="share parameters"):
        _fit(f, f.net, t, X)


def test_recipe_is_required_and_typed():
    t, X = _cases()
    f, h = _nets()
    with pytest.raises(TypeError, match="recipe must be a FeedbackRecipe"):
        train_neural_feedback(f, h, t, X, dict(iterations=1), seed=0)
    with pytest.raises(TypeError):
        train_neural_feedback(f, h, t, X, seed=0)  # no silent paper defaults
    with pytest.raises(TypeError):
        FeedbackRecipe(iterations=1)  # every setting is named


# --------------------------------------------------------------------------- several seeds side by side
def _seed_nets(seeds):
    """Per seed: a neural ODE (the frozen model of that seed) and the seed's feedback initialisation."""
    fs = []
    for s in seeds:
        torch.manual_seed(100 + s)
        fs.append(NeuralODE(2, (16,), "tanh"))
    return fs, NeuralODEEnsemble.from_members(fs, seeds), NeuralFeedbackEnsemble(2, (16,), "relu", seeds)


def test_ensemble_trains_every_seed_bitwise_as_alone():
    t, X = _cases()
    X = X.float()
    seeds = [0, 1, 2]
    settings = dict(iterations=12, batch_size=20, lr=0.01, refresh_every=4)
    _, f_ens, h_ens = _seed_nets(seeds)
    hist = _fit_seeds(f_ens, h_ens, t, X, seeds, **settings)
    assert len(hist.member_loss) == 12 and hist.seeds == seeds
    assert hist.loss == [sum(row) / 3 for row in hist.member_loss]
    for e, s in enumerate(seeds):
        fs, _, _ = _seed_nets([s])
        f1, h1 = NeuralODEEnsemble.from_members(fs, [s]), NeuralFeedbackEnsemble(2, (16,), "relu", [s])
        alone = _fit_seeds(f1, h1, t, X, [s], **settings)
        assert alone.member(0) == hist.member(e)  # bitwise: own initialisation, own mini-batch draws
        assert all(torch.equal(a, b) for a, b in zip(h1.member(0).parameters(), h_ens.member(e).parameters()))
        # a plain NeuralFeedback with the plain neural ODE, trained alone with seed s: equal up to float32 rounding
        fp = fs[0]
        torch.manual_seed(0)
        hp = NeuralFeedbackEnsemble(2, (16,), "relu", [s]).member(0)
        plain = _fit_seeds(fp, hp, t, X, s, **settings)
        assert plain.loss == pytest.approx(hist.member(e), rel=1e-4)
    assert hist.member(0) != hist.member(1)  # the seeds are independent


def test_ensemble_bad_seeds_and_widths():
    t, X = _cases()
    _, f_ens, h_ens = _seed_nets([0, 1])
    with pytest.raises(ValueError, match="distinct"):
        _fit_seeds(f_ens, h_ens, t, X, [1, 1])
    with pytest.raises(ValueError, match=r"map \(batch, 6\)"):
        _fit_seeds(f_ens, h_ens, t, X, [0, 1, 2])


def test_domain_randomized_ensemble_follows_each_model_trained_alone():
    """The domain-randomized neural ODEs train as one NeuralODEEnsemble on the tiled cases (the spiral's way):
    the members share the mini-batch draws; with a fixed-step solver each follows its model trained alone on
    the same draws, up to RMSprop's epsilon (the ensemble's loss is the members' mean)."""
    t, X = _cases()
    X = X.float()
    recipe = QUICK_RECIPE.replace(iterations=5, batch_size=6, batch_time=4, lr=1e-3, optimizer="rmsprop", loss="l1")
    seeds = [0, 1]
    ens = NeuralODEEnsemble(2, (8,), "relu", seeds)
    train_neural_ode(ens, t, stack_members(X, 2), recipe, seed=seeds[0], progress=False)
    for e, s in enumerate(seeds):
        seed_everything(s)
        alone = NeuralODE(2, (8,), "relu")
        train_neural_ode(alone, t, X, recipe, seed=seeds[0], progress=False)
        for a, b in zip(ens.member(e).parameters(), alone.parameters()):
            torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("kw, match", [(dict(optimizer="sgd"), "unknown optimizer"),
                                       (dict(refresh_every=0), "refresh_every"), (dict(iterations=0), "iterations"),
                                       (dict(lr=0.0), "lr must be a finite positive number")])
def test_a_feedback_recipe_checks_its_fields_when_made(kw, match):
    with pytest.raises(ValueError, match=match):
        PAPER_FEEDBACK_RECIPE.replace(**kw)
