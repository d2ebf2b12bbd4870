"""The Lissajous test reference of Sec. 5.2 / App. A.5.5, with analytic derivatives up to snap (NumPy, float64).

The test flight's flat outputs ``Psi = [p, v, a, j]`` for the differential-flatness controller and the MPC.
The library is z-down like the authors' release; the height offset has no effect on the dynamics since
gravity is uniform.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from fnnlib.quadrotor.control.checks import FloatArray, as_float_array, check_finite_real, check_int, check_positive

__all__ = ["FlatDerivatives", "lissajous", "lissajous_flat_outputs"]


class FlatDerivatives(NamedTuple):
    """Position and its first four time derivatives, each of shape ``(N, 3)``."""

    p: FloatArray
    v: FloatArray
    a: FloatArray
    j: FloatArray
    s: FloatArray


def lissajous(
    t: ArrayLike,
    *,
    r_x: float,
    r_y: float,
    r_z: float,
    T_x: float,
    T_y: float,
    T_z: float,
    h: float,
) -> FlatDerivatives:
    r"""The 3-D Lissajous test reference of Sec. 5.2 / App. A.5.5, with analytic derivatives.

    .. math:: p(t) = [\, r_x \sin(2\pi t / T_x),\; r_y \sin(2\pi t / T_y),\;
              h + r_z \cos(2\pi t / T_z) \,]

    The paper's ``[r_x, r_y, r_z, T_x, T_y, T_z, h]`` are
    :data:`~fnnlib.quadrotor.presets.PAPER_LISSAJOUS` (keyword-only, all required). The authors' release uses
    ``h = -0.5`` in its z-down frame; this library is z-down too, and the
    height offset has no effect on the dynamics since gravity is uniform.

    Derivatives use ``d^n/dt^n sin(w t) = w^n sin(w t + n pi / 2)`` (and the
    same for cos).

    Parameters
    ----------
    t : array_like, shape (N,)
        Times [s].
    r_x, r_y, r_z : float
        Amplitudes [m].
    T_x, T_y, T_z : float
        Periods [s], > 0.
    h : float
        Height offset of the z axis [m].

    Returns
    -------
    FlatDerivatives
        ``(p, v, a, j, s)``, each of shape ``(N, 3)``.
    """
    tt = as_float_array(t, name="t", ndim=1)
    radii = np.array([check_finite_real(r, name=nm) for r, nm in ((r_x, "r_x"), (r_y, "r_y"), (r_z, "r_z"))])
    periods = np.array([check_positive(T, name=nm) for T, nm in ((T_x, "T_x"), (T_y, "T_y"), (T_z, "T_z"))])
    offset = check_finite_real(h, name="h")

    w = 2.0 * np.pi / periods  # (3,)
    phase = w[None, :] * tt[:, None]  # (N, 3)
    out = []
    for order in range(5):
        shifted = phase + order * np.pi / 2.0
        wave = np.stack([np.sin(shifted[:, 0]), np.sin(shifted[:, 1]), np.cos(shifted[:, 2])], axis=1)
        out.append(radii * w**order * wave)
    out[0][:, 2] += offset
    return FlatDerivatives(*out)


def lissajous_flat_outputs(t0: float, n_nodes: int, Ts: float, **curve: float) -> FloatArray:
    """Flat-output reference ``Psi = [p, v, a, j]`` of :func:`lissajous` on ``t0 + i Ts``.

    Parameters
    ----------
    t0 : float
        First node time [s].
    n_nodes : int
        Number of nodes, >= 1 (the test flight uses 300 at 0.02 s).
    Ts : float
        Node spacing [s], > 0.
    **curve : float
        Curve parameters ``r_x, r_y, r_z, T_x, T_y, T_z, h`` passed to :func:`lissajous`
        (all required; the paper's: ``**PAPER_LISSAJOUS``).

    Returns
    -------
    ndarray, shape (n_nodes, 12)
    """
    start = check_finite_real(t0, name="t0")
    n = check_int(n_nodes, name="n_nodes", minimum=1)
    step = check_positive(Ts, name="Ts")
    d = lissajous(start + step * np.arange(n), **curve)
    return np.concatenate([d.p, d.v, d.a, d.j], axis=1)
