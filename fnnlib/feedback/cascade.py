r"""The cascade of Sec. 3.3: N feedback networks in series, gain decay Eq. (11), one or many gains at once.

Layer ``i`` (``i = 0 .. N-1``) is a feedback network (Eqs. (7)-(8)) with the
decayed gain :math:`L_i = L e^{-\beta i}`. Its input sequence is the previous
layer's one-step predictions :math:`z^{(i)}_k` (:math:`z^{(0)}_k = x(t_k)`, the
measurements); it keeps its own estimate :math:`\hat x^{(i)}` over time and
outputs :math:`z^{(i+1)}_k = z^{(i)}_k + T_s \hat f^{(i)}_k`, so :math:`z^{(N)}_k`
predicts :math:`x(t_{k+N})`. Per layer, all start times are done at once: one
batched network call and one linear scan (:func:`~fnnlib.feedback.layer.feedback_layer`).

**Gaps and partial measurements.** The paper measures the full state at every sample. Where samples are
missing, or only :math:`y = Cx` (or :math:`h(x)`) is measured, the first layer cannot evaluate the field at a
measurement; this library's design (our extension, not the paper's) is:

* layer 0 is the feedback observer on the measurements: the gap-aware layer with ``L`` (full state with
  gaps), or a :class:`~fnnlib.feedback.measured.MeasuredFeedback` observer with its output gain (``y = Cx``),
  solved for all times at once (:mod:`fnnlib.feedback.gaps`); its output :math:`z^{(1)}_k` is the estimate
  of :math:`x(t_{k+1})` from the data up to :math:`t_k`, complete (no gaps) and full-state;
* layers 1..N-1 are the paper's full-state cascade on those estimates, with :math:`L_i = Le^{-\beta i}`.

Why: an earlier design re-observed each layer's predicted *outputs* through ``C``, so the unmeasured states of
every later layer were corrected by nothing but their own predictions and drifted; at N = 25 it was 1.6-4.7x
worse than simply rolling the model out from the observer's estimate. With this design the layers after the
first see the whole estimated state, and ``L = 0`` there is exactly that open-loop rollout.

**Uneven times.** With sample times ``t`` instead of ``Ts``, row ``k`` of layer ``i`` steps by
:math:`\Delta_{k+i} = t_{k+i+1} - t_{k+i}` (:mod:`fnnlib.feedback.sampling`), so depth ``N`` predicts the state
at the record's own :math:`t_{k+N}`; Eq. (11)'s decay stays per layer.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from fnnlib._validation import as_trajectory, check_positive
from fnnlib.feedback.decay import check_N, decay_factors, decayed_gains
from fnnlib.feedback.gains import check_gain, gain_compact
from fnnlib.feedback.gaps import first_layer, start_state
from fnnlib.feedback.layer import eval_field, feedback_layer, lead_gains, shift_inputs
from fnnlib.feedback.measured import MeasuredFeedback
from fnnlib.feedback.measurement import Measurements, check_measurements
from fnnlib.feedback.options import Gains, Measurement, record_sampling
from fnnlib.feedback.sampling import Steps, check_times, longest, row_steps
from fnnlib.feedback.types import VectorField


def run_cascade(f: VectorField, x: Tensor, L_stack: Sequence[Tensor], Ts: Steps, *, diagonal: bool | None = None,
                return_all: bool = False, u: Tensor | None = None, rows: int | None = None,
                first_depth: int = 0) -> Tensor:
    r"""The layers of the cascade, one per decayed gain ``L_stack[i]`` (as :func:`feedback_layer` takes it).

    ``x`` (..., T, n); returns :math:`z^{(N)}` of the same shape, or with
    ``return_all`` every depth stacked, (N+1, ..., T, n), depth 0 being ``x``.
    With inputs ``u`` (..., T, m), layer ``i`` evaluates ``f(t, z, u)`` with row k's input
    ``u_{k+i}`` (:func:`~fnnlib.feedback.layer.shift_inputs`). ``Ts`` is the step, or the intervals
    (..., T-1) of uneven times (row k of layer i steps by :math:`\Delta_{k+i}`). ``first_depth`` is the depth
    of ``x`` (1 when ``x`` is an observer's output): layer ``i`` then uses the inputs and steps of depth
    ``first_depth + i``. Differentiable: gradients flow to the gains in ``L_stack``, to ``f``'s parameters
    and to ``x``.

    ``rows`` (1..T) computes only the first ``rows`` start times, (..., rows, n): every layer is causal
    in time (row k of its output reads rows <= k of its input, and the inputs ``u_{k+i}`` of the full
    sequence), so these rows are those of the whole run, at ``rows / T`` of its cost. Tuning against
    targets N samples later needs only the first ``T - N`` (:func:`~fnnlib.feedback.tuning.tune_gains`).
    """
    T = x.shape[-2]
    if rows is not None:
        if not 1 <= int(rows) <= T:
            raise ValueError(f"rows must lie in 1..{T} (the samples of x), got {rows!r}")
        rows = int(rows)
    z = x if rows is None else x[..., :rows, :]
    depths = [z] if return_all else None
    for i, L_i in enumerate(L_stack):
        d = first_depth + i
        u_i = shift_inputs(u, d)
        if u_i is not None and rows is not None:
            u_i = u_i[..., :rows, :]  # shifted on the whole sequence first: row k keeps u_{k+i}
        h = row_steps(Ts, d, T) if T > 1 else _single_step(Ts)
        if isinstance(h, Tensor) and rows is not None:
            h = h[..., :rows, :]
        _, f_hat = feedback_layer(eval_field(f, z, u_i), z, L_i, h, diagonal=diagonal)
        z = z + h * f_hat  # z^{(i+1)} = z^{(i)} + Ts * f_hat^{(i)}
        if depths is not None:
            depths.append(z)
    return torch.stack(depths) if depths is not None else z


def _single_step(Ts: Steps) -> Steps:
    return Ts if not isinstance(Ts, Tensor) else Ts[..., -1:, None]


def _checked(x: Tensor, Ts: float, N: int) -> tuple[Tensor, float, int]:
    """The checks every cascade makes before any work: a finite, non-empty trajectory, Ts > 0, an integer N >= 1."""
    N = check_N(N)
    Ts = check_positive(Ts, name="Ts")
    x = as_trajectory(x, x.shape[-1] if isinstance(x, Tensor) else None)
    if x.shape[-2] == 0 or x.shape[-1] == 0:
        raise ValueError(f"x is an empty trajectory (shape {tuple(x.shape)}); give at least one sample of a "
                         "state with at least one component")
    return x, Ts, N


def measured(f: VectorField, x: Tensor, Ts: float | None, N: int, *, t: Tensor | None = None,
             u: Tensor | None = None, mask: Tensor | None = None,
             observer: MeasuredFeedback | None = None) -> tuple[Measurements, Steps, int, int]:
    """The checks of a cascade on measurements before any work: (measurements, steps, N, n).

    Gaps (NaN or ``mask``), inputs, the times ``t`` or step ``Ts``, and the observer's measurement model.
    """
    N = check_N(N)
    if isinstance(x, Tensor) and x.ndim >= 2 and (x.shape[-2] == 0 or x.shape[-1] == 0):
        raise ValueError(f"x is an empty trajectory (shape {tuple(x.shape)}); give at least one sample of a "
                         "state with at least one component")
    if observer is not None and not isinstance(observer, MeasuredFeedback):
        raise TypeError(f"observer must be a fnnlib.MeasuredFeedback (the first layer on y = C x), got "
                        f"{type(observer).__name__}")
    if observer is None:
        n = x.shape[-1] if isinstance(x, Tensor) else 0
        meas = check_measurements(x, n, u=u, mask=mask, f=f, name="x")
    else:
        n = observer.n
        meas = check_measurements(x, n, C=observer.output, u=u, mask=mask, f=f, name="y")
    if Ts is None and t is None and observer is not None and observer.Ts is not None:
        Ts = observer.Ts
    return meas, check_times(t, Ts, meas.y, name="x" if observer is None else "y"), N, n


def _first_then_cascade(f: VectorField, meas: Measurements, dt: Steps, L0: Tensor, L_rest: Sequence[Tensor], n: int,
                        observer: MeasuredFeedback | None, *, diagonal: bool | None, return_all: bool) -> Tensor:
    """Layer 0 on the measurements (gaps or ``y = Cx``; module docstring), then the paper's cascade on its output."""
    x0 = start_state(meas, n, None if observer is None else observer.x0)
    if observer is not None:
        L0, diagonal0 = observer.gain_for(dt).to(meas.y.dtype), False
    else:
        diagonal0 = diagonal
    _, depth0, z1, _ = first_layer(f, meas, L0, dt, x0, diagonal=diagonal0)
    rest = run_cascade(f, z1, L_rest, dt, diagonal=diagonal, u=meas.u, first_depth=1, return_all=return_all)
    if not return_all:
        return rest
    return torch.cat([depth0.expand_as(z1)[None], rest])


@torch.no_grad()
def cascade_predict(f: VectorField, x: Tensor, Ts: float | None, N: int, gains: Gains, *, u: Tensor | None = None,
                    measurement: Measurement | None = None, observer: MeasuredFeedback | None = None) -> Tensor:
    r"""N-step prediction by the cascaded feedback network (Sec. 3.3, Eq. (11)), from every start time.

    With ``L = 0`` (and no gap) this equals :func:`~fnnlib.rollout_predict` with ``method="euler"``.

    Parameters
    ----------
    f : callable
        Learned vector field ``f(t, x)`` or, with inputs, ``f(t, x, u)``.
    x : Tensor, shape (..., T, n), or (..., T, p) with an ``observer``
        Measured states (or outputs), one row per sample.
    Ts : float or None
        Sample step (also the prediction step); ``None`` with ``measurement.t``.
    N : int
        Prediction steps (layers).
    gains : Gains
        The schedule of Eq. (11): base gain ``L`` (full state; float, (n,) or (n, n)) and decay rate ``beta``
        (0 keeps every layer at ``L``), checked by :func:`~fnnlib.feedback.gains.check_gain` (Theorem 1,
        Eq. (25), the noise amplification) unless ``gains.allow_unstable``.
    u : Tensor, shape (..., T, m), optional
        Inputs of a controlled model ``f(t, x, u)``, one row per sample (held over the step from it).
    measurement : Measurement, optional
        The record's missing samples (``mask`` (..., T) or (..., T, p), ``False`` where no sample was taken;
        a NaN in ``x`` means the same) and its sample times ``t`` (..., T) instead of ``Ts`` (uneven sampling,
        :mod:`fnnlib.feedback.sampling`). ``C`` and ``x0`` belong to the ``observer``.
    observer : MeasuredFeedback, optional
        Partial measurements ``y = C x`` (or ``h(x)``): the first layer is this observer (its output gain, its
        first estimate); the layers after it use ``gains`` (module docstring).

    Returns
    -------
    Tensor
        Shape (..., T, n): row k predicts the state at ``t_{k+N}``. :func:`cascade_depths` returns every depth.
    """
    return _cascade(f, x, Ts, N, gains, u, measurement, observer, return_all=False)


@torch.no_grad()
def cascade_depths(f: VectorField, x: Tensor, Ts: float | None, N: int, gains: Gains, *, u: Tensor | None = None,
                   measurement: Measurement | None = None, observer: MeasuredFeedback | None = None) -> Tensor:
    r"""Every depth of the cascade of :func:`cascade_predict` (same arguments), shape (N+1, ..., T, n).

    Depth ``i`` holds the ``i``-step predictions :math:`z^{(i)}`; depth 0 is ``x`` itself (its gaps filled by
    the estimate; with an ``observer``, the estimates :math:`\hat x_k`).
    """
    return _cascade(f, x, Ts, N, gains, u, measurement, observer, return_all=True)


def _cascade(f: VectorField, x: Tensor, Ts: float | None, N: int, gains: Gains, u: Tensor | None,
             measurement: Measurement | None, observer: MeasuredFeedback | None, *, return_all: bool) -> Tensor:
    """The cascade of Sec. 3.3 for :func:`cascade_predict` and :func:`cascade_depths`."""
    if not isinstance(gains, Gains):
        raise TypeError(f"gains must be a fnnlib.Gains(L, beta), got {type(gains).__name__}")
    t, mask = record_sampling(measurement)
    beta = gains.beta
    meas, dt, N, n = measured(f, x, Ts, N, t=t, u=u, mask=mask, observer=observer)
    L = check_gain(gains.L, n, longest(dt), allow_unstable=gains.allow_unstable, N=N,
                   beta=beta)  # warns on noise amplification
    L_stack = [gain_compact(L_i, n, dtype=meas.y.dtype) for L_i in decayed_gains(L, N, beta)]
    if observer is None and meas.mask is None:  # no gap: the paper's cascade, one scan per layer
        return run_cascade(f, meas.y, L_stack, dt, return_all=return_all, u=meas.u)
    return _first_then_cascade(f, meas, dt, L_stack[0], L_stack[1:], n, observer, diagonal=None,
                               return_all=return_all)


@torch.no_grad()
def cascade_sweep(f: VectorField, x: Tensor, Ts: float | None, N: int, gains: Sequence[Gains], *,
                  u: Tensor | None = None, measurement: Measurement | None = None,
                  observer: MeasuredFeedback | None = None) -> Tensor:
    r"""The N-step cascade for a batch of gain schedules (base gain, decay rate) in one pass.

    Batch element ``g`` runs :func:`cascade_predict` with ``gains[g]``: layer ``i`` uses
    :math:`L_g e^{-\beta_g i}`. Each base gain is a scalar or a diagonal (n,); :meth:`Gains.sweep
    <fnnlib.feedback.options.Gains.sweep>` pairs a grid of gains with decay rates by broadcasting.
    The ablations of Sec. 3.4 and App. A.3 sweep gains and decay rates this way.

    Parameters
    ----------
    f : callable
        Learned vector field ``f(t, x)``.
    x : Tensor, shape (..., T, n)
        Measurements (any leading axes: levels, noise draws); (..., T, p) with an ``observer``.
    Ts : float or None
        Sample step (also the prediction step); ``None`` with ``measurement.t``.
    N : int
        Prediction steps (layers).
    gains : sequence of Gains
        The G schedules, each checked by :func:`~fnnlib.feedback.gains.check_gain` unless its
        ``allow_unstable``.
    u, measurement, observer : optional
        As :func:`cascade_predict` takes them. With an ``observer`` the first layer runs once and the gains
        sweep the layers after it.

    Returns
    -------
    Tensor, shape (G, ..., T, n)
        Row ``k`` predicts the state at ``t_{k+N}``.
    """
    gains = tuple(gains) if isinstance(gains, (list, tuple)) else gains
    if not isinstance(gains, tuple) or not gains or not all(isinstance(g, Gains) for g in gains):
        raise TypeError("gains must be a non-empty sequence of fnnlib.Gains (e.g. Gains.sweep(L_grid, beta_grid))")
    if any(g.L.ndim > 1 for g in gains):
        raise ValueError("a swept gain must be a scalar or a diagonal (n,) (the sweep runs diagonal gains)")
    t, mask = record_sampling(measurement)
    meas, dt, N, n = measured(f, x, Ts, N, t=t, u=u, mask=mask, observer=observer)
    for g in gains:
        if g.L.ndim == 1 and g.L.shape[0] != n:
            raise ValueError(f"a swept diagonal gain has {g.L.shape[0]} entries but the state has n = {n}")
        check_gain(g.L, n, longest(dt), allow_unstable=g.allow_unstable)
    L = torch.stack([g.L.expand(n) for g in gains]).to(meas.y.dtype)  # (G, n) base gains
    decay = decay_factors([g.beta for g in gains], N)  # (G, N)
    G = L.shape[0]
    y = meas.y
    nd = y.ndim + 1
    L_stack = [lead_gains(L * decay[:, i].to(y.dtype)[:, None], nd) for i in range(N)]  # Eq. (11)
    if observer is None and meas.mask is None:
        return run_cascade(f, y.expand(G, *y.shape), L_stack, dt, diagonal=True, u=meas.u)
    if observer is None:  # gaps: layer 0 runs per gain
        meas = meas._replace(y=y.expand(G, *y.shape), mask=meas.mask.expand(G, *meas.mask.shape))
        return _first_then_cascade(f, meas, dt, L_stack[0], L_stack[1:], n, None, diagonal=True, return_all=False)
    x0 = start_state(meas, n, observer.x0)
    _, _, z1, _ = first_layer(f, meas, observer.gain_for(dt).to(y.dtype), dt, x0, diagonal=False)
    return run_cascade(f, z1.expand(G, *z1.shape), L_stack[1:], dt, diagonal=True, u=meas.u, first_depth=1)


@torch.no_grad()
def cascade_predict_loop(f: VectorField, x: Tensor, Ts: float, N: int, gains: Gains) -> Tensor:
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
    if not isinstance(gains, Gains):
        raise TypeError(f"gains must be a fnnlib.Gains(L, beta), got {type(gains).__name__}")
    L = check_gain(gains.L, n, Ts, allow_unstable=gains.allow_unstable)
    L_stack = [gain_compact(L_i, n, dtype=x.dtype) for L_i in decayed_gains(L, N, gains.beta)]
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
