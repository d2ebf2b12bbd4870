r"""Eqs. (7)-(8) through missing samples and on partial measurements ``y = C x``, batched over time.

Where a sample is missing the feedback term is zero and the estimate moves open loop,
:math:`\hat x_{k+1} = \hat x_k + \Delta_k f_{neural}(\hat x_k, u_k)`; it is corrected again when data return.

* Every state measured: :math:`\hat f_k = f_{neural}(\tilde z_k) + L(\tilde z_k - \hat x_k)` with
  :math:`\tilde z_k` the input where present and :math:`\hat x_k` where missing (per component); the layer
  outputs :math:`\tilde z_k + \Delta_k \hat f_k`. With no gap this is the paper's layer exactly.
* Partial measurements (:math:`y = Cx` or :math:`h(x)`): the field is evaluated at the estimate,
  :math:`\hat f_k = f_{neural}(\hat x_k) + L(y_k - C\hat x_k)` (gaps: that error set to 0), a discrete
  Luenberger observer on the learned model, and the layer outputs :math:`\hat x_{k+1}`.

Either way the estimate obeys a nonlinear recursion :math:`\hat x_{k+1} = g_k(\hat x_k)`, which
:func:`solve_layer` solves for all k at once by Newton's method on the whole sequence: each iteration
linearises every step around the current sequence, :math:`\hat x^{new}_{k+1} = g_k(\hat x_k) +
J_k(\hat x^{new}_k - \hat x_k)`, and solves that time-varying linear recursion with the doubling scan
(:func:`~fnnlib._scan.varying_recurrence`): one batched network call and one batched Jacobian per
iteration instead of T sequential calls. For a stable gain the error dynamics contract (Theorem 1, and its
output-feedback analogue checked by :func:`~fnnlib.feedback.measured.check_output_gain`), so the iterations
converge in a handful of steps from a good guess (measured by ``benchmarks/bench_measured.py``). From a
poor guess the linearised recursion can expand over thousands of steps, so long records are solved 1024 rows
at a time; Newton's method on a sequence is exact on its first j steps after j iterations, so it cannot run
forever: a chunk that has not converged after ``max_iter`` iterations is solved in pieces of 64 rows. :func:`layer_loop` is the
sequential reference the tests compare against (to 1e-10 in float64).

Gradients: the solution is found without autograd; one more linearised step at the solution, with the
Jacobians held fixed, carries the exact gradient (implicit differentiation: at the fixed point the
Jacobian's own derivative multiplies a zero step), so tuning and training through the layer are exact.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from fnnlib._scan import varying_recurrence
from fnnlib.feedback.measurement import Measurements
from fnnlib.feedback.sampling import Steps, row_steps
from fnnlib.feedback.types import Estimate, VectorField

#: The per-step map of a layer: ``x`` (..., T, c, n) -> ``g_k(x_k)`` (..., T, c, n), rows independent.
StepMap = Callable[[Tensor], Tensor]


def apply_gain(L: Tensor, e: Tensor, diagonal: bool | None = None) -> Tensor:
    """``L e`` in row-vector form: ``e * L`` for diagonals ((n,) or a batch (..., n)), ``e @ L.T`` for a matrix (n, q).

    By default a 1-D ``L`` is a diagonal.
    """
    return e * L if (L.ndim == 1 if diagonal is None else diagonal) else e @ L.T


def measure_fn(meas: Measurements, dtype: torch.dtype) -> Callable[[Tensor], Tensor] | None:
    """``x (..., n) -> y (..., p)`` of the measurement model, or ``None`` when every state is measured."""
    if meas.h is not None:
        return lambda x: meas.h(x.reshape(-1, x.shape[-1])).reshape(*x.shape[:-1], meas.p)
    if meas.C is None:
        return None
    C = meas.C.to(dtype)
    return lambda x: x @ C.T


def start_state(meas: Measurements, n: int, x0: Tensor | None) -> Tensor:
    r""":math:`\hat x_0`: ``x0``, else the least-squares state of the first sample's present outputs, :math:`(M_0C)^+ y_0`."""
    y0 = meas.y[..., 0, :]
    if x0 is not None:
        return torch.as_tensor(x0, dtype=y0.dtype).expand(*y0.shape[:-1], n)
    if meas.C is None and meas.h is None:
        return y0  # gaps hold 0
    if meas.h is not None:
        raise ValueError("with a measurement function h give the first estimate x0 (n,): h cannot be inverted")
    C = meas.C.to(y0.dtype)
    if meas.mask is not None:
        C = meas.mask[..., 0, :, None].to(y0.dtype) * C
    return (torch.linalg.pinv(C) @ y0[..., None])[..., 0]


def _field(f: VectorField, x: Tensor, u: Tensor | None) -> Tensor:
    """``f(t, x)`` or ``f(t, x, u)`` on every row of ``x`` (..., n), ``u`` broadcast to ``x``'s leading axes."""
    n = x.shape[-1]
    if u is None:
        out = f(0.0, x.reshape(-1, n))
    else:
        out = f(0.0, x.reshape(-1, n), u.expand(*x.shape[:-1], u.shape[-1]).reshape(-1, u.shape[-1]))
    if out.shape != (x[..., 0].numel(), n):
        raise ValueError(f"vector field returned shape {tuple(out.shape)} for input {(x[..., 0].numel(), n)}")
    return out.reshape(x.shape)


def layer_step(f: VectorField, z: Tensor, L: Tensor, dt: Tensor | float, *, mask: Tensor | None = None,
               u: Tensor | None = None, measure: Callable[[Tensor], Tensor] | None = None,
               diagonal: bool | None = None) -> Callable[[Tensor], tuple[Tensor, Tensor, Tensor]]:
    r"""The step of one layer, :math:`x \mapsto` (point the field is evaluated at, :math:`\hat f_k`, :math:`g_k(x)`).

    ``z`` (..., T, q) the layer's input (measurements), ``mask`` (..., T, q) present samples, ``u`` (..., T, m),
    ``dt`` a float or (..., T, 1) the step of each row. The returned map takes ``x`` (..., T, c, n), a copy
    axis ``c`` before the state (for batched Jacobians), and evaluates Eq. (7) and Eq. (8) on every row.
    """
    z_c = z.unsqueeze(-2)
    m_c = None if mask is None else mask.unsqueeze(-2)
    u_c = None if u is None else u.unsqueeze(-2)
    dt_c = dt.unsqueeze(-2) if isinstance(dt, Tensor) else dt
    diag = L.ndim == 1 if diagonal is None else diagonal
    L_c = L[..., None, None, :] if (diag and L.ndim > 1) else L  # batched diagonals (G, 1.., n): the T and copy axes

    def step(x: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        if measure is None:
            at = z_c if m_c is None else torch.where(m_c, z_c, x)
            e = at - x
        else:
            at = x
            e = z_c - measure(x)
            if m_c is not None:
                e = torch.where(m_c, e, torch.zeros((), dtype=e.dtype))  # no sample: no correction
        f_hat = _field(f, at, u_c) + apply_gain(L_c, e, diag)  # Eq. (7)
        return at, f_hat, x + dt_c * f_hat  # Eq. (8)

    return step


def _jacobian(g: StepMap, x: Tensor) -> tuple[Tensor, Tensor]:
    """``g(x)`` (..., T, n) and its per-row Jacobians (..., T, n, n): one batched forward and backward pass."""
    n = x.shape[-1]
    with torch.enable_grad():
        X = x.detach().unsqueeze(-2).expand(*x.shape[:-1], n, n).clone().requires_grad_(True)
        G = g(X)  # (..., T, n copies, n)
        (J,) = torch.autograd.grad(G.diagonal(dim1=-2, dim2=-1).sum(), X)
    return G[..., 0, :].detach(), J.detach()


def _newton(g: StepMap, x0: Tensor, guess: Tensor, tol: float, max_iter: int,
            need_J: bool) -> tuple[Tensor, Tensor | None, int, bool]:
    """Newton's method on ``x_{k+1} = g_k(x_k)`` from ``guess`` (..., T, n) (its row 0 is ``x0``).

    Returns x_0..x_T (..., T+1, n), the Jacobians at rows 0..T-1 when ``need_J`` (for the gradient step),
    the iterations and whether it converged: the step fell below ``tol`` (relative), or it stalled at the
    rounding floor of the scan (below 1e-12 relative and no longer halving).
    """
    x, last = guess, float("inf")
    for it in range(1, max_iter + 1):
        gx, J = _jacobian(g, x)
        b = gx - (J @ x[..., None])[..., 0]
        nxt = varying_recurrence(J, b, x0)[..., :-1, :]
        step = float((nxt - x).abs().max())
        x = nxt
        if not step < float("inf"):  # NaN or inf: diverged
            return x, None, it, False
        scale = max(1.0, float(x.abs().max()))
        if step <= tol * scale or (step <= 1e-12 * scale and step > 0.5 * last):
            if need_J:
                gx, J = _jacobian(g, x)
            else:
                gx, J = g(x.unsqueeze(-2))[..., 0, :], None
            return torch.cat([x[..., :1, :], gx], dim=-2), J, it, True
        last = step
    return x, None, max_iter, False


def solve_layer(make_step: Callable[[int, int], StepMap], x0: Tensor, T: int, *, guess: Tensor | None = None,
                tol: float | None = None, max_iter: int = 30, chunk: int = 1024) -> tuple[Tensor, int]:
    r"""Solve :math:`\hat x_{k+1} = g_k(\hat x_k)`, :math:`\hat x_0` = ``x0`` (..., n), for k < T at once.

    ``make_step(a, b)`` returns the map of rows ``a..b-1``, (..., b-a, c, n) -> (..., b-a, c, n) (see
    :func:`layer_step`). The record is solved ``chunk`` rows at a time, each chunk by Newton's method on its
    whole sequence from its first state held (or ``guess`` (..., T, n)); the linearisation at a poor guess can
    expand over thousands of steps, which chunks keep in bounds. A chunk that does not converge in
    ``max_iter`` iterations is solved in pieces of 64 rows (each exact after at most 64 iterations). Returns
    :math:`\hat x_0 .. \hat x_T` (..., T+1, n) and the Newton iterations taken (summed over chunks).
    Differentiable (module docstring).
    """
    tol = tol if tol is not None else 64 * torch.finfo(x0.dtype).eps
    need_J = torch.is_grad_enabled()
    with torch.no_grad():
        x0d = x0.detach()
        probe = make_step(0, 1)(x0d[..., None, None, :])
        lead = torch.broadcast_shapes(x0d.shape[:-1], probe.shape[:-3])
        start = x0d.expand(*lead, x0d.shape[-1])
        rows, Js, iters = [start.unsqueeze(-2)], [], 0
        for a in range(0, T, chunk):
            b = min(a + chunk, T)
            hint = None if guess is None else guess.detach().expand(*lead, T, start.shape[-1])[..., a:b, :]
            full, J, it = _solve_chunk(make_step, start, a, b, hint, tol, max_iter, need_J)
            iters += it
            rows.append(full[..., 1:, :])
            Js.append(J)
            start = full[..., -1, :]
        full = torch.cat(rows, dim=-2)
    if not need_J:
        return full, iters
    J = torch.cat(Js, dim=-3)
    xs = full[..., :-1, :]
    gx = make_step(0, T)(xs.unsqueeze(-2))[..., 0, :]  # with autograd: the parameters, gains, data
    b = gx - (J @ xs[..., None])[..., 0]
    return varying_recurrence(J, b, x0.expand(*lead, x0.shape[-1])), iters


def _solve_chunk(make_step: Callable[[int, int], StepMap], start: Tensor, a: int, b: int, hint: Tensor | None,
                 tol: float, max_iter: int, need_J: bool, piece: int = 64) -> tuple[Tensor, Tensor | None, int]:
    """Rows ``a..b-1`` from ``start``: Newton on the whole chunk, else in pieces of ``piece`` rows."""
    guess = start.unsqueeze(-2).expand(*start.shape[:-1], b - a, start.shape[-1]) if hint is None else hint
    guess = torch.cat([start.unsqueeze(-2), guess[..., 1:, :]], dim=-2)
    full, J, it, ok = _newton(make_step(a, b), start, guess, tol, max_iter, need_J)
    if ok:
        return full, J, it
    if b - a <= piece:
        full, J, it2, ok = _newton(make_step(a, b), start, guess, tol, b - a + 4, need_J)
        if not ok:
            raise FloatingPointError(f"the layer's recursion does not settle between samples {a} and {b}: the "
                                     "estimate diverges (an unstable gain or model through a long gap?)")
        return full, J, it + it2
    rows, Js = [start.unsqueeze(-2)], []
    for p in range(a, b, piece):
        q = min(p + piece, b)
        part, Jp, itp = _solve_chunk(make_step, start, p, q, None, tol, q - p + 4, need_J, piece)
        it += itp
        rows.append(part[..., 1:, :])
        Js.append(Jp)
        start = part[..., -1, :]
    return torch.cat(rows, dim=-2), (torch.cat(Js, dim=-3) if need_J else None), it


def layer_loop(f: VectorField, z: Tensor, L: Tensor, dt: Tensor | float, x0: Tensor, *, mask: Tensor | None = None,
               u: Tensor | None = None, measure: Callable[[Tensor], Tensor] | None = None,
               diagonal: bool | None = None) -> tuple[Estimate, Tensor]:
    """The sequential reference of one layer: a Python loop over time (T tiny network calls). Same arguments as
    :func:`layer_step`, from :math:`\\hat x_0` = ``x0``; returns (``x_hat``, ``f_hat``) and the layer's output."""
    x_hat = x0
    x_hats, f_hats, outs = [], [], []
    for k in range(z.shape[-2]):
        sl = slice(k, k + 1)
        step = layer_step(f, z[..., sl, :], L, dt[..., sl, :] if isinstance(dt, Tensor) else dt,
                          mask=None if mask is None else mask[..., sl, :],
                          u=None if u is None else u[..., sl, :], measure=measure, diagonal=diagonal)
        at, f_hat, nxt = step(x_hat[..., None, None, :])
        x_hats.append(x_hat)
        f_hats.append(f_hat[..., 0, 0, :])
        outs.append(at[..., 0, 0, :] + (dt[..., k, :] if isinstance(dt, Tensor) else dt) * f_hat[..., 0, 0, :])
        x_hat = nxt[..., 0, 0, :]
    return Estimate(torch.stack(x_hats, -2), torch.stack(f_hats, -2)), torch.stack(outs, -2)


def first_layer(f: VectorField, meas: Measurements, L: Tensor, dt: Steps, x0: Tensor, *,
                diagonal: bool | None = None, guess: Tensor | None = None) -> tuple[Estimate, Tensor, Tensor, int]:
    r"""Layer 0 on measurements with gaps or ``y = C x``, batched (:func:`solve_layer`): (``x_hat``, ``f_hat``),
    its depth-0 sequence (the measurements with gaps filled by the estimate, or the estimates), its output
    (..., T, n) and the Newton iterations."""
    y = meas.y
    T = y.shape[-2]
    measure = measure_fn(meas, y.dtype)
    steps = row_steps(dt, 0, T)

    def make_step(a: int, b: int) -> StepMap:
        part = lambda v: None if v is None else v[..., a:b, :]  # noqa: E731
        s_ab = part(steps) if isinstance(steps, Tensor) else steps
        step = layer_step(f, part(y), L, s_ab, mask=part(meas.mask), u=part(meas.u), measure=measure,
                          diagonal=diagonal)
        return lambda x: step(x)[2]

    full, iters = solve_layer(make_step, x0, T, guess=guess)
    x_hat = full[..., :-1, :]
    at, f_hat, _ = layer_step(f, y, L, steps, mask=meas.mask, u=meas.u, measure=measure,
                              diagonal=diagonal)(x_hat.unsqueeze(-2))
    at, f_hat = at[..., 0, :], f_hat[..., 0, :]
    at = at.expand_as(x_hat)
    out = full[..., 1:, :] if measure is not None else at + steps * f_hat
    return Estimate(x_hat, f_hat), (x_hat if measure is not None else at), out, iters
