r"""The cascade of Sec. 3.3: N feedback networks in series, gain decay Eq. (11), one or many gains at once.

Layer ``i`` (``i = 0 .. N-1``) is a feedback network (Eqs. (7)-(8)) with the
decayed gain :math:`L_i = L e^{-\beta i}`. Its input sequence is the previous
layer's one-step predictions :math:`z^{(i)}_k` (:math:`z^{(0)}_k = x(t_k)`, the
measurements); it keeps its own estimate :math:`\hat x^{(i)}` over time and
outputs :math:`z^{(i+1)}_k = z^{(i)}_k + T_s \hat f^{(i)}_k`, so :math:`z^{(N)}_k`
predicts :math:`x(t_{k+N})`. Per layer, all start times are done at once: one
batched network call and one linear scan (:func:`~fnnlib.feedback.layer.feedback_layer`).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from fnnlib._validation import as_trajectory, check_positive
from fnnlib.feedback.decay import check_N, decay_factors, decayed_gains
from fnnlib.feedback.gains import check_gain, gain_batch, gain_compact
from fnnlib.feedback.gaps import gap_cascade, start_state
from fnnlib.feedback.layer import eval_field, feedback_layer, lead_gains, shift_inputs
from fnnlib.feedback.measured import check_output_gain
from fnnlib.feedback.measurement import Measurements, check_measurements, output_matrix_at
from fnnlib.feedback.types import VectorField


def run_cascade(f: VectorField, x: Tensor, L_stack: Sequence[Tensor], Ts: float, *, diagonal: bool | None = None,
                return_all: bool = False, u: Tensor | None = None, rows: int | None = None) -> Tensor:
    """The layers of the cascade, one per decayed gain ``L_stack[i]`` (as :func:`feedback_layer` takes it).

    ``x`` (..., T, n); returns :math:`z^{(N)}` of the same shape, or with
    ``return_all`` every depth stacked, (N+1, ..., T, n), depth 0 being ``x``.
    With inputs ``u`` (..., T, m), layer ``i`` evaluates ``f(t, z, u)`` with row k's input
    ``u_{k+i}`` (:func:`~fnnlib.feedback.layer.shift_inputs`). Differentiable: gradients flow to
    the gains in ``L_stack``, to ``f``'s parameters and to ``x``.

    ``rows`` (1..T) computes only the first ``rows`` start times, (..., rows, n): every layer is causal
    in time (row k of its output reads rows <= k of its input, and the inputs ``u_{k+i}`` of the full
    sequence), so these rows are those of the whole run, at ``rows / T`` of its cost. Tuning against
    targets N samples later needs only the first ``T - N`` (:func:`~fnnlib.feedback.tuning.tune_gains`).
    """
    if rows is not None:
        if not 1 <= int(rows) <= x.shape[-2]:
            raise ValueError(f"rows must lie in 1..{x.shape[-2]} (the samples of x), got {rows!r}")
        rows = int(rows)
    z = x if rows is None else x[..., :rows, :]
    depths = [z] if return_all else None
    for i, L_i in enumerate(L_stack):
        u_i = shift_inputs(u, i)
        if u_i is not None and rows is not None:
            u_i = u_i[..., :rows, :]  # shifted on the whole sequence first: row k keeps u_{k+i}
        _, f_hat = feedback_layer(eval_field(f, z, u_i), z, L_i, Ts, diagonal=diagonal)
        z = z + Ts * f_hat  # z^{(i+1)} = z^{(i)} + Ts * f_hat^{(i)}
        if depths is not None:
            depths.append(z)
    return torch.stack(depths) if depths is not None else z


def _checked(x: Tensor, Ts: float, N: int) -> tuple[Tensor, float, int]:
    """The checks every cascade makes before any work: a finite, non-empty trajectory, Ts > 0, an integer N >= 1."""
    N = check_N(N)
    Ts = check_positive(Ts, name="Ts")
    x = as_trajectory(x, x.shape[-1] if isinstance(x, Tensor) else None)
    if x.shape[-2] == 0 or x.shape[-1] == 0:
        raise ValueError(f"x is an empty trajectory (shape {tuple(x.shape)}); give at least one sample of a "
                         "state with at least one component")
    return x, Ts, N


def _measured(f: VectorField, x: Tensor, Ts: float, N: int, n: int | None, *, C=None, u: Tensor | None = None,
              mask: Tensor | None = None) -> tuple[Measurements, float, int]:
    """The checks of a cascade on measurements that may have gaps (NaN or ``mask``), inputs and a ``C``: before any work."""
    N = check_N(N)
    Ts = check_positive(Ts, name="Ts")
    if isinstance(x, Tensor) and x.ndim >= 2 and (x.shape[-2] == 0 or x.shape[-1] == 0):
        raise ValueError(f"x is an empty trajectory (shape {tuple(x.shape)}); give at least one sample of a "
                         "state with at least one component")
    n = n if n is not None else (x.shape[-1] if isinstance(x, Tensor) else 0)
    return check_measurements(x, n, C=C, u=u, mask=mask, f=f, name="x" if C is None else "y"), Ts, N


def _state_dim(x: Tensor, C, L, f: VectorField, x0: Tensor | None) -> int | None:
    """The state dimension n: the measurements' own without ``C``, else from ``L`` (n, p), ``f.n``, ``C`` or ``x0``."""
    if C is None:
        return x.shape[-1] if isinstance(x, Tensor) else None
    L = torch.as_tensor(L)
    if L.ndim == 2:
        return int(L.shape[0])
    if getattr(f, "n", None) is not None:
        return int(f.n)
    if isinstance(C, Tensor) or not callable(C):
        return int(torch.as_tensor(C).shape[-1])
    return int(torch.as_tensor(x0).shape[-1])


@torch.no_grad()
def cascade_predict(f: VectorField, x: Tensor, Ts: float, N: int, L: float | Tensor, beta: float = 0.0,
                    *, return_all: bool = False, allow_unstable: bool = False, u: Tensor | None = None,
                    C=None, mask: Tensor | None = None, x0: Tensor | None = None, A: Tensor | None = None) -> Tensor:
    r"""N-step prediction by the cascaded feedback network (Sec. 3.3, Eq. (11)), from every start time.

    With ``L = 0`` this equals :func:`~fnnlib.rollout_predict` with ``method="euler"``.

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
        Base feedback gain (layer 0's).
    beta : float
        Decay rate of Eq. (11); 0 keeps every layer at ``L``.
    return_all : bool
        Also return every intermediate depth.
    u : Tensor, shape (..., T, m), optional
        Inputs of a controlled model ``f(t, x, u)``, one row per sample
        (the input held over the step from that sample).
    C : Tensor (p, n) or callable ``h(x)``, optional
        Partial measurements ``y = C x``: ``x`` is then ``y`` (..., T, p), ``L`` an output gain (n, p)
        (checked by :func:`~fnnlib.feedback.measured.check_output_gain`, with the Jacobian ``A`` when given),
        and every layer evaluates the field at its estimate (:mod:`fnnlib.feedback.gaps`).
    mask : Tensor of bool, shape (..., T) or (..., T, p), optional
        ``False`` where no sample was taken (a NaN in ``x`` means the same): the layers move open loop
        through the gap (:mod:`fnnlib.feedback.gaps`).
    x0 : Tensor (n,), optional
        First estimate with ``C`` (default: the least-squares state of the first sample).
    A : Tensor (n, n), optional
        The model's Jacobian (:func:`~fnnlib.feedback.measurement.model_jacobian`) for the checks with ``C``.

    Returns
    -------
    Tensor
        Shape (..., T, n): row k predicts the state at ``t_{k+N}``; with
        ``return_all`` shape (N+1, ..., T, n), depth 0 being ``x`` itself.
    """
    n = _state_dim(x, C, L, f, x0)
    meas, Ts, N = _measured(f, x, Ts, N, n, C=C, u=u, mask=mask)
    if C is None:
        L = check_gain(L, n, Ts, allow_unstable=allow_unstable, N=N, beta=beta)  # warns on strong noise amplification
        L_stack = [gain_compact(L_i, n, dtype=x.dtype) for L_i in decayed_gains(L, N, beta)]
        if meas.mask is None:  # no gap: the paper's cascade, one scan per layer
            return run_cascade(f, x, L_stack, Ts, return_all=return_all, u=u)
    else:
        C_lin = output_matrix_at(meas, start_state(meas, n, x0)[(0,) * (meas.y.ndim - 2)])
        L, _ = check_output_gain(L, C_lin, Ts, A=A, allow_unstable=allow_unstable)
        L_stack = [L_i.to(x.dtype) for L_i in decayed_gains(L, N, beta)]
    return gap_cascade(f, meas, L_stack, Ts, n, x0=x0, return_all=return_all)


@torch.no_grad()
def cascade_sweep(f: VectorField, x: Tensor, Ts: float, N: int, L: float | Sequence[float] | Tensor,
                  beta: float | Sequence[float] | Tensor = 0.0, *, allow_unstable: bool = False,
                  u: Tensor | None = None, mask: Tensor | None = None, C=None, x0: Tensor | None = None,
                  A: Tensor | None = None) -> Tensor:
    r"""The N-step cascade for a batch of (base gain, decay rate) pairs in one pass.

    Batch element ``g`` runs :func:`cascade_predict` with gain ``L_g`` and
    decay rate ``beta_g``: layer ``i`` uses :math:`L_g e^{-\beta_g i}`. Gains and
    decay rates pair up by broadcasting (one of either, or as many of each).
    The ablations of Sec. 3.4 and App. A.3 sweep gains and decay rates this way.

    Parameters
    ----------
    f : callable
        Learned vector field ``f(t, x)``.
    x : Tensor, shape (..., T, n)
        Measurements (any leading axes: levels, noise draws).
    Ts : float
        Sample step (also the prediction step).
    N : int
        Prediction steps (layers).
    L : float, Tensor (G,) or Tensor (G, n)
        Scalar or diagonal base gains.
    beta : float or Tensor (G,)
        Decay rates of Eq. (11).
    u : Tensor, shape (..., T, m), optional
        Inputs of a controlled model, as :func:`cascade_predict` takes them.
    mask : Tensor of bool, shape (..., T) or (..., T, n), optional
        Missing samples (or NaN in ``x``), as :func:`cascade_predict` takes them.
    C, x0, A : optional
        Partial measurements ``y = C x``, as :func:`cascade_predict` takes them: ``x`` is then ``y``
        (..., T, p) and ``L`` output gains (n, p) or (G, n, p); each pair runs :func:`cascade_predict`
        (its checks included), one after another.

    Returns
    -------
    Tensor, shape (G, ..., T, n)
        Row ``k`` predicts the state at ``t_{k+N}``.
    """
    if C is not None:
        return _output_sweep(f, x, Ts, N, L, beta, allow_unstable=allow_unstable, u=u, mask=mask, C=C, x0=x0, A=A)
    meas, Ts, N = _measured(f, x, Ts, N, None, u=u, mask=mask)
    n = x.shape[-1]
    L = gain_batch(L, n, Ts, allow_unstable=allow_unstable).to(x.dtype)  # (G, n) base gains
    decay = decay_factors(beta, N)  # (B, N)
    G, B = L.shape[0], decay.shape[0]
    if B != 1 and G != 1 and B != G:
        raise ValueError(f"{G} gains and {B} decay rates do not pair up (give one of either, or as many)")
    G = max(G, B)
    L = L.expand(G, n)
    L_stack = [lead_gains(L * decay[:, i].to(x.dtype)[:, None], x.ndim + 1) for i in range(N)]  # Eq. (11)
    if meas.mask is None:
        return run_cascade(f, x.expand(G, *x.shape), L_stack, Ts, diagonal=True, u=u)
    meas = meas._replace(y=meas.y.expand(G, *x.shape), mask=meas.mask.expand(G, *x.shape))
    return gap_cascade(f, meas, L_stack, Ts, n, diagonal=True)


def _output_sweep(f: VectorField, x: Tensor, Ts: float, N: int, L, beta, **kw) -> Tensor:
    """:func:`cascade_sweep` with ``C``: output gains ``L`` (n, p) or (G, n, p) paired with ``beta`` (B,) by
    broadcasting, each pair through :func:`cascade_predict`; returns (G, ..., T, n)."""
    L = torch.as_tensor(L, dtype=torch.float64)
    if L.ndim == 2:
        L = L[None]
    if L.ndim != 3:
        raise ValueError(f"with C, L must be an output gain (n, p) or a batch (G, n, p), got shape {tuple(L.shape)}")
    beta = torch.as_tensor(beta, dtype=torch.float64).reshape(-1)
    G, B = L.shape[0], beta.shape[0]
    if B != 1 and G != 1 and B != G:
        raise ValueError(f"{G} gains and {B} decay rates do not pair up (give one of either, or as many)")
    G = max(G, B)
    L, beta = L.expand(G, *L.shape[1:]), beta.expand(G)
    return torch.stack([cascade_predict(f, x, Ts, N, L[g], float(beta[g]), **kw) for g in range(G)])


@torch.no_grad()
def cascade_predict_loop(f: VectorField, x: Tensor, Ts: float, N: int, L: float | Tensor, beta: float = 0.0,
                         *, allow_unstable: bool = False) -> Tensor:
    """Reference implementation of :func:`cascade_predict`: loops over start times and depths.

    The streaming form a real-time system would run: at each new measurement
    ``x_k`` the N layers are evaluated one after another, each updating its
    own estimate. Quadratic in Python calls (T * N network evaluations of one
    state); kept for tests and benchmarks. ``x`` has shape (T, n).
    """
    x, Ts, N = _checked(x, Ts, N)
    if x.ndim != 2:
        raise ValueError(f"the loop reference takes one trajectory of shape (T, n), got {tuple(x.shape)}")
    T, n = x.shape
    L = check_gain(L, n, Ts, allow_unstable=allow_unstable)
    L_stack = [gain_compact(L_i, n, dtype=x.dtype) for L_i in decayed_gains(L, N, beta)]
    x_hat: list[Tensor] = []  # each layer's estimate, started at that layer's first input
    out = torch.empty_like(x)
    for k in range(T):
        z = x[k]
        for i in range(N):
            if k == 0:
                x_hat.append(z.clone())
            e = z - x_hat[i]
            f_hat = f(0.0, z[None])[0] + (L_stack[i] * e if L_stack[i].ndim == 1 else L_stack[i] @ e)  # Eq. (7)
            x_hat[i] = x_hat[i] + Ts * f_hat  # Eq. (8)
            z = z + Ts * f_hat
        out[k] = z
    return out
