"""Multi-step prediction: the cascade of Sec. 3.3 with gain decay Eq. (11), and plain rollouts."""

from __future__ import annotations

import torch
from torch import Tensor
from torchdiffeq import odeint

from fnnlib._validation import as_trajectory, check_positive
from fnnlib.observers.gains import check_gain, decayed_gains, gain_compact
from fnnlib.observers.linear import VectorField, _times, eval_field, feedback_layer


def _check_N(N: int) -> int:
    if int(N) != N or int(N) < 1:
        raise ValueError(f"number of prediction steps N must be an integer >= 1, got {N!r}")
    return int(N)


@torch.no_grad()
def cascade_predict(f: VectorField, x: Tensor, Ts: float, N: int, L: float | Tensor, beta: float = 0.0,
                    *, return_all: bool = False, allow_unstable: bool = False) -> Tensor:
    r"""N-step prediction by the cascaded feedback network (Sec. 3.3), from every start time.

    Layer ``i`` (``i = 0 .. N-1``) is a feedback network with gain
    :math:`L_i = L e^{-\beta i}` (Eq. (11) gain decay). Its input sequence is
    the previous layer's one-step predictions :math:`z^{(i)}_k` (with
    :math:`z^{(0)}_k = x(t_k)`, the measurements); it keeps its own estimate
    :math:`\hat x^{(i)}` over time (Eq. (8)) and outputs
    :math:`z^{(i+1)}_k = z^{(i)}_k + T_s \hat f^{(i)}_k` (Eq. (7)), so
    :math:`z^{(N)}_k` predicts :math:`x(t_{k+N})`. Per layer, all start times
    are done at once: one batched network call and one linear scan.

    With ``L = 0`` this equals :func:`rollout_predict` with ``method="euler"``.

    Parameters
    ----------
    f : callable
        Learned vector field ``f(t, x)``.
    x : Tensor, shape (..., T, n)
        Measured states, one row per sample time.
    Ts : float
        Sample step (also the prediction step).
    N : int
        Prediction steps (layers).
    L : float, Tensor (n,) or (n, n)
        Base feedback gain.
    beta : float
        Decay rate of Eq. (11).
    return_all : bool
        Also return every intermediate depth.

    Returns
    -------
    Tensor
        Shape (..., T, n): row k predicts the state at ``t_{k+N}``; with
        ``return_all`` shape (N+1, ..., T, n), depth 0 being ``x`` itself.
    """
    N = _check_N(N)
    Ts = check_positive(Ts, name="Ts")
    n = x.shape[-1] if isinstance(x, Tensor) else 0
    x = as_trajectory(x, n)
    L0 = check_gain(L, n, Ts, allow_unstable=allow_unstable)
    gains = [gain_compact(Li, n, dtype=x.dtype) for Li in decayed_gains(L0, N, beta)]
    z = x
    depths = [z] if return_all else None
    for L_i in gains:
        fz = eval_field(f, z)
        _, f_hat = feedback_layer(fz, z, L_i, Ts)
        z = z + Ts * f_hat  # z^{(i+1)} = z^{(i)} + Ts * f_hat^{(i)}
        if depths is not None:
            depths.append(z)
    return torch.stack(depths) if depths is not None else z


@torch.no_grad()
def cascade_predict_loop(f: VectorField, x: Tensor, Ts: float, N: int, L: float | Tensor, beta: float = 0.0,
                         *, allow_unstable: bool = False) -> Tensor:
    """Reference implementation of :func:`cascade_predict`: loops over start times and depths.

    The streaming form a real-time system would run: at each new measurement
    ``x_k`` the N layers are evaluated one after another, each updating its
    own estimate. Quadratic in Python calls (T * N network evaluations of one
    state); kept for tests and benchmarks. ``x`` has shape (T, n).
    """
    N = _check_N(N)
    Ts = check_positive(Ts, name="Ts")
    x = as_trajectory(x, x.shape[-1] if isinstance(x, Tensor) else None)
    if x.ndim != 2:
        raise ValueError(f"the loop reference takes one trajectory of shape (T, n), got {tuple(x.shape)}")
    T, n = x.shape
    L0 = check_gain(L, n, Ts, allow_unstable=allow_unstable)
    gains = [gain_compact(Li, n, dtype=x.dtype) for Li in decayed_gains(L0, N, beta)]
    x_hat: list[Tensor] = []  # each layer's estimate, started at that layer's first input
    out = torch.empty_like(x)
    for k in range(T):
        z = x[k]
        for i in range(N):
            if k == 0:
                x_hat.append(z.clone())
            f_hat = f(0.0, z[None])[0] + _times(gains[i], z - x_hat[i])  # Eq. (7)
            x_hat[i] = x_hat[i] + Ts * f_hat  # Eq. (8)
            z = z + Ts * f_hat
        out[k] = z
    return out


@torch.no_grad()
def rollout_predict(f: VectorField, x: Tensor, Ts: float, N: int, *, method: str = "euler",
                    return_all: bool = False, rtol: float = 1e-7, atol: float = 1e-9) -> Tensor:
    """N-step open-loop neural-ODE prediction (Eq. (2)) from every sample of ``x``.

    Parameters
    ----------
    x : Tensor, shape (..., T, n)
        Start states.
    method : str
        torchdiffeq solver; ``"euler"`` steps at ``Ts`` (the discretisation
        the cascade uses), adaptive solvers integrate accurately.

    Returns
    -------
    Tensor, shape (..., T, n) (row k predicts ``t_{k+N}``), or with
    ``return_all`` (N+1, ..., T, n).
    """
    N = _check_N(N)
    Ts = check_positive(Ts, name="Ts")
    x = as_trajectory(x, x.shape[-1] if isinstance(x, Tensor) else None)
    n = x.shape[-1]
    grid = torch.arange(N + 1, dtype=x.dtype) * Ts
    fixed = method in {"euler", "midpoint", "rk4"}
    kwargs = {"options": {"step_size": Ts}} if fixed else {"rtol": rtol, "atol": atol}
    sol = odeint(f, x.reshape(-1, n), grid, method=method, **kwargs)  # (N+1, M, n)
    sol = sol.reshape(N + 1, *x.shape)
    return sol if return_all else sol[-1]
