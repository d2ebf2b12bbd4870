r"""A linear ARX model fitted by least squares: the linear baseline of an input-output benchmark.

.. math::

    y_k = \sum_{i=1}^{n_a} a_i\, y_{k-i} + \sum_{j=0}^{n_b-1} b_j\, u_{k-n_k-j} + c ,

fitted on one record by ordinary least squares on the one-step equation error, and judged by *free-run
simulation*: the recursion is fed its own outputs after the first ``n_init`` samples, which are taken
from the measured record (that is how the initial state is estimated). The orders may be chosen by the
simulation error on the fitting record (:func:`select_arx`), so that nothing is tuned on the record that
judges the model.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

__all__ = ["ARXModel", "fit_arx", "select_arx"]


def _col(name: str, v: object) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.ndim == 2 and a.shape[1] == 1:
        a = a[:, 0]
    if a.ndim != 1:
        raise ValueError(f"{name} must be one signal, shape (T,) or (T, 1), got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} holds non-finite values")
    return a


@dataclass(frozen=True)
class ARXModel:
    """A fitted ARX model (see the module docstring).

    Attributes
    ----------
    a : ndarray, shape (na,)
        Output coefficients :math:`a_1, \\dots, a_{n_a}`.
    b : ndarray, shape (nb,)
        Input coefficients :math:`b_0, \\dots, b_{n_b-1}`.
    nk : int
        Input delay, samples.
    c : float
        Offset.
    """

    a: np.ndarray
    b: np.ndarray
    nk: int
    c: float

    @property
    def n_init(self) -> int:
        """The measured samples a simulation starts from: ``max(na, nk + nb - 1)``."""
        return max(len(self.a), self.nk + len(self.b) - 1)

    def simulate(self, u: object, y: object, *, n_init: int | None = None) -> np.ndarray:
        """Free-run simulation over a record: the first ``n_init`` outputs are the measured ``y`` (the initial
        state), every later one is computed from the model's own past outputs and the inputs ``u``.

        Parameters
        ----------
        u, y : array, shape (T,) or (T, 1)
            The record's input and measured output (only ``y[:n_init]`` is read).
        n_init : int, optional
            Measured samples to start from, at least :attr:`n_init` (default: that).

        Returns
        -------
        ndarray, shape (T,)
            The simulated output (its first ``n_init`` entries are the measured ones).
        """
        u, y = _col("u", u), _col("y", y)
        if u.shape != y.shape:
            raise ValueError(f"u and y must have the same length, got {u.shape} and {y.shape}")
        n0 = self.n_init if n_init is None else int(n_init)
        if not self.n_init <= n0 < y.size:
            raise ValueError(f"n_init must be in {self.n_init}..{y.size - 1} for this model, got {n_init}")
        out = np.empty_like(y)
        out[:n0] = y[:n0]
        na, nb = len(self.a), len(self.b)
        for k in range(n0, y.size):
            past_y = out[k - na:k][::-1] if na else np.empty(0)
            past_u = u[k - self.nk - nb + 1:k - self.nk + 1][::-1] if nb else np.empty(0)
            out[k] = self.a @ past_y + self.b @ past_u + self.c  # y_k = sum a_i y_{k-i} + sum b_j u_{k-nk-j} + c
        return out


def fit_arx(u: object, y: object, na: int, nb: int, nk: int = 1) -> ARXModel:
    """Least-squares fit of the ARX model with orders ``na`` >= 0, ``nb`` >= 1 and delay ``nk`` >= 0 on one
    record (the one-step equation error, with an offset).

    Raises
    ------
    ValueError
        Bad orders, signals of different lengths, non-finite values, or a record too short for the orders.
    """
    u, y = _col("u", u), _col("y", y)
    for name, v, low in (("na", na, 0), ("nb", nb, 1), ("nk", nk, 0)):
        if int(v) != v or v < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {v}")
    na, nb, nk = int(na), int(nb), int(nk)
    if u.shape != y.shape:
        raise ValueError(f"u and y must have the same length, got {u.shape} and {y.shape}")
    k0 = max(na, nk + nb - 1)
    rows = y.size - k0
    if rows < na + nb + 2:
        raise ValueError(f"a record of {y.size} samples is too short for na={na}, nb={nb}, nk={nk}")
    cols = [y[k0 - i:y.size - i] for i in range(1, na + 1)]
    cols += [u[k0 - nk - j:y.size - nk - j] for j in range(nb)]
    Phi = np.column_stack(cols + [np.ones(rows)])
    theta, *_ = np.linalg.lstsq(Phi, y[k0:], rcond=None)
    return ARXModel(theta[:na], theta[na:na + nb], nk, float(theta[-1]))


def select_arx(u: object, y: object, *, na: Iterable[int] = range(1, 5), nb: Iterable[int] = range(1, 5),
               nk: Iterable[int] = (0, 1), n_init: int | None = None) -> tuple[ARXModel, dict]:
    """Fit every order in the grid on the record (``u``, ``y``) and keep the one whose free-run simulation
    of that same record has the lowest RMSE (scored after ``n_init`` samples: default the largest
    :attr:`ARXModel.n_init` of the grid, so that every order is scored on the same samples).

    Returns
    -------
    (model, table) : tuple
        The chosen model and ``{(na, nb, nk): simulation RMSE on the record}``; a diverging order scores inf.
    """
    u, y = _col("u", u), _col("y", y)
    grid = list(itertools.product(na, nb, nk))
    if not grid:
        raise ValueError("the order grid is empty")
    n0 = max(max(a, k + b - 1) for a, b, k in grid) if n_init is None else int(n_init)
    table, best = {}, None
    for a, b, k in grid:
        model = fit_arx(u, y, a, b, k)
        with np.errstate(over="ignore", invalid="ignore"):
            sim = model.simulate(u, y, n_init=n0)
        err = float(np.sqrt(np.mean((sim[n0:] - y[n0:]) ** 2))) if np.isfinite(sim).all() else float("inf")
        table[(a, b, k)] = err
        if best is None or err < table[best[0]]:
            best = ((a, b, k), model)
    return best[1], table
