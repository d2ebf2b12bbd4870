"""The paper's Sec. 3-4 settings (the spiral of Eq. (26), App. A.3 and A.7, the authors' release), each written once.

The Sec. 3 and Sec. 4 notebooks (spiral, theory, ablations, observers, neural feedback, and the spiral part of
"Your own system") share these values: their settings dataclasses (``fnnbook.tasks``) take their paper values
from here, and a task's profile may still override them. The Sec. 5 values live in
:mod:`fnnlib.quadrotor.presets`; the training recipes in :mod:`fnnlib.training` (``PAPER_SPIRAL_RECIPE``,
``PAPER_BOTTLE_RECIPE``).

Sequences are tuples (read-only); a notebook receives them as lists.
"""

from __future__ import annotations

from types import MappingProxyType

__all__ = [
    "KALMAN_SETTINGS",
    "PAPER_SPIRAL_BETA",
    "PAPER_SPIRAL_HIDDEN",
    "PAPER_SPIRAL_L",
    "PAPER_SPIRAL_N",
    "RESIDUAL_GRID",
    "SPIRAL_ACTIVATION",
    "SPIRAL_NOISE_STD",
    "SPIRAL_NOMINAL",
    "SPIRAL_SAMPLES",
    "SPIRAL_TEST",
    "SPIRAL_TS",
    "SPIRAL_X0",
]

# -- the data: Eq. (26), sampled as in the authors' release
SPIRAL_TS = 0.01
"""Sampling time ``Ts`` of the spiral data and of the feedback layers (Eq. (25)), s."""

SPIRAL_SAMPLES = 1000
"""Samples per spiral trajectory (10 s at ``Ts``)."""

SPIRAL_X0 = (9.0, 0.0)
"""Initial state ``x(0)`` of the training and the test spiral."""

SPIRAL_NOMINAL = (2.0, 0.1, 0.0)
"""``(omega, eta, eps)`` of the training spiral (the release's values; the paper gives none)."""

SPIRAL_TEST = (3.0, 0.05, 10.0)
"""``(omega, eta, eps)`` of the test spiral (the release's values)."""

# -- the learned field f_neural (App. A.3.3)
PAPER_SPIRAL_HIDDEN = (50, 50)
"""Hidden widths of the spiral's neural ODE and of the neural feedback ``h_neural`` (App. A.3.3)."""

SPIRAL_ACTIVATION = "relu"
"""Activation of those networks."""

# -- the linear feedback, Eqs. (7)-(8) and (11)
PAPER_SPIRAL_L = 20.0
"""Base gain ``L = 20 I`` of the linear feedback (Fig. 4)."""

PAPER_SPIRAL_BETA = 0.02
"""Gain decay rate ``beta`` of Eq. (11) (Fig. 4g)."""

PAPER_SPIRAL_N = 50
"""Prediction horizon ``N`` (the number of cascade layers) of Fig. 4f."""

SPIRAL_NOISE_STD = 0.01
"""The measurement-noise std at which the noise claims (S3, S7, S9, S11) are judged.

The paper shows noise (Fig. 4g, Fig. 3, S11) without giving its level, and the release draws Fig. 4g from
noise-free data: 0.01 is the project's choice, never tuned per claim. The spiral task prints what it means on
its run (its ratio to the state's RMS and to the noise-free N-step error) and sweeps the other levels."""

# -- App. A.7: the residual grid of Fig. S11 and of the D4 test levels
RESIDUAL_GRID = MappingProxyType({
    "domega_range": (-0.72, 0.12, 0.6),
    "deta_range": (-0.03, 0.005, 0.025),
    "deps_range": (-14.4, 2.4, 12.0),
})
"""``[start, step, stop]`` of the changes of ``(omega, eta, eps)`` around the nominal spiral (App. A.7)."""

# -- the Kalman baseline's settings (the project's, shared by S11 and "Your own system")
KALMAN_SETTINGS = MappingProxyType({"kf_q_x": 1e-8, "kf_p0_d": 100.0})
"""Process noise of the state block and the initial variance of the disturbance block of the augmented Kalman
filter (the disturbance's process noise ``q_d`` is estimated from training data, never from the test)."""
