r"""Compiled (numba) kernels for the per-step work of the Sec. 5.2 MPC: Eq. (27) with a tanh residual network.

The torch code (:class:`~fnnlib.quadrotor.system.Quadrotor`, the models of
:mod:`fnnlib.quadrotor.mpc.models` and :func:`~fnnlib.quadrotor.mpc.linearize.linearize`) is the
reference implementation; this module is its declared reference twin (the
:class:`~fnnlib.quadrotor.mpc.backends.NumbaBackend` of the flight loop) for the one place where
per-op overhead, not arithmetic, sets the cost: the MPC loop, which at every
0.02 s step evaluates the model along a 10-step plan, linearizes it there and
simulates the vehicle, all on batches of 1 to 170 rows. Eager torch spends
~10 us per op on such batches; here each call is one compiled loop.

What is computed, for a plant ``params`` and a residual network
:math:`f_{neural}(v, \Theta)` (``tanh`` hidden layers, linear last layer, as
:class:`~fnnlib.quadrotor.residual.AeroResidual` and :class:`~fnnlib.quadrotor.residual.AdaptiveResidual`):

* :meth:`CompiledQuadrotor.f`: :math:`\dot x = f(x, u) + [0, f_{neural}, 0, 0]`, Eq. (27);
* :meth:`CompiledQuadrotor.step`: :math:`\Phi(x, u)`, classical RK4 over ``Ts``;
* :meth:`CompiledQuadrotor.step_jacobian`: :math:`\Phi` and its exact Jacobians
  :math:`A = \partial\Phi/\partial x`, :math:`B = \partial\Phi/\partial u` by forward-mode
  differentiation through the RK4 stages, with the analytic Jacobian of Eq. (27)
  and a reverse pass through the network at every stage.

Every kernel is checked against the torch reference in ``tests/quadrotor/mpc/test_compiled.py``
(values to 1e-13, Jacobians against torch autograd to 1e-10).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numba as nb
import numpy as np
import torch
from torch import Tensor, nn

from fnnlib.quadrotor.residual import AdaptiveResidual, AeroResidual
from fnnlib.quadrotor.mpc.linearize import Linearization, affine_model
from fnnlib.quadrotor.mpc.models import PredictionModel
from fnnlib.systems.integrator import check_step
from fnnlib.quadrotor.presets import PAPER_RESIDUAL_RECIPE
from fnnlib.quadrotor.system import NOMINAL, Quadrotor, constants

__all__ = ["CompiledModel", "CompiledQuadrotor", "residual_layers", "warm_up"]

_JIT: dict[str, Any] = {"cache": True, "nogil": True, "error_model": "numpy"}
# reassociation and fused multiply-add let the network's dot products vectorize (results move by ~1e-16)
_FAST: dict[str, Any] = {**_JIT, "fastmath": {"reassoc", "contract", "nsz"}}

# layout of the packed plant constants P (float64)
_S_T, _A0, _D, _J = 0, 16, 19, 22  # S_T (4x4 row-major: u @ S_T = [T/m, tau/J]), a0 = g e3 + F/m, drag, inertia
_NP = 25


# --------------------------------------------------------------------------- kernels


@nb.njit(**_FAST)
def _residual(y, Ws, bs, H, r, G, want_jac):  # pragma: no cover - compiled
    """f_neural(v, Theta) into r (3,); with want_jac its Jacobian (3, 6) into G[:3, :6] (reverse pass)."""
    L = len(Ws)
    for j in range(6):
        H[0, j] = y[3 + j]
    for layer in range(L):
        W = Ws[layer]
        b = bs[layer]
        n_out, n_in = W.shape
        for i in range(n_out):
            s = b[i]
            for j in range(n_in):
                s += W[i, j] * H[layer, j]
            if layer < L - 1:
                H[layer + 1, i] = math.tanh(s)
            else:
                r[i] = s
    if not want_jac:
        return
    # G = W_L diag(1 - h_{L-1}^2) W_{L-1} ... diag(1 - h_1^2) W_1, carried as rows of the output
    W = Ws[L - 1]
    width = W.shape[1]
    for i in range(3):
        for j in range(width):
            G[i, j] = W[i, j]
    for layer in range(L - 2, -1, -1):
        W = Ws[layer]
        n_out, n_in = W.shape
        for i in range(3):
            for j in range(n_out):
                G[i, j] *= 1.0 - H[layer + 1, j] ** 2
        for i in range(3):  # G[i] <- G[i] W, row by row (contiguous inner loop)
            for c in range(n_in):
                G[3 + i, c] = 0.0
            for j in range(n_out):
                g = G[i, j]
                for c in range(n_in):
                    G[3 + i, c] += g * W[j, c]
        for i in range(3):
            for c in range(n_in):
                G[i, c] = G[3 + i, c]


@nb.njit(**_JIT)
def _rhs(y, u, P, Ws, bs, H, G, has_res, k, Jm, want_jac):  # pragma: no cover - compiled
    """Eq. (27) at one (y, u) into k (12,); with want_jac its Jacobian [df/dx, df/du] (12, 16) into Jm."""
    v0, v1, v2 = y[3], y[4], y[5]
    w0, w1, w2 = y[9], y[10], y[11]
    cf, sf = math.cos(y[6]), math.sin(y[6])
    ct, st = math.cos(y[7]), math.sin(y[7])
    cp, sp = math.cos(y[8]), math.sin(y[8])
    # R = Rz(psi) Ry(theta) Rx(phi)
    R = np.empty((3, 3))
    R[0, 0], R[0, 1], R[0, 2] = cp * ct, cp * st * sf - sp * cf, cp * st * cf + sp * sf
    R[1, 0], R[1, 1], R[1, 2] = sp * ct, sp * st * sf + cp * cf, sp * st * cf - cp * sf
    R[2, 0], R[2, 1], R[2, 2] = -st, ct * sf, ct * cf
    s = np.zeros(4)  # [T/m, tau/J]
    for i in range(4):
        for j in range(4):
            s[i] += u[j] * P[_S_T + 4 * j + i]
    # b = D R^T v (body-frame drag), drag acceleration = R b
    b = np.empty(3)
    for i in range(3):
        b[i] = P[_D + i] * (R[0, i] * v0 + R[1, i] * v1 + R[2, i] * v2)
    r = np.zeros(3)
    if has_res:
        _residual(y, Ws, bs, H, r, G, want_jac)
    k[0], k[1], k[2] = v0, v1, v2
    for i in range(3):
        k[3 + i] = P[_A0 + i] - s[0] * R[i, 2] - (R[i, 0] * b[0] + R[i, 1] * b[1] + R[i, 2] * b[2]) + r[i]
    q = sf * w1 + cf * w2  # Theta' = W(Theta) omega
    p1 = cf * w1 - sf * w2
    k[6] = w0 + q * st / ct
    k[7] = p1
    k[8] = q / ct
    J0, J1, J2 = P[_J], P[_J + 1], P[_J + 2]
    c0, c1, c2 = (J2 - J1) / J0, (J0 - J2) / J1, (J1 - J0) / J2  # omega' = tau/J - (omega x J omega)/J
    k[9] = s[1] - c0 * w1 * w2
    k[10] = s[2] - c1 * w2 * w0
    k[11] = s[3] - c2 * w0 * w1
    if not want_jac:
        return
    Jm[:, :] = 0.0
    for i in range(3):
        Jm[i, 3 + i] = 1.0
    # dR/dphi = R [e1]x, dR/dtheta, dR/dpsi = [e3]x R
    M = np.empty((3, 3, 3))
    for i in range(3):
        M[0, i, 0], M[0, i, 1], M[0, i, 2] = 0.0, R[i, 2], -R[i, 1]
    M[1, 0, 0], M[1, 0, 1], M[1, 0, 2] = -cp * st, cp * ct * sf, cp * ct * cf
    M[1, 1, 0], M[1, 1, 1], M[1, 1, 2] = -sp * st, sp * ct * sf, sp * ct * cf
    M[1, 2, 0], M[1, 2, 1], M[1, 2, 2] = -ct, -st * sf, -st * cf
    for j in range(3):
        M[2, 0, j], M[2, 1, j], M[2, 2, j] = -R[1, j], R[0, j], 0.0
    v = y[3:6]
    for i in range(3):
        # d v'/d v = -R D R^T (+ the network's)
        for j in range(3):
            acc = 0.0
            for c in range(3):
                acc += R[i, c] * P[_D + c] * R[j, c]
            Jm[3 + i, 3 + j] = -acc
        # d v'/d Theta_a = -T/m dR/da e3 - (dR/da) b - R D (dR/da)^T v
        for a in range(3):
            acc = s[0] * M[a, i, 2]
            for c in range(3):
                acc += M[a, i, c] * b[c]
                acc += R[i, c] * P[_D + c] * (M[a, 0, c] * v[0] + M[a, 1, c] * v[1] + M[a, 2, c] * v[2])
            Jm[3 + i, 6 + a] = -acc
        for j in range(4):
            Jm[3 + i, 12 + j] = -P[_S_T + 4 * j] * R[i, 2]
    if has_res:
        for i in range(3):
            for j in range(6):
                Jm[3 + i, 3 + j] += G[i, j]
    tt = st / ct
    Jm[6, 6], Jm[6, 7] = p1 * tt, q / (ct * ct)
    Jm[6, 9], Jm[6, 10], Jm[6, 11] = 1.0, sf * tt, cf * tt
    Jm[7, 6] = -q
    Jm[7, 10], Jm[7, 11] = cf, -sf
    Jm[8, 6], Jm[8, 7] = p1 / ct, q * st / (ct * ct)
    Jm[8, 10], Jm[8, 11] = sf / ct, cf / ct
    Jm[9, 10], Jm[9, 11] = -c0 * w2, -c0 * w1
    Jm[10, 9], Jm[10, 11] = -c1 * w2, -c1 * w0
    Jm[11, 9], Jm[11, 10] = -c2 * w1, -c2 * w0
    for i in range(3):
        for j in range(4):
            Jm[9 + i, 12 + j] = P[_S_T + 4 * j + 1 + i]


def _buffers(Ws: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
    width = max([6] + [W.shape[0] for W in Ws] + [W.shape[1] for W in Ws])
    return np.zeros((len(Ws) + 1, width)), np.zeros((6, width))


@nb.njit(**_JIT)
def _f_batch(X, U, P, Ws, bs, has_res, H, G, out):  # pragma: no cover - compiled
    Jm = np.empty((12, 16))
    for row in range(X.shape[0]):
        _rhs(X[row], U[row], P, Ws, bs, H, G, has_res, out[row], Jm, False)


@nb.njit(**_JIT)
def _rk4_batch(X, U, Ts, substeps, P, Ws, bs, has_res, H, G, out, rate):  # pragma: no cover - compiled
    """One RK4 step of length Ts (``substeps`` equal sub-steps) per row, as :func:`fnnlib.systems.integrator.rk4`.

    ``rate`` receives the first stage, f(x, u) at the start of the step.
    """
    h = Ts / substeps
    Jm = np.empty((12, 16))
    k1, k2, k3, k4 = np.empty(12), np.empty(12), np.empty(12), np.empty(12)
    y, z = np.empty(12), np.empty(12)
    for row in range(X.shape[0]):
        u = U[row]
        y[:] = X[row]
        for sub in range(substeps):
            _rhs(y, u, P, Ws, bs, H, G, has_res, k1, Jm, False)
            if sub == 0:
                rate[row] = k1
            for i in range(12):
                z[i] = y[i] + 0.5 * h * k1[i]
            _rhs(z, u, P, Ws, bs, H, G, has_res, k2, Jm, False)
            for i in range(12):
                z[i] = y[i] + 0.5 * h * k2[i]
            _rhs(z, u, P, Ws, bs, H, G, has_res, k3, Jm, False)
            for i in range(12):
                z[i] = y[i] + h * k3[i]
            _rhs(z, u, P, Ws, bs, H, G, has_res, k4, Jm, False)
            for i in range(12):
                y[i] = y[i] + h / 6.0 * ((k1[i] + k4[i]) + 2.0 * (k2[i] + k3[i]))
        out[row] = y


@nb.njit(**_FAST)
def _stage(z, Z, u, P, Ws, bs, has_res, H, G, k, K, Jm):  # pragma: no cover - compiled
    """k = f(z, u) and its tangent K = df/dx Z + df/du [0 I] (12, 16) for the stage state's tangent Z."""
    _rhs(z, u, P, Ws, bs, H, G, has_res, k, Jm, True)
    for i in range(12):
        for d in range(12):
            K[i, d] = 0.0
        for d in range(12, 16):
            K[i, d] = Jm[i, d]
        for c in range(12):
            a = Jm[i, c]
            if a != 0.0:  # df/dx is sparse (about half zeros)
                for d in range(16):
                    K[i, d] += a * Z[c, d]


@nb.njit(**_JIT)
def _rk4_jac_batch(X, U, Ts, substeps, P, Ws, bs, has_res, H, G, out, A, B):  # pragma: no cover - compiled
    """RK4 step per row and its exact Jacobians, forward mode: the tangent of (x, u) carried through every stage."""
    h = Ts / substeps
    Jm = np.empty((12, 16))
    k1, k2, k3, k4 = np.empty(12), np.empty(12), np.empty(12), np.empty(12)
    K1, K2, K3, K4 = np.empty((12, 16)), np.empty((12, 16)), np.empty((12, 16)), np.empty((12, 16))
    y, z = np.empty(12), np.empty(12)
    Y, Z = np.empty((12, 16)), np.empty((12, 16))
    for row in range(X.shape[0]):
        u = U[row]
        y[:] = X[row]
        Y[:, :] = 0.0
        for i in range(12):
            Y[i, i] = 1.0
        for _ in range(substeps):
            _stage(y, Y, u, P, Ws, bs, has_res, H, G, k1, K1, Jm)
            for i in range(12):
                z[i] = y[i] + 0.5 * h * k1[i]
                for d in range(16):
                    Z[i, d] = Y[i, d] + 0.5 * h * K1[i, d]
            _stage(z, Z, u, P, Ws, bs, has_res, H, G, k2, K2, Jm)
            for i in range(12):
                z[i] = y[i] + 0.5 * h * k2[i]
                for d in range(16):
                    Z[i, d] = Y[i, d] + 0.5 * h * K2[i, d]
            _stage(z, Z, u, P, Ws, bs, has_res, H, G, k3, K3, Jm)
            for i in range(12):
                z[i] = y[i] + h * k3[i]
                for d in range(16):
                    Z[i, d] = Y[i, d] + h * K3[i, d]
            _stage(z, Z, u, P, Ws, bs, has_res, H, G, k4, K4, Jm)
            for i in range(12):
                y[i] = y[i] + h / 6.0 * ((k1[i] + k4[i]) + 2.0 * (k2[i] + k3[i]))
                for d in range(16):
                    Y[i, d] = Y[i, d] + h / 6.0 * ((K1[i, d] + K4[i, d]) + 2.0 * (K2[i, d] + K3[i, d]))
        out[row] = y
        A[row] = Y[:, :12]
        B[row] = Y[:, 12:]


# --------------------------------------------------------------------------- the Python side


def residual_layers(residual: nn.Module | None) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    r"""The residual network's current weights and biases as float64 arrays, first layer first.

    :class:`~fnnlib.quadrotor.residual.AeroResidual`: its linear layers. :class:`~fnnlib.quadrotor.residual.AdaptiveResidual`:
    the frozen front layers, then :math:`\hat\chi` (as adapted so far, Eq. (30)) and the fixed bias.
    The arrays are views of the network's tensors (float64, CPU, contiguous, else ``TypeError``), so
    in-place updates (Eq. (30)'s adaptation, ``load_state_dict``) are seen. ``None``: no residual (empty tuples).

    Raises
    ------
    TypeError
        For another kind of network or an activation other than ``tanh`` (use the torch reference).
    """
    if residual is None:
        return (), ()
    if isinstance(residual, AeroResidual):
        body, last_W, last_b = residual.net[:-1], residual.last.weight, residual.last.bias
    elif isinstance(residual, AdaptiveResidual):
        body, last_W, last_b = residual.front, residual.chi_hat, residual.b
    else:
        raise TypeError(f"the compiled kernels take an AeroResidual or AdaptiveResidual, got {type(residual).__name__}")
    Ws, bs = [], []
    for i, layer in enumerate(body):
        if i % 2 == 1:
            if not isinstance(layer, nn.Tanh):
                raise TypeError(f"the compiled kernels support tanh hidden layers only, got {type(layer).__name__} "
                                "(use the torch reference)")
            continue
        Ws.append(layer.weight)
        bs.append(layer.bias)
    Ws.append(last_W)
    bs.append(last_b)
    for t in (*Ws, *bs):
        if t.dtype != torch.float64 or t.device.type != "cpu" or not t.is_contiguous():
            raise TypeError(f"the compiled kernels read the network's float64 CPU tensors in place; got {t.dtype} on "
                            f"{t.device} (call .double() on the network first)")
    as_np = lambda t: t.detach().numpy()  # noqa: E731  (views: in-place updates are seen)
    return tuple(as_np(W) for W in Ws), tuple(as_np(b) for b in bs)


def pack_params(plant: Quadrotor) -> np.ndarray:
    """The plant constants the kernels read (S_T, a0, drag, inertia), packed float64 (25,)."""
    k = constants(plant.params, torch.float64, torch.device("cpu"))
    P = np.concatenate([k.S_T.numpy().ravel(), k.a0.numpy(), k.D.numpy(), k.J.numpy()])
    assert P.shape == (_NP,)
    return P


# Typed stand-in when there is no residual (never evaluated). Numba compiles the kernels once per tuple length,
# so the stand-in is as deep as the paper's residual networks (two hidden layers and the last, App. A.5.2): the
# plant alone and the paper's networks share one compilation (~8 s on a fresh cache) instead of two.
_DUMMY_DEPTH = len(PAPER_RESIDUAL_RECIPE["hidden"]) + 1
_DUMMY = ((np.zeros((3, 6)),) * _DUMMY_DEPTH, (np.zeros(3),) * _DUMMY_DEPTH)


class CompiledQuadrotor:
    r"""Eq. (27) of a :class:`~fnnlib.quadrotor.system.Quadrotor` plus an optional residual network, compiled.

    The numba twin of ``plant.f(x, u, a_res=residual(x))`` and of its RK4 step
    ``plant.step(x, u, Ts, substeps, a_res_fn=residual)``, for float64 numpy
    batches, with exact step Jacobians. The residual's weights are read at
    every call through views of its tensors, so an :class:`~fnnlib.quadrotor.residual.AdaptiveResidual`
    adapting online is seen as it is now (build a new one after replacing the
    network's tensors, e.g. by ``.to()``).

    Parameters
    ----------
    plant : Quadrotor
    residual : AeroResidual or AdaptiveResidual, optional
        A tanh network (see :func:`residual_layers`); ``None`` for the plant alone.
    """

    def __init__(self, plant: Quadrotor, residual: nn.Module | None = None) -> None:
        if not isinstance(plant, Quadrotor):
            raise TypeError(f"plant must be a Quadrotor, got {type(plant).__name__}")
        self.plant = plant
        self.residual = residual
        self.P = pack_params(plant)
        Ws, bs = residual_layers(residual)  # fails early on an unsupported network
        # (weights, biases, has_res): views of the network's tensors, so in-place updates are seen
        self._net = (Ws, bs, True) if Ws else (_DUMMY[0], _DUMMY[1], False)
        self._H, self._G = _buffers(self._net[0])

    @staticmethod
    def _inputs(x: np.ndarray | Tensor, u: np.ndarray | Tensor) -> tuple[np.ndarray, np.ndarray, bool]:
        as_np = lambda a: a.detach().numpy() if isinstance(a, Tensor) else np.asarray(a)  # noqa: E731
        X, U = as_np(x), as_np(u)
        single = X.ndim == 1
        X, U = np.atleast_2d(X), np.atleast_2d(U)
        if X.ndim != 2 or X.shape[1] != 12 or U.ndim != 2 or U.shape[1] != 4:
            raise ValueError(f"x must have shape (B, 12) or (12,) and u (B, 4) or (4,); got {X.shape} and {U.shape}")
        if U.shape[0] != X.shape[0]:
            if U.shape[0] != 1:
                raise ValueError(f"x and u must have the same number of rows, got {X.shape[0]} and {U.shape[0]}")
            U = np.broadcast_to(U, (X.shape[0], 4))
        X = np.ascontiguousarray(X, dtype=np.float64)
        U = np.ascontiguousarray(U, dtype=np.float64)
        if not (np.isfinite(X).all() and np.isfinite(U).all()):
            raise ValueError("x or u holds a NaN or infinite value; refusing to evaluate the model there")
        return X, U, single

    def f(self, x: np.ndarray | Tensor, u: np.ndarray | Tensor) -> np.ndarray:
        """Change rate ``f(x, u) + [0, f_neural, 0, 0]``: (B, 12) or (12,), like ``x``."""
        X, U, single = self._inputs(x, u)
        Ws, bs, has_res = self._net
        out = np.empty_like(X)
        _f_batch(X, U, self.P, Ws, bs, has_res, self._H, self._G, out)
        return out[0] if single else out

    def step(self, x: np.ndarray | Tensor, u: np.ndarray | Tensor, Ts: float, substeps: int = 1) -> np.ndarray:
        r""":math:`\Phi(x, u)`: one RK4 step of length ``Ts`` in ``substeps`` sub-steps, the input held."""
        return self.rate_and_step(x, u, Ts, substeps)[1]

    def rate_and_step(self, x: np.ndarray | Tensor, u: np.ndarray | Tensor, Ts: float,
                      substeps: int = 1) -> tuple[np.ndarray, np.ndarray]:
        r"""``(f(x, u), Phi(x, u))`` in one pass: the change rate is the RK4 step's first stage."""
        X, U, single = self._inputs(x, u)
        Ts, substeps = _check_step(Ts, substeps)
        Ws, bs, has_res = self._net
        out, rate = np.empty_like(X), np.empty_like(X)
        _rk4_batch(X, U, Ts, substeps, self.P, Ws, bs, has_res, self._H, self._G, out, rate)
        return (rate[0], out[0]) if single else (rate, out)

    def step_jacobian(self, x: np.ndarray | Tensor, u: np.ndarray | Tensor, Ts: float,
                      substeps: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r""":math:`\Phi(x, u)` (B, 12) with :math:`A = \partial\Phi/\partial x` (B, 12, 12) and
        :math:`B = \partial\Phi/\partial u` (B, 12, 4), exact (forward mode through the RK4 stages)."""
        X, U, _ = self._inputs(x, u)
        return self._step_jacobian(X, U, *_check_step(Ts, substeps))

    def _step_jacobian(self, X: np.ndarray, U: np.ndarray, Ts: float,
                       substeps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        Ws, bs, has_res = self._net
        out = np.empty_like(X)
        A = np.empty((X.shape[0], 12, 12))
        B = np.empty((X.shape[0], 12, 4))
        _rk4_jac_batch(X, U, Ts, substeps, self.P, Ws, bs, has_res, self._H, self._G, out, A, B)
        return out, A, B


class CompiledModel:
    r"""A prediction model of :mod:`fnnlib.quadrotor.mpc.models` with its per-step numerics compiled.

    :meth:`f` and :meth:`phi` are the model's ``f`` and ``phi`` (nominal plant plus residual, RK4);
    :meth:`linearize` is :func:`~fnnlib.quadrotor.mpc.linearize.linearize` of ``model.step`` at horizon steps
    ``k = 0 .. N-1``, with exact Jacobians: those of :math:`\Phi` from :meth:`CompiledQuadrotor.step_jacobian`
    and, for the feedback cascade, the correction of Eqs. (7), (11) added in closed form
    (:meth:`~fnnlib.quadrotor.mpc.models.PredictionModel.feedback_terms`):

    .. math:: A_k = \partial\Phi/\partial x + T_s L_k, \qquad
              x_{k+1} = \Phi(\bar x_k, \bar u_k) + T_s L_k (\bar x_k - \hat x^{(k)}).

    The model's online state (the cascade's :math:`\hat x^{(k)}`, the adaptive :math:`\hat\chi`) is read
    at every call; its hooks (``observe``, ``commit``) stay the torch ones.
    """

    def __init__(self, model: PredictionModel) -> None:
        if not isinstance(model, PredictionModel):
            raise TypeError(f"model must be a PredictionModel, got {type(model).__name__}")
        self.model = model
        self.dynamics = CompiledQuadrotor(model.plant, model.residual)  # type: ignore[arg-type]
        self.Ts, self.substeps = float(model.Ts), int(model.substeps)

    def f(self, x: np.ndarray | Tensor, u: np.ndarray | Tensor) -> np.ndarray:
        """The model's change rate (no feedback), as ``model.f``."""
        return self.dynamics.f(x, u)

    def phi(self, x: np.ndarray | Tensor, u: np.ndarray | Tensor) -> np.ndarray:
        r""":math:`\Phi(x, u)`, as ``model.phi``."""
        return self.dynamics.step(x, u, self.Ts, self.substeps)

    def f_and_phi(self, x: np.ndarray | Tensor, u: np.ndarray | Tensor) -> tuple[np.ndarray, np.ndarray]:
        r"""``(model.f(x, u), model.phi(x, u))`` in one pass."""
        return self.dynamics.rate_and_step(x, u, self.Ts, self.substeps)

    def linearize(self, x_bar: np.ndarray | Tensor, u_bar: np.ndarray | Tensor) -> Linearization:
        """Affine model of ``model.step`` along the plan, horizon steps ``k = 0 .. N-1`` (see the class docstring).

        Raises ``ValueError`` where it is not finite, as :func:`~fnnlib.quadrotor.mpc.linearize.linearize` does.
        """
        X, U, _ = CompiledQuadrotor._inputs(x_bar, u_bar)
        x_next, A, B = self.dynamics._step_jacobian(X, U, self.Ts, self.substeps)
        terms = self.model.feedback_terms()
        if terms is not None:
            G = terms[0].numpy()
            if G.shape[0] < X.shape[0]:
                raise ValueError(f"the plan has {X.shape[0]} points but the cascade only {G.shape[0]} layers")
            G, e = G[:X.shape[0]], X - terms[1].numpy()[:X.shape[0]]
            A += G
            x_next += np.einsum("kij,kj->ki", G, e)
        return affine_model(A, B, x_next, X, U)


_WARM_UP_TS = 0.01  # any step: numba compiles per argument type, not value


def warm_up(*residuals: nn.Module | None) -> float:
    """Compile (or load from numba's cache) every kernel for the plant alone and for each residual's depth.

    Numba compiles a kernel at its first call, per argument types (the number of network layers is
    one of them): ~30 s on a fresh cache, ~0.5 s to load a cached one. Call this before timing a loop.

    Returns
    -------
    float
        Seconds it took.
    """
    tic = time.perf_counter()
    plant = Quadrotor(NOMINAL)
    x, u = np.zeros((1, 12)), plant.hover_input().numpy()[None]
    for residual in (None, *residuals):
        cq = CompiledQuadrotor(plant, residual)
        cq.f(x, u)
        cq.rate_and_step(x, u, _WARM_UP_TS)
        cq.step_jacobian(x, u, _WARM_UP_TS)
    return time.perf_counter() - tic


def _check_step(Ts: float, substeps: int) -> tuple[float, int]:
    """:func:`~fnnlib.systems.integrator.check_step`, taking numpy scalars too."""
    return check_step(float(Ts) if isinstance(Ts, np.floating) else Ts, substeps)
