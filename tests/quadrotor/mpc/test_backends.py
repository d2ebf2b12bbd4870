"""The flight backends of fnnlib.quadrotor.mpc.backends: one interface, chosen by name, the numba twin equal to the torch code."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fnnlib.quadrotor.mpc.backends import BACKENDS, NumbaBackend, TorchBackend, check_backend_name, make_backend
from fnnlib.quadrotor.mpc.models import FeedbackCascadeModel, PredictionModel
from fnnlib.quadrotor.system import NOMINAL, TEST_TRUTH, Quadrotor

# one worker runs every test that compiles the numba kernels: they compile once (~8 s per network depth),
# not once per worker at the same moment
pytestmark = pytest.mark.xdist_group("numba")

TS, N = 0.02, 4


def _model() -> PredictionModel:
    return PredictionModel("Nomi", Quadrotor(NOMINAL), Ts=TS)


def _plan(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(N, 12)) * np.r_[np.ones(6), 0.3 * np.ones(3), np.ones(3)]
    return X, rng.uniform(1.0, 4.0, size=(N, 4))


def test_backends_are_chosen_by_name_once():
    assert BACKENDS == {"torch": TorchBackend, "numba": NumbaBackend}
    m, truth = _model(), Quadrotor(TEST_TRUTH)
    torch_b = make_backend("torch", m, truth, Ts=TS, substeps=1, N=N, linearize_method="forward")
    assert isinstance(torch_b, TorchBackend) and torch_b.name == "torch"
    numba_b = make_backend("numba", m, truth, Ts=TS, substeps=1, N=N)
    assert isinstance(numba_b, NumbaBackend) and numba_b.name == "numba"


def test_bad_backend_settings_are_refused():
    m, truth = _model(), Quadrotor(TEST_TRUTH)
    with pytest.raises(ValueError, match="backend must be one of"):
        check_backend_name("jax")
    with pytest.raises(ValueError, match="linearize_method"):
        make_backend("torch", m, truth, Ts=TS, substeps=1, N=N)
    with pytest.raises(ValueError, match="Ts"):
        make_backend("numba", m, truth, Ts=0.01, substeps=1, N=N)


@pytest.mark.parametrize("substeps", [1, 3])
def test_the_numba_twin_computes_what_the_torch_backend_does(substeps):
    """Same interface, same numbers: the truth's rate and step, the model's rate and Phi along a plan, and the
    affine form (numba exact, torch by reverse-mode autograd) of a model with the feedback cascade."""
    truth = Quadrotor(TEST_TRUTH)
    fb = FeedbackCascadeModel(_model(), 3.0, beta=0.1, N=N)
    X, U = _plan(0)
    with torch.no_grad():
        fb.commit(torch.from_numpy(np.vstack([X, X[-1:]])), torch.from_numpy(U))  # the cascade holds x_hat now
    t_b = TorchBackend(fb, truth, Ts=TS, substeps=substeps, linearize_method="reverse", N=N)
    n_b = NumbaBackend(fb, truth, Ts=TS, substeps=substeps)
    x, u = X[0] + 0.1, U[0]
    with torch.no_grad():
        for a, b in zip(t_b.truth_rate_and_step(x, u), n_b.truth_rate_and_step(x, u)):
            np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)
        for a, b in zip(t_b.model_rate_and_phi(X, U), n_b.model_rate_and_phi(X, U)):
            np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)
    lin_t, lin_n = t_b.linearize(X + 0.05, U), n_b.linearize(X + 0.05, U)
    for field in ("A", "B", "c", "x_next"):
        np.testing.assert_allclose(getattr(lin_n, field), getattr(lin_t, field), rtol=0, atol=1e-10, err_msg=field)
    assert np.abs(lin_t.A - lin_n.A).max() < 1e-10 and np.abs(lin_t.A).max() > 0.9  # I + Ts (A_c + L_k) ~ I
