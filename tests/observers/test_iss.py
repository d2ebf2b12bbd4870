"""App. A.2, Eq. (25): the discrete observer error is input-to-state stable exactly when rho(I - Ts L) < 1.

The bound tested: with A = I - Ts L and ||Delta f_k|| <= gamma,
    ||x_tilde_k|| <= ||A^k|| ||x_tilde_0|| + Ts gamma sum_{j<k} ||A^j||        (any L)
and for symmetric L, ||A^j|| = rho^j, so
    ||x_tilde_k|| <= rho^k ||x_tilde_0|| + Ts gamma (1 - rho^k) / (1 - rho)
                  <= rho^k ||x_tilde_0|| + Ts gamma / (1 - rho).
Proof: unroll Eq. (25), x_tilde_k = A^k x_tilde_0 + Ts sum_{j<k} A^{k-1-j} Delta f_j, and take norms.
"""

from __future__ import annotations

import math

import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from fnnlib import LinearFeedback
from fnnlib.feedback import spectral_radius, Gains
from fnnlib.stability import discrete_residual, iss_bound

F64 = torch.float64
TS = 0.01
REL = 1e-9  # float64 round-off over a few hundred steps stays far below this


def _rotation(angle: float) -> torch.Tensor:
    c, s = math.cos(angle), math.sin(angle)
    return torch.tensor([[c, -s], [s, c]], dtype=F64)


def _symmetric_gain(lam1: float, lam2: float, angle: float) -> torch.Tensor:
    Q = _rotation(angle)
    L = Q @ torch.diag(torch.tensor([lam1, lam2], dtype=F64)) @ Q.T
    return 0.5 * (L + L.T)


def _residuals(gamma: float, steps: int, seed: int) -> torch.Tensor:
    """Random Delta f_k with ||Delta f_k|| <= gamma: random directions, random lengths, some exactly gamma."""
    g = torch.Generator().manual_seed(seed)
    d = torch.randn(steps, 2, generator=g, dtype=F64)
    d = d / d.norm(dim=-1, keepdim=True)
    r = torch.rand(steps, 1, generator=g, dtype=F64)
    r[::7] = 1.0
    return gamma * r * d


def _eq25(L: torch.Tensor, e0: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
    """Eq. (25) step by step: x_tilde_k = (I - Ts L) x_tilde_{k-1} + Ts Delta f_{k-1}; returns norms (K+1,)."""
    A = torch.eye(2, dtype=F64) - TS * L
    e, norms = e0, [e0.norm()]
    for dk in d:
        e = A @ e + TS * dk
        norms.append(e.norm())
    return torch.stack(norms)


stable_eig = st.floats(0.02 / TS, 1.98 / TS)  # rho(I - Ts L) = max |1 - Ts lambda| <= 0.98


@settings(max_examples=40, deadline=None)
@given(lam1=stable_eig, lam2=stable_eig, angle=st.floats(0.0, math.pi), gamma=st.floats(0.01, 100.0),
       e0=st.floats(0.0, 10.0), seed=st.integers(0, 2**31 - 1))
def test_symmetric_gain_error_stays_in_the_iss_bound(lam1, lam2, angle, gamma, e0, seed):
    L = _symmetric_gain(lam1, lam2, angle)
    rho = spectral_radius(torch.eye(2, dtype=F64) - TS * L)
    assert rho < 1
    K = 300
    start = e0 * (_rotation(seed % 628 / 100.0) @ torch.tensor([1.0, 0.0], dtype=F64))
    norms = _eq25(L, start, _residuals(gamma, K, seed))
    k = torch.arange(K + 1, dtype=F64)
    bound = rho**k * e0 + TS * gamma * (1 - rho**k) / (1 - rho)
    assert bool((norms <= bound * (1 + REL) + 1e-12).all())
    assert float(norms.max()) <= (e0 + TS * gamma / (1 - rho)) * (1 + REL)  # the ISS ball, uniformly in k
    # the library's general-form bound (spectral norms of A^k) is the same number for a symmetric L
    torch.testing.assert_close(iss_bound(L, TS, gamma, K + 1, e0=e0), bound, rtol=1e-9, atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(scale=st.floats(0.0, 0.97), entries=st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4),
       gamma=st.floats(0.01, 50.0), e0=st.floats(0.0, 5.0), seed=st.integers(0, 2**31 - 1))
def test_any_stable_gain_error_stays_in_the_general_bound(scale, entries, gamma, e0, seed):
    """Non-symmetric L: ||A^k|| can exceed rho^k (transient growth), the bound with ||A^j|| still holds."""
    R = torch.tensor(entries, dtype=F64).reshape(2, 2)
    rho_R = spectral_radius(R)
    A = R * (scale / rho_R) if rho_R > 1e-6 else torch.zeros(2, 2, dtype=F64)
    L = (torch.eye(2, dtype=F64) - A) / TS  # so that I - Ts L = A, rho(A) = scale < 1
    K = 200
    start = torch.tensor([e0, 0.0], dtype=F64)
    norms = _eq25(L, start, _residuals(gamma, K, seed))
    bound = iss_bound(L, TS, gamma, K + 1, e0=e0)
    assert bool((norms <= bound * (1 + REL) + 1e-10).all())


@settings(max_examples=25, deadline=None)
@given(lam1=stable_eig, lam2=stable_eig, angle=st.floats(0.0, math.pi), gamma=st.floats(0.1, 20.0),
       seed=st.integers(0, 2**31 - 1))
def test_library_observer_obeys_eq25_and_its_bound(lam1, lam2, angle, gamma, seed):
    """LinearFeedback on any measured sequence: x_tilde follows Eq. (25) with Delta f_k = (x_{k+1}-x_k)/Ts - f(x_k)."""
    L = _symmetric_gain(lam1, lam2, angle)
    rho = spectral_radius(torch.eye(2, dtype=F64) - TS * L)
    W = torch.tensor([[-0.3, 2.0], [-2.0, -0.3]], dtype=F64)

    def f(_t, z):
        return z @ W.T

    # measurements built so that the residual is a chosen bounded sequence: x_{k+1} = x_k + Ts (f(x_k) + d_k)
    d = _residuals(gamma, 250, seed)
    x = [torch.tensor([3.0, -1.0], dtype=F64)]
    for dk in d:
        x.append(x[-1] + TS * (f(0.0, x[-1][None])[0] + dk))
    x = torch.stack(x)
    est = LinearFeedback(f, TS, gains=Gains(L), n=2).observe(x)
    resid = discrete_residual(x, f(0.0, x), TS)
    torch.testing.assert_close(resid, d, rtol=0, atol=1e-9)  # 1e-9: (x_{k+1} - x_k)/Ts cancels O(1) values
    err = (x - est.x_hat).norm(dim=-1)
    torch.testing.assert_close(err, _eq25(L, torch.zeros(2, dtype=F64), d), rtol=1e-9, atol=1e-12)
    k = torch.arange(err.numel(), dtype=F64)
    gamma_d = float(resid.norm(dim=-1).max())
    assert bool((err <= TS * gamma_d * (1 - rho**k) / (1 - rho) * (1 + 1e-7) + 1e-12).all())


@settings(max_examples=30, deadline=None)
@given(rho=st.floats(1.05, 2.0), side=st.sampled_from(["above_2_over_Ts", "negative"]),
       lam_other=stable_eig, angle=st.floats(0.0, math.pi), tilt=st.floats(-1.0, 1.0), e0=st.floats(0.01, 10.0))
def test_unstable_gain_unforced_error_grows_like_rho_k(rho, side, lam_other, angle, tilt, e0):
    """rho(I - Ts L) > 1: with no residual, x_tilde_k = A^k x_tilde_0 grows like rho^k along the unstable direction."""
    lam_bad = (1 + rho) / TS if side == "above_2_over_Ts" else (1 - rho) / TS  # |1 - Ts lambda| = rho
    L = _symmetric_gain(lam_bad, lam_other, angle)
    assert abs(spectral_radius(torch.eye(2, dtype=F64) - TS * L) - rho) < 1e-9
    unstable_dir = _rotation(angle) @ torch.tensor([1.0, 0.0], dtype=F64)
    start = e0 * (_rotation(tilt) @ unstable_dir)  # within 1 rad of the unstable direction: cos >= 0.54
    K = 100
    norms = _eq25(L, start, torch.zeros(K, 2, dtype=F64))
    # exact lower bound: the unstable component alone grows by rho per step
    assert float(norms[-1]) >= e0 * math.cos(tilt) * rho**K * (1 - 1e-9)
    assert float(norms[-1]) > 50 * e0  # 0.54 * 1.05^100 = 71


def test_bound_is_attained_by_a_constant_aligned_residual():
    """Not vacuous: scalar L in (0, 1/Ts) and a constant residual reach the bound exactly at every step."""
    lam, gamma, K = 30.0, 2.0, 120
    d = torch.tensor([gamma, 0.0], dtype=F64).expand(K, 2)
    norms = _eq25(lam * torch.eye(2, dtype=F64), torch.zeros(2, dtype=F64), d)
    rho = 1 - TS * lam
    k = torch.arange(K + 1, dtype=F64)
    torch.testing.assert_close(norms, TS * gamma * (1 - rho**k) / (1 - rho), rtol=1e-12, atol=1e-15)
