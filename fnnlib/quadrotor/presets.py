"""The paper's Sec. 5 settings (App. A.5 and the authors' release), each written once.

Library functions take these as required keywords, never as silent defaults; a paper run passes them
from here (tests, benchmarks) or from a notebook's ``parameters`` cell. The vehicles of Eq. (27) are
presets of :class:`~fnnlib.quadrotor.system.QuadrotorParams` and live beside it:
:data:`~fnnlib.quadrotor.system.NOMINAL` (the models' and the DFBC's vehicle),
:data:`~fnnlib.quadrotor.system.TRAINING_TRUTH` (the training data) and
:data:`~fnnlib.quadrotor.system.TEST_TRUTH` (the Sec. 5.3 flight test).

Mappings are read-only; unpack them into the call, e.g. ``DFBC(NOMINAL, **PAPER_DFBC_GAINS)``.
"""

from __future__ import annotations

import math
from types import MappingProxyType

__all__ = [
    "PAPER_BETA",
    "PAPER_DFBC_GAINS",
    "PAPER_FLIGHT_DATA",
    "PAPER_GAMMA",
    "PAPER_HORIZON",
    "PAPER_L",
    "PAPER_LISSAJOUS",
    "PAPER_MLP_RECIPE",
    "PAPER_MPC_WEIGHTS",
    "PAPER_RESIDUAL_RECIPE",
    "PAPER_THETA_MAX",
    "PAPER_THRUST_MAX",
    "PAPER_TS",
    "PAPER_WAYPOINT_BOX",
    "VALIDATION_RANDOMIZATION",
]

PAPER_TS = 0.02
"""Sampling time ``Ts`` of Sec. 5 in s: the data, the models' RK4 step and the MPC's control step."""

# -- the MPC of Eq. (28) and the models of App. A.5.4
PAPER_HORIZON = 10
"""MPC horizon ``N`` (and the number of cascade layers)."""

PAPER_MPC_WEIGHTS = MappingProxyType({
    "Q": (100.0, 100.0, 100.0, 50.0, 50.0, 50.0, 50.0, 50.0, 50.0, 1.0, 1.0, 1.0),
    "R": (1.0, 1.0, 1.0, 1.0),
})
"""Diagonal state and input weights of Eq. (28)."""

PAPER_THETA_MAX = math.pi / 2
"""Attitude box ``|Theta| <= pi/2`` of Eq. (28), rad."""

PAPER_THRUST_MAX = 4.0
"""Thrust bound per motor of Eq. (28) as the paper states it, N (the authors' release flies 6 N)."""

PAPER_L = 3.0
"""Base feedback gain ``L = 3 I`` of the cascade (App. A.5.3)."""

PAPER_BETA = 0.1
"""Gain decay rate ``beta`` of Eq. (11) in the MPC horizon."""

PAPER_GAMMA = 8.0
"""Adaptation gain ``Gamma`` of Eq. (30) (the authors' release)."""

# -- the reference trajectories
PAPER_LISSAJOUS = MappingProxyType({"r_x": 3.0, "r_y": 3.0, "r_z": 0.5, "T_x": 6.0, "T_y": 3.0, "T_z": 3.0,
                                    "h": 0.5})
"""The Lissajous test curve of App. A.5.5, ``[r_x, r_y, r_z, T_x, T_y, T_z, h]``."""

PAPER_WAYPOINT_BOX: tuple[tuple[float, float], ...] = ((-3.0, 3.0), (-3.0, 3.0), (-2.0, 2.0))
"""Box ``((x_lo, x_hi), (y_lo, y_hi), (z_lo, z_hi))`` in m of the training waypoints (the authors' release)."""

PAPER_FLIGHT_DATA = MappingProxyType({"n_waypoints": 3, "box": PAPER_WAYPOINT_BOX, "max_speed": 10.0,
                                      "substeps": 4})
"""How the training flights are drawn and flown (release): 3 waypoints per 200-node flight, speeds up to
10 m/s, the truth integrated with 4 RK4 sub-steps per ``Ts``."""

# -- the controller that flies the data (App. A.5)
PAPER_DFBC_GAINS = MappingProxyType({
    "Kp": (2.0, 2.0, 1.4),
    "K_Theta": (10.0, 10.0, 4.0),
    "Kp_w": (40.0, 40.0, 16.0),
    "Ki_w": (10.0, 10.0, 5.0),
    "Kd_w": (0.5, 0.5, 0.0),
    "tau_f": 0.05,
})
"""Gains of the DFBC (the authors' release); ``Kv`` is left to its rule ``4 Kp``."""

# -- training recipes (App. A.1, A.5.4; the paper gives only "50 epochs, Adam")
PAPER_RESIDUAL_RECIPE = MappingProxyType({"hidden": (36, 36), "activation": "tanh", "segment_length": 20,
                                          "batch_size": 80, "epochs": 50, "lr": 5e-3})
"""The neural-ODE residual and its training by Alg. 3 (segments, Adam)."""

PAPER_MLP_RECIPE = MappingProxyType({"epochs": 300, "lr": 1e-3, "batch_size": 256})
"""The single-step MLP baseline's training (Adam on shuffled mini-batches)."""

# -- validation vehicles for choosing baseline settings (not in the paper)
VALIDATION_RANDOMIZATION = MappingProxyType({"mass": 0.5, "inertia": 0.5, "drag": 0.5, "force_per_weight": 0.1})
r"""Domain randomisation of the validation vehicles on which a baseline's settings (AdapNN's :math:`\Gamma`) are chosen.

Each validation vehicle is drawn around :data:`~fnnlib.quadrotor.system.TRAINING_TRUTH`, the vehicle that made
the training data, by :func:`fnnlib.quadrotor.mpc.tuning.randomized_vehicles`: mass, each of the three inertias and each
of the three drag coefficients independently uniform in *training value* x (1 +- the relative half-width given
here), and a constant force with each axis uniform in +- ``force_per_weight`` x the training vehicle's weight
(+-0.81 N). Arm, torque coefficient and gravity stay.

Why these ranges, fixed before any flight and without looking at a test vehicle:

* the spirit of the paper's own Alg. 1 / Eq. (12): randomise the parameters of the simulation model around the
  nominal task. App. A.3.3's 20 randomised spiral cases span the rate :math:`\omega` from 0.8 to 3.08 and the
  decay :math:`\eta` from 0.04 to 0.135 around the nominal 2 and 0.1, i.e. about -60 %..+55 % and
  -60 %..+35 %: relative changes of about one half. Made symmetric, the same scale is +-50 % on every parameter
  of Eq. (27) that the learned residual saw at one value (mass, inertia, drag);
* the training vehicle has no external force, so there is no scale to take a fraction of; a tenth of the weight
  per axis is a moderate constant load (a steady wind or a tether), small enough that the thrust margin at
  either bound of the flight test stays available for tracking;
* the ranges are symmetric, so lighter and heavier, stiffer and looser vehicles are equally likely: the
  validation flights ask how a gain copes with *a* vehicle that is not the training one, not with a guessed
  direction of change.

On the training vehicle itself a gain has nothing to correct and the validation RMSE is flat over the grid
(:math:`\Gamma` is not identifiable there); on the randomised vehicles it is. The notebook reports where its
test vehicle lies in these ranges as context only; the draw never reads it.
"""
