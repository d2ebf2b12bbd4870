"""Open-loop neural-ODE prediction, Eq. (2): the baseline every cascade is compared to."""

from __future__ import annotations

import torch
from torch import Tensor
from torchdiffeq import odeint

from fnnlib._validation import as_trajectory, check_positive
from fnnlib.feedback.decay import check_N
from fnnlib.feedback.types import VectorField


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
    N = check_N(N)
    Ts = check_positive(Ts, name="Ts")
    x = as_trajectory(x, x.shape[-1] if isinstance(x, Tensor) else None)
    n = x.shape[-1]
    grid = torch.arange(N + 1, dtype=x.dtype) * Ts
    fixed = method in {"euler", "midpoint", "rk4"}
    kwargs = {"options": {"step_size": Ts}} if fixed else {"rtol": rtol, "atol": atol}
    sol = odeint(f, x.reshape(-1, n), grid, method=method, **kwargs)  # (N+1, M, n)
    sol = sol.reshape(N + 1, *x.shape)
    return sol if return_all else sol[-1]
