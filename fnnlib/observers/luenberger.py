r"""A Luenberger observer with a constant-disturbance state, its gain placed by ``control.place``.

The observer runs on the augmented learned model of
:mod:`fnnlib.observers.augmented` (Euler at :math:`T_s`, :math:`z = [x; d]`,
:math:`u_k = f_{neural}(y_k)` as in Eq. (7)):

.. math:: \hat z_{k+1|k} = A\hat z_{k|k-1} + B f_{neural}(y_k) + L(y_k - C\hat z_{k|k-1}),

whose error obeys :math:`e_{k+1} = (A - LC)e_k` plus the noise terms, so the
requested discrete poles are the eigenvalues of :math:`A - LC` exactly
(Luenberger 1966; pole placement by the dual :math:`A^T - C^T L^T`).

**Uneven sample times** ``t`` (``estimate``/``observe``/``predict`` take ``t=`` instead of the nominal ``Ts``):
the poles are placed **per sample** (each step contracts the error by the same requested discrete poles,
whatever its length) and the gain is recomputed **per interval** :math:`\Delta_k` for that interval's plant.

* Full state: :math:`A(\Delta) = D_\Delta A(1) D_\Delta^{-1}` with :math:`D_\Delta = \mathrm{diag}(I, I/\Delta)`
  and :math:`C D_\Delta = C`, so :math:`L_\Delta = \mathrm{diag}(I, (T_s/\Delta) I)\,L` has exactly the poles
  of :math:`L` at :math:`T_s` (closed form, no placement per interval).
* With ``C``: :math:`\Phi_\Delta` (the Euler step of the linearised model) is no such similarity, so the poles
  are placed for every distinct interval (intervals within 1e-10 of each other share one): with one output
  by Ackermann's formula for all of them at once (the placing gain is then unique); with more, by
  :func:`place_observer_gain` one interval at a time (about 2 ms each, a progress bar for many).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor
from tqdm.auto import tqdm

from fnnlib.feedback.gains import gain_matrix
from fnnlib.feedback.types import VectorField
from fnnlib._validation import as_trajectory
from fnnlib.observers.augmented import DisturbanceEstimate, observer_steps, steps_per_record
from fnnlib.observers.kalman import _OutputModel, _state_dimension


def place_observer_gain(A: Tensor | np.ndarray, C: Tensor | np.ndarray, poles: Sequence[complex], *,
                        allow_unstable: bool = False) -> Tensor:
    r"""Observer gain :math:`L` with :math:`\operatorname{eig}(A - LC)` = ``poles`` (discrete time).

    The gain ``L`` of Eq. (7) for a linear(ised) model: the error dynamics of Eq. (9), discretised at ``Ts``,
    decay at ``poles``.

    By duality, :math:`L^T` is the state-feedback gain that places ``poles``
    for :math:`(A^T, C^T)`: ``L = control.place(A.T, C.T, poles).T``.

    Parameters
    ----------
    A : array, shape (m, m)
    C : array, shape (q, m)
    poles : sequence of m complex
        Requested eigenvalues of :math:`A - LC`; complex ones in conjugate
        pairs, each repeated at most ``rank(C)`` times, inside the unit disc
        (a stable observer) unless ``allow_unstable``.

    Returns
    -------
    Tensor, shape (m, q), float64

    Raises
    ------
    ValueError
        If (A, C) is not observable, or the poles are of the wrong number,
        not in conjugate pairs, repeated too often, or outside the unit disc.
    """
    A = np.asarray(A, dtype=float)
    C = np.atleast_2d(np.asarray(C, dtype=float))
    m = A.shape[0]
    if A.shape != (m, m) or C.shape[1] != m:
        raise ValueError(f"A must be square and C have as many columns; got A {A.shape}, C {C.shape}")
    try:
        p = np.asarray(poles, dtype=complex).ravel()
    except (TypeError, ValueError):
        raise TypeError(f"poles must be numbers (real or complex), got {poles!r}") from None
    if p.size != m:
        raise ValueError(f"need {m} poles for a {m}-state observer, got {p.size}: {p.tolist()}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"poles must be finite, got {p.tolist()}")
    if not np.allclose(np.sort_complex(p), np.sort_complex(p.conj())):
        raise ValueError(f"complex poles must come in conjugate pairs for a real gain, got {p.tolist()}")
    if not allow_unstable and np.any(np.abs(p) >= 1):
        bad = [complex(z) for z in p if abs(z) >= 1]
        raise ValueError(f"discrete observer poles must lie inside the unit disc |z| < 1; got {bad} "
                         "(the estimation error would not decay). Pass allow_unstable=True to place them anyway.")
    import control  # noqa: PLC0415 (python-control loads matplotlib.pyplot: ~0.6 s of CPU, only for the gain)

    rank = np.linalg.matrix_rank(control.obsv(A, C))
    if rank < m:
        raise ValueError(f"(A, C) is not observable (observability matrix rank {rank} < {m}): "
                         "no gain can place every pole")
    q = np.linalg.matrix_rank(C)
    for z in p:
        if np.sum(np.isclose(p, z)) > q:
            raise ValueError(f"pole {complex(z)} is requested {int(np.sum(np.isclose(p, z)))} times; pole placement "
                             f"(Tits-Yang) can repeat a pole at most rank(C) = {q} times")
    with warnings.catch_warnings():
        # Tits-Yang stops refining the *robustness* of the eigenvectors after maxiter; the poles are still
        # placed, which the check below verifies instead
        warnings.filterwarnings("ignore", message="Convergence was not reached", category=UserWarning)
        L = control.place(A.T, C.T, p).T  # eig(A^T - C^T L^T) = poles  <=>  eig(A - L C) = poles
    L = np.real_if_close(L).real
    got = np.sort_complex(np.linalg.eigvals(A - L @ C))
    miss = float(np.abs(got - np.sort_complex(p)).max())
    if miss > 1e-6 * max(1.0, float(np.abs(p).max())):
        raise RuntimeError(f"pole placement missed the requested poles by {miss:.3g}: got {got.tolist()}")
    return torch.as_tensor(L, dtype=torch.float64)


class LuenbergerObserver(_OutputModel):
    r"""Luenberger observer on the learned model with a constant-disturbance state.

    The model and gain are those of :mod:`fnnlib.observers.augmented` and
    :func:`place_observer_gain`. With every state measured, the augmented
    plant is linear in :math:`z` once :math:`f_{neural}` is evaluated at the
    measurement (as Eq. (7) does), so the design needs no linearisation and
    the placed poles are the true error poles.

    Every observer is built as ``(f, Ts, *, ...)``: the model and the nominal sample step by position, the rest
    by name. :meth:`with_gain` builds one from a ready gain instead of poles.

    Parameters
    ----------
    f, Ts
        Learned field and sampling step, as :class:`~fnnlib.observers.augmented.AugmentedObserver`.
    n : int, optional
        State dimension; by default ``f.n``.
    poles : sequence of 2n complex
        Discrete poles of :math:`A - LC`, placed by :func:`place_observer_gain`.
    allow_unstable : bool
        Accept poles on or outside the unit circle.
    C, disturbance, A : optional
        Partial measurements ``y = C x`` (p, n), the disturbance layout (states or E (n, q)) and the model
        Jacobian (default: at the origin), as the Kalman filters take them, detectability checked. With any of
        them the poles are placed for the augmented model linearised at ``A`` (:math:`\Phi - LC`, ``L``
        (n + q, p)) and the observer runs with the model evaluated at the *estimate*, filter gain
        :math:`\Phi^{-1}L` (:meth:`~fnnlib.observers.kalman._OutputModel.constant_gain_loop`); it then takes
        gaps (``mask`` or NaN). Without them the full-state observer above is unchanged.

    Attributes
    ----------
    A, B, C : Tensor
        Augmented plant, (2n, 2n), (2n, n), (n, 2n).
    L : Tensor, shape (2n, n)
        Observer gain (predictor form).
    """

    def __init__(self, f: VectorField, Ts: float, *, n: int | None = None, poles: Sequence[complex],
                 allow_unstable: bool = False, C=None, disturbance=None, A=None):
        self._build(f, Ts, n, poles, None, allow_unstable, C, disturbance, A)

    @classmethod
    def with_gain(cls, f: VectorField, Ts: float, *, n: int | None = None, L: Tensor, allow_unstable: bool = False,
                  C=None, disturbance=None, A=None) -> LuenbergerObserver:
        """The observer with a ready gain ``L`` (n + q, p) (e.g. :func:`linear_feedback_gain`) instead of placed
        poles; its poles are then :meth:`error_poles`, refused outside the unit disc unless ``allow_unstable``."""
        obs = cls.__new__(cls)
        obs._build(f, Ts, n, None, L, allow_unstable, C, disturbance, A)
        return obs

    def _build(self, f, Ts, n, poles, L, allow_unstable, C, disturbance, A) -> None:
        """The set-up of :meth:`__init__` (``poles``) and :meth:`with_gain` (``L``)."""
        super().__init__(f, Ts, _state_dimension(f, n), C=C, disturbance=disturbance, A=A)
        if poles is None and L is None:
            raise ValueError("LuenbergerObserver needs its poles (or LuenbergerObserver.with_gain and a ready L)")
        self.output_form = C is not None or disturbance is not None
        self.J = self._jacobian(A) if self.output_form else None  # the model Jacobian the output form is linearised at
        self.Phi = self._linearised(self.J) if self.output_form else self.A  # the transition the poles are placed for
        if self.output_form:
            self.takes_gaps = True
        if poles is not None:
            self.L = place_observer_gain(self.Phi, self.C, poles, allow_unstable=allow_unstable)
        else:
            try:
                self.L = torch.as_tensor(L, dtype=torch.float64)
            except (TypeError, ValueError, RuntimeError):
                raise TypeError(f"observer gain L must be a matrix of numbers, got {L!r}") from None
            if self.L.shape != (self.n + self.q, self.p):
                raise ValueError(f"observer gain L must have shape {(self.n + self.q, self.p)}, got {tuple(self.L.shape)}")
            rho = float(np.abs(self.error_poles()).max())
            if rho >= 1 and not allow_unstable:
                raise ValueError(f"observer gain L gives error poles with |z| = {rho:.4g} >= 1 (unstable); "
                                 "pass allow_unstable=True to use it anyway")
        self.poles = [complex(z) for z in (poles if poles is not None else self.error_poles())]

    def estimate(self, x: Tensor, u: Tensor | None = None, *, mask: Tensor | None = None, t: Tensor | None = None,
                 x0=None) -> DisturbanceEstimate:
        """Filtered state, disturbance and change rate along measurements ``x`` (..., T, n) (inputs ``u``);
        with ``C``, ``x`` is ``y`` (..., T, p) and ``mask`` marks missing outputs. ``t`` (..., T): the sample
        times (module docstring: the poles per sample, the gain per interval); ``x0``: the first estimate."""
        if self.output_form:
            if t is None:
                K = torch.linalg.solve(self.Phi, self.L).numpy()  # filter form: z_{k|k} = z_{k|k-1} + Phi^{-1} L (...)
            else:
                K = self.interval_gains
            return self.constant_gain_loop(K, x, u, mask, t=t, x0=x0)
        x = as_trajectory(x, self.n)
        dt = observer_steps(t, self.Ts, x)
        self.start_prior(x, x0)  # x0 checked before the model runs
        if not isinstance(dt, Tensor):
            return self.constant_gain_estimate(*self.inputs(x, u), self.L, u, x0=x0)
        h = steps_per_record(dt, tuple(x.shape[:-2]))
        h = torch.cat([h, h[..., -1:]], -1)  # the gain of sample k pairs with the interval after it
        scale = torch.cat([torch.ones(*h.shape, self.n, dtype=torch.float64),
                           (self.Ts / h)[..., None].expand(*h.shape, self.q)], -1)  # diag(I, Ts/Delta I)
        L_k = scale[..., None] * self.L  # (..., T, 2n, n): the poles of L at every interval
        return self.constant_gain_estimate(*self.inputs(x, u), L_k, u, dt=dt, x0=x0)

    def interval_gains(self, hs: np.ndarray, *, rtol: float = 1e-10) -> np.ndarray:
        r"""Filter gains :math:`\Phi_\Delta^{-1}L_\Delta` (B, T, n + q, p) placing ``self.poles`` for each interval
        of ``hs`` (B, T-1).

        One placement per distinct interval; sample k uses the interval after it (the last sample the one before).
        Intervals within ``rtol`` of each other share one placement (a grid's rounding, ~1e-15, would
        otherwise give a new one each); one within ``rtol`` of ``Ts`` uses the gain of ``Ts`` itself.
        """
        h_all = np.concatenate([hs, hs[:, -1:]], 1) if hs.shape[1] else np.full((hs.shape[0], 1), self.Ts)
        uniq, inv = np.unique(h_all, return_inverse=True)
        group = np.concatenate([[0], np.cumsum(np.diff(uniq) > rtol * uniq[1:])])  # runs of near-equal intervals
        reps = [uniq[group == g] for g in range(int(group[-1]) + 1)]
        at_Ts = np.array([bool(np.any(np.abs(hg - self.Ts) <= rtol * self.Ts)) for hg in reps])
        eye = np.eye(self.n + self.q)
        Acl = (self.Phi.numpy() - eye) / self.Ts  # Phi(h) = I + h (A_c + [[J, 0], [0, 0]]), linear in h
        Phis = eye + np.array([float(hg[0]) for hg in reps])[:, None, None] * Acl
        gains = np.empty((len(reps), self.n + self.q, self.p))
        todo = np.flatnonzero(~at_Ts)
        L = _ackermann(Phis[todo], self.C.numpy(), self.poles) if self.p == 1 and todo.size else None
        for j in tqdm(todo if L is None else [], desc="placing poles per interval",
                      disable=L is not None or todo.size < 100, leave=False):
            gains[j] = np.linalg.solve(Phis[j], place_observer_gain(Phis[j], self.C, self.poles,
                                                                    allow_unstable=True).numpy())
        if L is not None:
            gains[todo] = np.linalg.solve(Phis[todo], L)
        gains[at_Ts] = torch.linalg.solve(self.Phi, self.L).numpy()
        return gains[group[inv.reshape(h_all.shape)]]

    def error_poles(self) -> np.ndarray:
        r"""Eigenvalues of :math:`\Phi - LC` (complex, shape (n + q,)); :math:`\Phi = A` without ``C``."""
        return np.linalg.eigvals((self.Phi - self.L @ self.C).numpy())

    def __repr__(self) -> str:
        poles = [z.real if z.imag == 0 else z for z in self.poles]
        return f"LuenbergerObserver(n={self.n}, Ts={self.Ts}, poles={poles})"


def _ackermann(Phis: np.ndarray, C: np.ndarray, poles) -> np.ndarray | None:
    r"""Single-output observer gains for many plants at once (Ackermann): :math:`L = p(\Phi)\,\mathcal O^{-1} e_m`.

    ``Phis`` (K, m, m), ``C`` (1, m); :math:`p` the polynomial with roots ``poles``, :math:`\mathcal O` the
    observability matrix. With one output the placing gain is unique, so this is
    :func:`place_observer_gain`'s answer; None if any plant is unobservable or a placed pole misses by more
    than 1e-6 (ill-conditioned), and the caller places one by one instead.
    """
    K, m = Phis.shape[0], Phis.shape[-1]
    coeffs = np.real(np.poly(np.asarray(poles, dtype=complex)))  # p(s) = s^m + c_1 s^{m-1} + ... + c_m
    rows, pw = [np.broadcast_to(C, (K, 1, m))], np.broadcast_to(np.eye(m), (K, m, m))
    p_Phi = coeffs[m] * pw
    for j in range(1, m + 1):
        pw = pw @ Phis
        if j < m:
            rows.append(C @ pw)
        p_Phi = p_Phi + coeffs[m - j] * pw
    O = np.concatenate(rows, 1)  # (K, m, m): [C; C Phi; ...; C Phi^{m-1}]
    e = np.zeros((K, m, 1))
    e[:, -1] = 1.0
    try:
        L = p_Phi @ np.linalg.solve(O, e)  # (K, m, 1)
    except np.linalg.LinAlgError:
        return None
    got = np.sort_complex(np.linalg.eigvals(Phis - L @ C))
    want = np.sort_complex(np.asarray(poles, dtype=complex))
    if not np.all(np.isfinite(L)) or float(np.abs(got - want).max()) > 1e-6 * max(1.0, float(np.abs(want).max())):
        return None
    return L


def linear_feedback_gain(L: float | Tensor, Ts: float, n: int) -> Tensor:
    r"""The Luenberger gain that *is* the linear feedback of Eqs. (7)-(8) with gain ``L``.

    With :math:`L_{obs} = \begin{bmatrix} I + T_s L\\ L\end{bmatrix}` the filter
    gain is :math:`M = A^{-1}L_{obs} = [I;\, L]`, so :math:`\hat x_{k|k} = y_k` (the
    state part is deadbeat) and the disturbance estimate obeys
    :math:`\hat d_{k+1} = (I - T_s L)\hat d_k + T_s L\, r_k`,
    :math:`r_k = (y_{k+1} - y_k)/T_s - f_{neural}(y_k)`: the recursion of
    :math:`L(y_k - \hat x_k)` in Eqs. (7)-(8) (both start at 0). Hence
    :math:`\hat f = f_{neural}(y) + \hat d` equals Eq. (7)'s, and the error
    poles are :math:`\{0\} \cup \operatorname{eig}(I - T_s L)`, the matrix of
    Eq. (25).

    Returns
    -------
    Tensor, shape (2n, n), float64
    """
    Lm = gain_matrix(L, int(n))
    return torch.cat([torch.eye(int(n), dtype=torch.float64) + float(Ts) * Lm, Lm], 0)
